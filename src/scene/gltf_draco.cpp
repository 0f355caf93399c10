// KHR_draco_mesh_compression (gltf_draco.h).
#include "scene/gltf_draco.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

#include "scene/gltf_accessors.h"

#ifdef VKSONAR_HAVE_DRACO
#include <draco/compression/decode.h>
#include <draco/mesh/mesh.h>
#endif

namespace vksonar::gltf {
namespace {

// Decoded bytes (12 per vertex, 4 per index) per stream byte at most. Draco's edgebreaker and rANS
// coders shrink a regular grid's connectivity to a few bits per triangle and its positions, quantized
// coarsely, to less: a million-triangle grid at 1-bit quantization measured 1:10757, at 14 bits
// 1:139. Accessors that declare more than this are refused before the decoder runs.
constexpr std::size_t kMaxExpansion = std::size_t(1) << 14;

// How far outside the POSITION accessor's min/max a decoded position may lie, as a fraction of the
// largest extent: Draco quantizes every axis over the largest extent and rounds to the nearest step,
// so a vertex on the box may move out by half a step; 1/64 allows quantization to 5 bits and more
// (Blender's default is 14), while a stream that decodes to garbage lands far outside.
constexpr double kBoundsSlack = 1.0 / 64.0;

[[maybe_unused]] int index_value(const tinygltf::Value& value, const std::string& where) {
    if (value.IsInt()) return value.Get<int>();
    if (value.IsNumber()) {
        const double d = value.Get<double>();
        if (d >= 0 && d <= double(std::numeric_limits<int>::max()) && d == std::floor(d)) return int(d);
    }
    fail(ErrorCode::parse, where + " is not an index");
}

} // namespace

bool draco_available() {
#ifdef VKSONAR_HAVE_DRACO
    return true;
#else
    return false;
#endif
}

std::vector<DracoIndices> prepare_draco(nlohmann::json& doc) {
    std::vector<DracoIndices> taken;
    const auto meshes = doc.find("meshes");
    if (meshes == doc.end() || !meshes->is_array()) return taken;
    for (std::size_t m = 0; m < meshes->size(); ++m) {
        nlohmann::json& mesh = (*meshes)[m];
        if (!mesh.is_object()) continue;
        const auto prims = mesh.find("primitives");
        if (prims == mesh.end() || !prims->is_array()) continue;
        for (std::size_t p = 0; p < prims->size(); ++p) {
            nlohmann::json& prim = (*prims)[p];
            if (!prim.is_object()) continue;
            const auto ext = prim.find("extensions");
            if (ext == prim.end() || !ext->is_object() || !ext->contains("KHR_draco_mesh_compression")) continue;
            const auto indices = prim.find("indices");
            if (indices == prim.end()) continue;
            if (!indices->is_number_unsigned() ||
                indices->get<std::size_t>() > std::size_t(std::numeric_limits<int>::max()))
                fail(ErrorCode::parse, "mesh " + std::to_string(m) + " primitive " + std::to_string(p) +
                                           ": indices = " + indices->dump() + " is not an accessor index");
            taken.push_back({m, p, int(indices->get<std::size_t>())});
            prim.erase(indices);
        }
    }
    return taken;
}

void restore_draco(const std::vector<DracoIndices>& taken, tinygltf::Model& model) {
    for (const DracoIndices& t : taken) { // tinygltf keeps every mesh and primitive, in order
        if (t.mesh >= model.meshes.size() || t.primitive >= model.meshes[t.mesh].primitives.size())
            fail(ErrorCode::parse,
                 "mesh " + std::to_string(t.mesh) + " primitive " + std::to_string(t.primitive) + " was not read");
        model.meshes[t.mesh].primitives[t.primitive].indices = t.accessor;
    }
}

void decode_draco(const tinygltf::Model& model, const tinygltf::Primitive& prim, const tinygltf::Value& extension,
                  const std::string& where, std::vector<float>& positions, std::vector<std::uint32_t>& indices) {
    const std::string ext_where = where + ": KHR_draco_mesh_compression";
#ifndef VKSONAR_HAVE_DRACO
    (void)model;
    (void)prim;
    (void)extension;
    (void)positions;
    (void)indices;
    fail(ErrorCode::unsupported, ext_where + ": this build has no libdraco");
#else
    if (!extension.IsObject()) fail(ErrorCode::parse, ext_where + " is not an object");
    if (prim.mode != TINYGLTF_MODE_TRIANGLES)
        fail(ErrorCode::parse, ext_where + ": mode " + std::to_string(prim.mode) + " (a Draco mesh is TRIANGLES)");

    // The stream: a buffer view inside its buffer.
    const int view_index = index_value(extension.Get("bufferView"), ext_where + ".bufferView");
    if (std::size_t(view_index) >= model.bufferViews.size())
        fail(ErrorCode::parse, ext_where + ": bufferView " + std::to_string(view_index) + " does not exist");
    const tinygltf::BufferView& view = model.bufferViews[std::size_t(view_index)];
    if (view.buffer < 0 || std::size_t(view.buffer) >= model.buffers.size())
        fail(ErrorCode::parse, ext_where + ": bufferView " + std::to_string(view_index) + " has no valid buffer");
    const std::vector<unsigned char>& buffer = model.buffers[std::size_t(view.buffer)].data;
    if (view.byteOffset > buffer.size() || view.byteLength > buffer.size() - view.byteOffset)
        fail(ErrorCode::parse,
             ext_where + ": bufferView " + std::to_string(view_index) + " runs past its buffer's end");
    if (view.byteLength == 0) fail(ErrorCode::parse, ext_where + ": the stream is empty");
    if (view.byteLength > std::size_t(std::numeric_limits<std::int32_t>::max()))
        fail(ErrorCode::unsupported, ext_where + ": a stream over 2 GiB");

    // The POSITION attribute's id in the stream, and the accessors the decoded data must match.
    const tinygltf::Value& attributes = extension.Get("attributes");
    if (!attributes.IsObject() || !attributes.Has("POSITION"))
        fail(ErrorCode::parse, ext_where + ": attributes has no POSITION");
    const int position_id = index_value(attributes.Get("POSITION"), ext_where + ".attributes.POSITION");
    const auto position = prim.attributes.find("POSITION");
    if (position == prim.attributes.end()) fail(ErrorCode::parse, where + ": missing POSITION attribute");
    const std::string pos_where = where + ": POSITION accessor " + std::to_string(position->second);
    if (position->second < 0 || std::size_t(position->second) >= model.accessors.size())
        fail(ErrorCode::parse, pos_where + " does not exist");
    const tinygltf::Accessor& pos = model.accessors[std::size_t(position->second)];
    const bool quantization = std::find(model.extensionsUsed.begin(), model.extensionsUsed.end(),
                                        "KHR_mesh_quantization") != model.extensionsUsed.end();
    const int ct = pos.componentType;
    const bool integer = ct == TINYGLTF_COMPONENT_TYPE_BYTE || ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                         ct == TINYGLTF_COMPONENT_TYPE_SHORT || ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT;
    if (pos.type != TINYGLTF_TYPE_VEC3 || !(ct == TINYGLTF_COMPONENT_TYPE_FLOAT || (integer && quantization)))
        fail(ErrorCode::unsupported, pos_where + " is not float VEC3 (byte and short positions need "
                                                 "KHR_mesh_quantization in extensionsUsed)");
    std::size_t index_count = 0;
    std::string idx_where;
    if (prim.indices >= 0) {
        idx_where = where + ": indices accessor " + std::to_string(prim.indices);
        if (std::size_t(prim.indices) >= model.accessors.size()) fail(ErrorCode::parse, idx_where + " does not exist");
        const tinygltf::Accessor& idx = model.accessors[std::size_t(prim.indices)];
        if (idx.type != TINYGLTF_TYPE_SCALAR) fail(ErrorCode::parse, idx_where + " is not SCALAR");
        index_count = idx.count;
    } else if (prim.indices < -1) {
        fail(ErrorCode::parse, where + ": indices " + std::to_string(prim.indices) + " is invalid");
    }
    // Bounded before anything is decoded: what the accessors declare must be what this stream can
    // expand to, and fit the loader's 32-bit counts.
    constexpr std::size_t max_u32 = std::numeric_limits<std::uint32_t>::max();
    if (pos.count > max_u32 / 3 || index_count > max_u32)
        fail(ErrorCode::unsupported, where + ": more than 2^32 vertices or indices");
    const std::size_t declared = pos.count * 12 + index_count * 4;
    if (declared / kMaxExpansion > view.byteLength)
        fail(ErrorCode::parse, ext_where + ": the accessors declare " + std::to_string(declared) + " bytes from a " +
                                   std::to_string(view.byteLength) + "-byte stream, more than Draco expands to");

    draco::DecoderBuffer stream;
    stream.Init(reinterpret_cast<const char*>(buffer.data() + view.byteOffset), view.byteLength);
    const auto type = draco::Decoder::GetEncodedGeometryType(&stream);
    if (!type.ok() || type.value() != draco::TRIANGULAR_MESH)
        fail(ErrorCode::parse, ext_where + ": the stream is not a Draco triangle mesh");
    draco::Decoder decoder;
    auto decoded = decoder.DecodeMeshFromBuffer(&stream);
    if (!decoded.ok())
        fail(ErrorCode::parse,
             ext_where + ": the Draco stream does not decode (" + one_line(decoded.status().error_msg_string()) + ")");
    const std::unique_ptr<draco::Mesh> mesh = std::move(decoded).value();
    if (!mesh) fail(ErrorCode::parse, ext_where + ": the Draco stream does not decode");

    // Counts first, against the accessors, before anything is copied.
    const std::size_t points = mesh->num_points(), faces = mesh->num_faces();
    if (points != pos.count)
        fail(ErrorCode::parse, ext_where + ": the stream decodes to " + std::to_string(points) + " vertices, " +
                                   pos_where + " declares " + std::to_string(pos.count));
    if (prim.indices >= 0 && faces * 3 != index_count)
        fail(ErrorCode::parse, ext_where + ": the stream decodes to " + std::to_string(faces * 3) + " indices, " +
                                   idx_where + " declares " + std::to_string(index_count));
    const draco::PointAttribute* att = mesh->GetAttributeByUniqueId(std::uint32_t(position_id));
    if (!att)
        fail(ErrorCode::parse,
             ext_where + ": the stream has no attribute " + std::to_string(position_id) + " (attributes.POSITION)");
    if (att->num_components() != 3)
        fail(ErrorCode::parse, ext_where + ": attribute " + std::to_string(position_id) + " has " +
                                   std::to_string(int(att->num_components())) + " components, not 3");
    const bool float_stream = att->data_type() == draco::DT_FLOAT32 || att->data_type() == draco::DT_FLOAT64;
    if (float_stream != (ct == TINYGLTF_COMPONENT_TYPE_FLOAT))
        fail(ErrorCode::parse, ext_where + ": attribute " + std::to_string(position_id) + " is " +
                                   (float_stream ? "float" : "integer") + ", " + pos_where + " is not");

    const std::size_t first_position = positions.size();
    positions.resize(first_position + points * 3);
    float* const out_positions = positions.data() + first_position;
    for (std::size_t p = 0; p < points; ++p) {
        const draco::AttributeValueIndex value = att->mapped_index(draco::PointIndex(std::uint32_t(p)));
        double v[3];
        if (value.value() >= att->size() || !att->ConvertValue<double>(value, 3, v))
            fail(ErrorCode::parse, ext_where + ": vertex " + std::to_string(p) + " has no position in the stream");
        for (int k = 0; k < 3; ++k) {
            double x = v[k];
            if (integer && pos.normalized && !att->normalized()) // the glTF rule (KHR_mesh_quantization)
                x = ct == TINYGLTF_COMPONENT_TYPE_BYTE            ? std::max(x / 127.0, -1.0)
                    : ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ? x / 255.0
                    : ct == TINYGLTF_COMPONENT_TYPE_SHORT         ? std::max(x / 32767.0, -1.0)
                                                                  : x / 65535.0;
            if (!std::isfinite(x) || std::fabs(x) > double(std::numeric_limits<float>::max()))
                fail(ErrorCode::parse, ext_where + ": vertex " + std::to_string(p) + " has a NaN or Inf position");
            out_positions[3 * p + std::size_t(k)] = static_cast<float>(x);
        }
    }
    // The decoded positions against the accessor's box (glTF requires it for POSITION).
    if (pos.minValues.size() == 3 && pos.maxValues.size() == 3) {
        double extent = 0;
        for (int k = 0; k < 3; ++k)
            extent = std::max(extent, pos.maxValues[std::size_t(k)] - pos.minValues[std::size_t(k)]);
        for (int k = 0; k < 3; ++k) {
            const double lo = pos.minValues[std::size_t(k)], hi = pos.maxValues[std::size_t(k)];
            const double slack = kBoundsSlack * extent + 1e-6 * std::max(std::fabs(lo), std::fabs(hi)) + 1e-30;
            for (std::size_t p = 0; p < points; ++p) {
                const double x = out_positions[3 * p + std::size_t(k)];
                if (x < lo - slack || x > hi + slack)
                    fail(ErrorCode::parse, ext_where + ": vertex " + std::to_string(p) + " decodes to " +
                                               std::to_string(x) + " on axis " + std::to_string(k) + ", outside " +
                                               pos_where + "'s min/max [" + std::to_string(lo) + ", " +
                                               std::to_string(hi) + "]");
            }
        }
    }
    const std::size_t first_index = indices.size();
    indices.resize(first_index + faces * 3);
    std::uint32_t* const out_indices = indices.data() + first_index;
    for (std::size_t f = 0; f < faces; ++f) {
        const draco::Mesh::Face& face = mesh->face(draco::FaceIndex(std::uint32_t(f)));
        for (int k = 0; k < 3; ++k) {
            const std::uint32_t i = face[std::size_t(k)].value();
            if (i >= points)
                fail(ErrorCode::parse, ext_where + ": triangle " + std::to_string(f) + " names vertex " +
                                           std::to_string(i) + " of " + std::to_string(points));
            out_indices[3 * f + std::size_t(k)] = i;
        }
    }
#endif
}

} // namespace vksonar::gltf
