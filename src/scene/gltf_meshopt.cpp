// EXT_meshopt_compression (gltf_meshopt.h).
#include "scene/gltf_meshopt.h"

#include <algorithm>
#include <limits>

#ifdef VKSONAR_HAVE_MESHOPT
#include <meshoptimizer.h>
#endif

namespace vksonar::gltf {
namespace {

using nlohmann::json;

// Decoded bytes per compressed byte at most: meshopt's vertex codec spends at least a few bits per
// vertex byte block and its index codec at least 4 bits per triangle, so real files stay far below;
// a declaration above this is refused before anything is allocated.
constexpr std::size_t kMaxExpansion = 256;

std::size_t whole(const json& object, const char* key, const std::string& where, bool required = true) {
    const auto it = object.find(key);
    if (it == object.end()) {
        if (required) fail(ErrorCode::parse, where + ": " + key + " is missing");
        return 0;
    }
    if (!it->is_number_unsigned()) fail(ErrorCode::parse, where + ": " + key + " = " + it->dump() + " is not a count");
    return it->get<std::size_t>();
}

} // namespace

bool meshopt_available() {
#ifdef VKSONAR_HAVE_MESHOPT
    return true;
#else
    return false;
#endif
}

MeshoptPlan prepare_meshopt(json& doc) {
    MeshoptPlan plan;
    auto buffers = doc.find("buffers");
    auto views = doc.find("bufferViews");
    if (buffers == doc.end() || !buffers->is_array() || views == doc.end() || !views->is_array()) return plan;
    for (std::size_t b = 0; b < buffers->size(); ++b) {
        json& buffer = (*buffers)[b];
        if (!buffer.is_object() || buffer.contains("uri")) continue;
        const json* ext = nullptr;
        if (auto e = buffer.find("extensions"); e != buffer.end() && e->is_object())
            if (auto m = e->find("EXT_meshopt_compression"); m != e->end()) ext = &*m;
        if (!ext || !ext->is_object() || !ext->value("fallback", false)) continue;
        const std::string where = "buffer " + std::to_string(b) + " (EXT_meshopt_compression fallback)";
        plan.fallbacks.push_back({int(b), whole(buffer, "byteLength", where)});
        buffer["byteLength"] = 1; // tinygltf needs data; decode_meshopt replaces it
        buffer["uri"] = "data:application/octet-stream;base64,AA==";
    }
    for (std::size_t v = 0; v < views->size(); ++v) {
        const json& view = (*views)[v];
        if (!view.is_object()) continue;
        const auto e = view.find("extensions");
        if (e == view.end() || !e->is_object()) continue;
        const auto m = e->find("EXT_meshopt_compression");
        if (m == e->end()) continue;
        const std::string where = "bufferView " + std::to_string(v) + " EXT_meshopt_compression";
        if (!m->is_object()) fail(ErrorCode::parse, where + " is not an object");
        MeshoptView d;
        d.view = int(v);
        d.source_buffer = int(whole(*m, "buffer", where));
        d.source_offset = whole(*m, "byteOffset", where, false);
        d.source_length = whole(*m, "byteLength", where);
        d.count = whole(*m, "count", where);
        d.stride = whole(*m, "byteStride", where);
        const std::string mode = m->value("mode", std::string());
        const std::string filter = m->value("filter", std::string("NONE"));
        d.mode = mode == "ATTRIBUTES" ? 0 : mode == "TRIANGLES" ? 1 : mode == "INDICES" ? 2 : -1;
        d.filter = filter == "NONE"          ? 0
                   : filter == "OCTAHEDRAL"  ? 1
                   : filter == "QUATERNION"  ? 2
                   : filter == "EXPONENTIAL" ? 3
                                             : -1;
        if (d.mode < 0) fail(ErrorCode::parse, where + ": mode '" + mode + "' (ATTRIBUTES, TRIANGLES or INDICES)");
        if (d.filter < 0) fail(ErrorCode::parse, where + ": filter '" + filter + "'");
        const bool attributes = d.mode == 0;
        if (attributes ? (d.stride == 0 || d.stride % 4 != 0 || d.stride > 256) : (d.stride != 2 && d.stride != 4))
            fail(ErrorCode::parse,
                 where + ": byteStride " + std::to_string(d.stride) + " is not allowed for mode " + mode);
        if (d.mode == 1 && d.count % 3 != 0)
            fail(ErrorCode::parse, where + ": count " + std::to_string(d.count) + " is not whole triangles");
        if ((d.filter == 1 && d.stride != 4 && d.stride != 8) || (d.filter == 2 && d.stride != 8) ||
            (d.filter != 0 && !attributes))
            fail(ErrorCode::parse, where + ": filter " + filter + " with byteStride " + std::to_string(d.stride));
        const std::size_t view_offset = whole(view, "byteOffset", where, false);
        const std::size_t view_length = whole(view, "byteLength", where);
        if (d.count > std::numeric_limits<std::size_t>::max() / d.stride || d.count * d.stride != view_length)
            fail(ErrorCode::parse,
                 where + ": count x byteStride is not the view's byteLength " + std::to_string(view_length));
        if (view_length / kMaxExpansion > d.source_length)
            fail(ErrorCode::parse, where + ": " + std::to_string(view_length) + " bytes from " +
                                       std::to_string(d.source_length) + " compressed is more than meshopt expands to");
        const std::size_t target = whole(view, "buffer", where);
        const auto fallback = std::find_if(plan.fallbacks.begin(), plan.fallbacks.end(),
                                           [&](const auto& f) { return std::size_t(f.first) == target; });
        if (fallback == plan.fallbacks.end()) continue; // its uncompressed bytes are in the file: read those
        if (view_offset > fallback->second || view_length > fallback->second - view_offset)
            fail(ErrorCode::parse, where + ": the view runs past its fallback buffer");
        plan.views.push_back(d);
    }
    return plan;
}

void decode_meshopt(const MeshoptPlan& plan, tinygltf::Model& model) {
#ifndef VKSONAR_HAVE_MESHOPT
    if (!plan.empty()) fail(ErrorCode::unsupported, "EXT_meshopt_compression: this build has no libmeshoptimizer");
#else
    // First every number against the bytes present, then the allocation: each fallback buffer gets
    // room up to the end of the last view decoded into it, which must be about what its views hold
    // (gltfpack packs them back to back; gaps of alignment only).
    std::vector<std::size_t> needed(model.buffers.size(), 0), held(model.buffers.size(), 0);
    for (const MeshoptView& d : plan.views) {
        const std::string where = "bufferView " + std::to_string(d.view) + " EXT_meshopt_compression";
        if (d.source_buffer < 0 || std::size_t(d.source_buffer) >= model.buffers.size())
            fail(ErrorCode::parse, where + ": buffer " + std::to_string(d.source_buffer) + " does not exist");
        const std::vector<unsigned char>& source = model.buffers[std::size_t(d.source_buffer)].data;
        if (d.source_offset > source.size() || d.source_length > source.size() - d.source_offset)
            fail(ErrorCode::parse, where + ": the compressed bytes run past buffer " + std::to_string(d.source_buffer));
        const tinygltf::BufferView& view = model.bufferViews[std::size_t(d.view)];
        if (view.buffer < 0 || std::size_t(view.buffer) >= needed.size())
            fail(ErrorCode::parse, where + ": the view's buffer does not exist");
        needed[std::size_t(view.buffer)] =
            std::max(needed[std::size_t(view.buffer)], view.byteOffset + view.byteLength);
        held[std::size_t(view.buffer)] += view.byteLength + 16;
    }
    for (const auto& [buffer, declared] : plan.fallbacks) {
        const std::size_t b = std::size_t(buffer);
        if (needed[b] > 2 * held[b] + 4096)
            fail(ErrorCode::parse, "buffer " + std::to_string(buffer) +
                                       " (EXT_meshopt_compression fallback): its views " + "spread over " +
                                       std::to_string(needed[b]) + " bytes but hold " + std::to_string(held[b]));
        model.buffers[b].data.assign(std::min(needed[b], declared), 0);
    }
    for (const MeshoptView& d : plan.views) { // every index and range checked in the loop above
        const std::string where = "bufferView " + std::to_string(d.view) + " EXT_meshopt_compression";
        const std::vector<unsigned char>& source = model.buffers[std::size_t(d.source_buffer)].data;
        const tinygltf::BufferView& view = model.bufferViews[std::size_t(d.view)];
        std::vector<unsigned char>& target = model.buffers[std::size_t(view.buffer)].data;
        unsigned char* out = target.data() + view.byteOffset;
        const unsigned char* in = source.data() + d.source_offset;
        const int status = d.mode == 0   ? meshopt_decodeVertexBuffer(out, d.count, d.stride, in, d.source_length)
                           : d.mode == 1 ? meshopt_decodeIndexBuffer(out, d.count, d.stride, in, d.source_length)
                                         : meshopt_decodeIndexSequence(out, d.count, d.stride, in, d.source_length);
        if (status != 0)
            fail(ErrorCode::parse,
                 where + ": the compressed data does not decode (meshopt " + std::to_string(status) + ")");
        if (d.filter == 1) meshopt_decodeFilterOct(out, d.count, d.stride);
        if (d.filter == 2) meshopt_decodeFilterQuat(out, d.count, d.stride);
        if (d.filter == 3) meshopt_decodeFilterExp(out, d.count, d.stride);
    }
#endif
}

} // namespace vksonar::gltf
