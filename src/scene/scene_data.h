// Internal scene representation shared by the CPU and Vulkan backends.
#pragma once

#include <cstddef>
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
    // Mesh-local axis-aligned bounds of its vertices (set_bounds), for skipping a draw in a slice it
    // cannot reach (cull_depth_draws). A mesh without bounds is drawn in every slice.
    bool has_bounds = false;
    float bounds_min[3] = {0.0f, 0.0f, 0.0f};
    float bounds_max[3] = {0.0f, 0.0f, 0.0f};
};

// mesh's bounds from its vertex_count vertices at xyz (finite: the loaders reject NaN and Inf).
inline void set_bounds(MeshRange& mesh, const float* xyz) {
    mesh.has_bounds = mesh.vertex_count > 0;
    for (int k = 0; k < 3; ++k) {
        float lo = mesh.has_bounds ? xyz[k] : 0.0f, hi = lo;
        for (std::uint32_t v = 1; v < mesh.vertex_count; ++v) {
            const float x = xyz[3 * std::size_t(v) + std::size_t(k)];
            lo = x < lo ? x : lo;
            hi = x > hi ? x : hi;
        }
        mesh.bounds_min[k] = lo;
        mesh.bounds_max[k] = hi;
    }
}

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
