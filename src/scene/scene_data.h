// Internal scene representation shared by the CPU and Vulkan backends.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/access.h"
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
    std::vector<SceneInstance> instances;    // glTF nodes with a mesh, in the order the node tree is walked
    std::vector<std::string> classes;        // class names, class_id - 1
    SceneStats stats;
    std::string effects_json; // scene-level effect requests, "" if none
    std::string source_path;
};

// Puts the triangles of a mesh that has more than one depth cluster's worth (kClusterTriangles, plan.h)
// in the order of their centroids along a Morton (Z-order) curve through the mesh's bounding box,
// stable for equal keys. The depth pass draws a mesh as runs of consecutive triangles and skips the
// runs a slice cannot see (cull_depth_clusters): runs of a spatially sorted mesh are compact patches,
// where runs in an exporter's order are long strips across a whole terrain that every slice sees.
// Each run of kClusterTriangles then gets its own copy of the vertices it uses (GPUs shade every
// vertex in an indexed draw's index range), so the mesh's vertex count grows by the runs' shared
// borders. The triangles, their winding and their positions do not change; between overlapping
// coplanar triangles of one mesh the depth test's tie goes to the earlier one, as before. Only for the
// scene's last mesh (its vertices end the array: call it right after adding the mesh).
void order_triangles_spatially(SceneData& scene, const MeshRange& mesh);

// The same for every mesh of a scene whose meshes' vertices lie one after another in mesh order and
// fill the array (as the glTF loader writes them), with the same result as calling the function above
// after adding each mesh: the loader reads every mesh first and orders them once the file's buffers
// are freed, so that the sort's scratch never coexists with them. The positions end in a new array
// exactly as large as the copies need; the indices keep their array (one mesh that fills it takes the
// sort's scratch block of exactly its size instead). Leaves any other layout as it is.
void order_triangles_spatially(SceneData& scene);

} // namespace vksonar
