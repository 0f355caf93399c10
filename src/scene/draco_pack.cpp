// Writing glTF as KHR_draco_mesh_compression (draco_pack.h).
#include "scene/draco_pack.h"

#include <cstdint>
#include <fstream>
#include <memory>
#include <vector>

#include <nlohmann/json.hpp>

#include "scene/gltf_accessors.h"
#include "scene/gltf_file.h"

#ifdef VKSONAR_HAVE_DRACO
#include <draco/compression/encode.h>
#include <draco/mesh/mesh.h>
#endif

namespace vksonar::gltf {
namespace {

using nlohmann::json;

[[maybe_unused]] std::string base64(const std::string& bytes) {
    static const char* table = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    for (std::size_t i = 0; i < bytes.size(); i += 3) {
        std::uint32_t v = std::uint32_t(std::uint8_t(bytes[i])) << 16;
        if (i + 1 < bytes.size()) v |= std::uint32_t(std::uint8_t(bytes[i + 1])) << 8;
        if (i + 2 < bytes.size()) v |= std::uint8_t(bytes[i + 2]);
        out += table[(v >> 18) & 63];
        out += table[(v >> 12) & 63];
        out += i + 1 < bytes.size() ? table[(v >> 6) & 63] : '=';
        out += i + 2 < bytes.size() ? table[v & 63] : '=';
    }
    return out;
}

[[maybe_unused]] json extras_of(const std::string& text) {
    return text.empty() ? json() : json::parse(text);
}

} // namespace

std::string write_draco_gltf(const std::string& in, const std::string& out, int position_bits, int speed) {
#ifndef VKSONAR_HAVE_DRACO
    (void)in;
    (void)out;
    (void)position_bits;
    (void)speed;
    return "this build has no libdraco";
#else
    try {
        std::vector<std::string> warnings;
        const tinygltf::Model model = read_model(in, "", warnings);
        json doc = {{"asset", {{"version", "2.0"}, {"generator", "vksonar draco_pack"}}},
                    {"extensionsUsed", {"KHR_draco_mesh_compression"}},
                    {"extensionsRequired", {"KHR_draco_mesh_compression"}}};
        if (model.defaultScene >= 0) doc["scene"] = model.defaultScene;
        for (const tinygltf::Scene& s : model.scenes) {
            json scene = {{"nodes", s.nodes}};
            if (!s.extras_json_string.empty()) scene["extras"] = extras_of(s.extras_json_string);
            doc["scenes"].push_back(scene);
        }
        for (const tinygltf::Node& n : model.nodes) {
            if (!n.extensions.empty()) return "node extensions are not written";
            json node = json::object();
            if (!n.name.empty()) node["name"] = n.name;
            if (n.mesh >= 0) node["mesh"] = n.mesh;
            if (!n.children.empty()) node["children"] = n.children;
            if (!n.matrix.empty()) node["matrix"] = n.matrix;
            if (!n.translation.empty()) node["translation"] = n.translation;
            if (!n.rotation.empty()) node["rotation"] = n.rotation;
            if (!n.scale.empty()) node["scale"] = n.scale;
            doc["nodes"].push_back(node);
        }
        for (const tinygltf::Material& m : model.materials) {
            json material = json::object();
            if (!m.name.empty()) material["name"] = m.name;
            if (!m.extras_json_string.empty()) material["extras"] = extras_of(m.extras_json_string);
            doc["materials"].push_back(material);
        }
        std::string bin;
        doc["accessors"] = json::array();
        doc["bufferViews"] = json::array();
        for (std::size_t mi = 0; mi < model.meshes.size(); ++mi) {
            json mesh = {{"primitives", json::array()}};
            for (std::size_t pi = 0; pi < model.meshes[mi].primitives.size(); ++pi) {
                const tinygltf::Primitive& prim = model.meshes[mi].primitives[pi];
                const std::string where = "mesh " + std::to_string(mi) + " primitive " + std::to_string(pi);
                if (prim.mode != TINYGLTF_MODE_TRIANGLES) return where + ": not TRIANGLES";
                if (!prim.targets.empty()) return where + ": morph targets are not written";
                const auto position = prim.attributes.find("POSITION");
                if (position == prim.attributes.end()) return where + ": no POSITION";
                const tinygltf::Accessor& acc = model.accessors[std::size_t(position->second)];
                if (acc.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT) return where + ": positions are not float";
                const std::vector<double> p = read_accessor(model, position->second, where);
                const std::size_t points = p.size() / 3;
                std::vector<double> idx;
                if (prim.indices >= 0) {
                    idx = read_accessor(model, prim.indices, where);
                } else {
                    for (std::size_t i = 0; i < points; ++i)
                        idx.push_back(double(i));
                }
                draco::Mesh dm;
                dm.set_num_points(static_cast<std::uint32_t>(points));
                draco::GeometryAttribute ga;
                ga.Init(draco::GeometryAttribute::POSITION, nullptr, 3, draco::DT_FLOAT32, false, 12, 0);
                const int att = dm.AddAttribute(ga, true, static_cast<std::uint32_t>(points));
                for (std::size_t i = 0; i < points; ++i) {
                    const float v[3] = {float(p[3 * i]), float(p[3 * i + 1]), float(p[3 * i + 2])};
                    dm.attribute(att)->SetAttributeValue(draco::AttributeValueIndex(std::uint32_t(i)), v);
                }
                for (std::size_t t = 0; t + 2 < idx.size(); t += 3)
                    dm.AddFace({draco::PointIndex(std::uint32_t(idx[t])), draco::PointIndex(std::uint32_t(idx[t + 1])),
                                draco::PointIndex(std::uint32_t(idx[t + 2]))});
                draco::Encoder encoder;
                if (position_bits > 0)
                    encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION, position_bits);
                encoder.SetSpeedOptions(speed, speed);
                encoder.SetTrackEncodedProperties(true); // num_encoded_points, _faces: the accessor counts
                draco::EncoderBuffer stream;
                const draco::Status status = encoder.EncodeMeshToBuffer(dm, &stream);
                if (!status.ok()) return where + ": draco: " + status.error_msg_string();
                while (bin.size() % 4)
                    bin += '\0';
                doc["bufferViews"].push_back(
                    {{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", stream.size()}});
                bin.append(stream.data(), stream.size());
                json pos = {{"componentType", 5126}, {"count", encoder.num_encoded_points()}, {"type", "VEC3"}};
                if (acc.minValues.size() == 3 && acc.maxValues.size() == 3) {
                    pos["min"] = acc.minValues;
                    pos["max"] = acc.maxValues;
                }
                doc["accessors"].push_back(pos);
                doc["accessors"].push_back(
                    {{"componentType", 5125}, {"count", encoder.num_encoded_faces() * 3}, {"type", "SCALAR"}});
                const std::size_t a = doc["accessors"].size() - 2;
                json primitive = {{"attributes", {{"POSITION", a}}},
                                  {"indices", a + 1},
                                  {"mode", 4},
                                  {"extensions",
                                   {{"KHR_draco_mesh_compression",
                                     {{"bufferView", doc["bufferViews"].size() - 1},
                                      {"attributes", {{"POSITION", dm.attribute(att)->unique_id()}}}}}}}};
                if (prim.material >= 0) primitive["material"] = prim.material;
                mesh["primitives"].push_back(primitive);
            }
            doc["meshes"].push_back(mesh);
        }
        while (bin.size() % 4)
            bin += '\0';
        const bool glb = out.size() >= 4 && out.compare(out.size() - 4, 4, ".glb") == 0;
        doc["buffers"] = {{{"byteLength", bin.size()}}};
        if (!glb) doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64(bin);
        std::string text = doc.dump();
        std::ofstream file(out, std::ios::binary);
        if (!glb) {
            file << text;
        } else {
            while (text.size() % 4)
                text += ' ';
            auto u32 = [&](std::size_t v) {
                const std::uint32_t x = static_cast<std::uint32_t>(v);
                file.write(reinterpret_cast<const char*>(&x), 4);
            };
            file.write("glTF", 4);
            u32(2);
            u32(12 + 8 + text.size() + 8 + bin.size());
            u32(text.size());
            u32(0x4E4F534Au);
            file << text;
            u32(bin.size());
            u32(0x004E4942u);
            file << bin;
        }
        if (!file) return "cannot write " + out;
        return "";
    } catch (const LoadFailure& e) {
        return in + ": " + e.what;
    } catch (const std::exception& e) {
        return one_line(e.what());
    }
#endif
}

} // namespace vksonar::gltf
