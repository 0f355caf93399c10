// KHR_draco_mesh_compression (Blender's compressed export): a primitive's geometry stored as one
// Draco stream in a buffer view, decoded with Debian's libdraco. The primitive's accessors keep
// their count, type and min/max but usually have no data; the stream's POSITION attribute (the id the
// extension's attributes map names) and its faces replace them. Draco dequantizes positions to float
// as it decodes. Internal to src/scene.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "scene/gltf_file.h"

namespace vksonar::gltf {

// True when this build decodes KHR_draco_mesh_compression (libdraco-dev was found).
bool draco_available();

// tinygltf 2.7 refuses an indices accessor without a bufferView, which is how a Draco primitive's
// indices are written: the indices of every primitive with the extension are taken out of `doc`
// before tinygltf runs (prepare) and put back after it ran (restore).
struct DracoIndices {
    std::size_t mesh = 0, primitive = 0;
    int accessor = -1;
};
std::vector<DracoIndices> prepare_draco(nlohmann::json& doc);
void restore_draco(const std::vector<DracoIndices>& taken, tinygltf::Model& model);

// Decodes the KHR_draco_mesh_compression stream of `prim` (`extension` is its value) and appends its
// positions (3 floats per vertex, in the POSITION accessor's space) to `positions` and its triangles
// (3 vertex numbers each, from 0 for the primitive's first vertex) to `indices`, each grown by exactly
// what the stream holds. Before the decoder runs: the stream lies inside its buffer, the POSITION (and
// indices) accessors declare no more than Draco could expand that stream to. After it: the decoded
// vertex and triangle counts equal the accessors' counts and the positions lie within the accessor's
// min/max, or the file is refused with one line naming `where` (the mesh and primitive). Throws
// LoadFailure (the arrays may have grown; the load fails as a whole).
void decode_draco(const tinygltf::Model& model, const tinygltf::Primitive& prim, const tinygltf::Value& extension,
                  const std::string& where, std::vector<float>& positions, std::vector<std::uint32_t>& indices);

} // namespace vksonar::gltf
