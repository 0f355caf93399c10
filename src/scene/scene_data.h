// Internal scene representation shared by the CPU and Vulkan backends.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "vksonar/scene.h"

namespace vksonar {

struct MeshRange {
    std::uint32_t first_index = 0;  // into SceneData::indices
    std::uint32_t index_count = 0;  // multiple of 3
    std::uint32_t first_vertex = 0; // added to every index (indices are mesh-local)
    std::uint32_t vertex_count = 0;
};

struct SceneData {
    std::vector<float> positions;       // xyz per vertex, mesh-local, metres (glTF meshes keep glTF's y-up axes)
    std::vector<std::uint32_t> indices; // triangle lists, mesh-local indices
    std::vector<MeshRange> meshes;
    std::vector<SceneDraw> draws;            // world_from_local already includes the glTF y-up -> z-up rotation
    std::vector<AcousticMaterial> materials; // at least one (the default material) once a mesh exists
    SceneStats stats;
    std::string effects_json; // scene-level effect requests, "" if none
    std::string source_path;
};

} // namespace vksonar
