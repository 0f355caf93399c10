// EXT_meshopt_compression (gltfpack -c): buffer views stored compressed in one buffer and decoded,
// with Debian's libmeshoptimizer, into a "fallback" buffer that the file declares but leaves without
// data. tinygltf 2.7 cannot load such a buffer, so the fallback buffers are replaced in the JSON by a
// one-byte placeholder before tinygltf runs (prepare), and filled after it ran (decode): the buffer
// views then point at decoded bytes and the accessor reader needs no change. Internal to src/scene.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "scene/gltf_file.h"

namespace vksonar::gltf {

struct MeshoptView {
    int view = 0;          // the buffer view that holds the decoded bytes
    int source_buffer = 0; // where the compressed bytes are
    std::size_t source_offset = 0, source_length = 0;
    std::size_t count = 0, stride = 0;
    int mode = 0;   // 0 ATTRIBUTES, 1 TRIANGLES, 2 INDICES
    int filter = 0; // 0 NONE, 1 OCTAHEDRAL, 2 QUATERNION, 3 EXPONENTIAL
};

struct MeshoptPlan {
    std::vector<MeshoptView> views;
    std::vector<std::pair<int, std::size_t>> fallbacks; // buffer index, declared byteLength
    bool empty() const { return views.empty() && fallbacks.empty(); }
};

// True when this build decodes EXT_meshopt_compression (libmeshoptimizer-dev was found).
bool meshopt_available();

// Reads the extension from `doc`, checks every number against the others (a view's declared size,
// count x stride, lies inside its fallback buffer; the decoded size is bounded by the compressed
// size), and replaces each fallback buffer in `doc` by a one-byte placeholder. Throws LoadFailure.
MeshoptPlan prepare_meshopt(nlohmann::json& doc);

// Decodes every compressed view of `plan` into its fallback buffer in `model`. Throws LoadFailure.
void decode_meshopt(const MeshoptPlan& plan, tinygltf::Model& model);

} // namespace vksonar::gltf
