// Scene: triangle meshes with node transforms and acoustic materials, in the world frame
// (x forward/east, y left/north, z up, metres). glTF's +Y-up frame maps to it by a +90 deg rotation
// about x: world = (x_gltf, -z_gltf, y_gltf) (the same mapping Blender uses).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "vksonar/config.h"
#include "vksonar/result.h"

namespace vksonar {

// Acoustic material, read from glTF material extras: {"vksonar": {"backscatter_db": -27, "model": "lambert"}}.
// Default (a material whose extras say nothing, and the implicit "default" material given to primitives
// without one): backscatter_db = -30 dB, model = lambert (a mid value for sand/silt seabeds).
// Scattering strength per unit area at incidence theta (from the surface normal):
//   lambert   s = mu cos^2(theta)
//   constant  s = mu cos(theta): the echo of a pixel does not depend on theta (the monostatic
//             Lommel-Seeliger law; glTF also accepts "lommel_seeliger")
//   rough     s = mu cos^2(theta) + R^2 exp(-tan^2(theta) / (2 m^2)) / (8 pi m^2 cos^4(theta)): Lambert
//             plus the Kirchhoff facet term of an interface with Gaussian slopes of rms m and pressure
//             reflection coefficient R at normal incidence (the near-specular lobe of smooth surfaces)
// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct AcousticMaterial {
    std::string name;
    double backscatter_db = -30.0; // mu, dB re 1 m^2 per m^2 per sr; NaN: the config's default_backscatter
    enum class Model : std::uint8_t { lambert, constant, rough } model = Model::lambert;
    double rms_slope = 0.1;      // rough only: m, rms slope of the interface along one axis (0.01 to 1)
    double reflection_db = -8.0; // rough only: 10 log10 R^2 (<= 0; -8 dB is medium sand, -1 dB steel)

    // Checks the model (one of the three) and the parameters it uses. Returns success, or
    // ErrorCode::invalid_argument whose message names the first problem ("rms_slope = 0 (expected 0.01 to 1)").
    [[nodiscard]] Result<void> validate() const;
};

// The acoustic material a glTF material's name suggests, for scenes exported without extras.vksonar:
// the first keyword found in the lower-cased name (steel, iron, metal, aluminium: rough, -10 dB;
// concrete, stone, rock, boulder, brick: rough, -15 dB; gravel, shell: -20 dB; wood, timber: -20 dB;
// sand: -27 dB; mud, silt, clay: -35 dB; rubber, plastic, pvc: -25 dB; glass: rough, -15 dB). The
// levels are typical high-frequency (100 kHz - 1 MHz) backscatter at moderate grazing angles, within
// the spread the literature reports for each class (docs/materials.md); empty when none matches.
[[nodiscard]] std::optional<AcousticMaterial> acoustic_material_by_name(const std::string& name);

// One drawable: a range of a mesh's triangles placed by a world matrix.
// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct SceneDraw {
    std::uint32_t mesh = 0;     // index into SceneMeshView list
    std::uint32_t material = 0; // index into materials
    std::uint32_t instance = 0; // SceneInstance::id of the object drawn (0: none given)
    std::array<double, 16> world_from_local{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}; // column-major
};

// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct SceneStats {
    std::uint64_t triangles = 0; // drawn triangles (instances counted)
    std::uint32_t meshes = 0;
    std::uint32_t draws = 0;
    std::uint64_t instances = 0;          // EXT_mesh_gpu_instancing instances (each one draw of a shared mesh)
    std::vector<std::string> extensions;  // glTF extensions the file uses
    std::uint32_t skipped_primitives = 0; // points/lines and degenerate-only primitives, skipped with a warning
    std::vector<std::string> warnings;
};

// An object of the scene, as ground-truth labels name it: a glTF node with a mesh. Its id is the
// node's index + 1, stable across frames and runs of the same file (0 means no object); every draw of
// the node (its primitives, its EXT_mesh_gpu_instancing copies) carries it. Its class is the node's
// extras.vksonar.class, else its mesh's, else the mesh's name (else "mesh N"); classes are numbered
// from 1 in the order the file first names them (Scene::classes()[class_id - 1]).
// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct SceneInstance {
    std::uint32_t id = 0;
    std::string node;       // the node's name ("" if it has none)
    std::string mesh;       // its mesh's name ("" if it has none)
    std::string class_name; // as above
    std::uint32_t class_id = 0;
};

struct SceneData; // internal
namespace detail {
struct Access; // internal: src/core/access.h
}

// How Scene::load_gltf treats the files a scene names (external buffers), for scenes nobody here wrote.
// A buffer's uri is relative to the scene file's folder; it is resolved (symlinks and ".." followed)
// and must lie inside asset_root, be a regular file (not a directory, FIFO or device, which is opened
// without blocking to find out) and hold exactly the buffer's byteLength bytes, at most 2 GiB; anything
// else fails with a one-line error naming the uri. Images are never read (vksonar uses no textures).
// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct SceneLoadOptions {
    // The folder every file named inside the scene must lie in; empty: the scene file's own folder.
    // Widen it for layouts that share buffers between folders (the CLI's --asset-root).
    std::string asset_root;
    // Uniform scale applied to the whole scene (0.001: a model exported in millimetres).
    double scale = 1.0;
};

// The axis-aligned box around every drawn triangle, world frame (m); empty when nothing is drawn.
// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct SceneBounds {
    bool empty = true;
    double min_m[3] = {0, 0, 0}, max_m[3] = {0, 0, 0};
    // The length of the box's diagonal, m; 0 when empty. Pure.
    double diagonal_m() const;
};

// Thread-safety: safe to read from many threads at once, to write from one; it must not change while a
// Renderer made from it exists.
class Scene {
public:
    // An empty scene (no mesh, no material, no draw), to build with add_mesh / add_material / add_draw.
    // Move-only; the scene owns its arrays and frees them on destruction; a moved-from scene stays
    // usable.
    Scene();
    ~Scene();
    Scene(Scene&&) noexcept;
    Scene& operator=(Scene&&) noexcept;

    // Loads .gltf or .glb (and the buffers it names, under options.asset_root) into a new scene. Fails
    // with a one-line error naming the file and what is wrong: ErrorCode::io (a file cannot be read),
    // ErrorCode::parse (malformed glTF or extras), ErrorCode::unsupported (a required extension vksonar
    // does not decode), ErrorCode::invalid_argument (a bad options.scale). Thread-safety: may be
    // called from any thread; loads share nothing.
    [[nodiscard]] static Result<Scene> load_gltf(const std::string& path, const SceneLoadOptions& options = {});

    // Builds a scene from arrays an engine already has: positions xyz (mesh-local), triangle indices.
    // Adds one mesh (the arrays are copied; the caller keeps its own) and returns its index; then place
    // it with add_draw. Fails with ErrorCode::invalid_argument for null or empty arrays, an index count
    // that is not a multiple of 3, an index out of range or a non-finite coordinate, with
    // ErrorCode::unsupported if host memory runs out; the scene is then unchanged.
    [[nodiscard]] Result<std::uint32_t> add_mesh(const float* positions_xyz, std::uint32_t vertex_count,
                                                 const std::uint32_t* indices, std::uint32_t index_count);
    // Adds a material (copied; not validated until a Renderer is made from the scene, which then names
    // it in its error) and returns its index for SceneDraw::material. Fails only with
    // ErrorCode::unsupported if host memory runs out; the scene is then unchanged.
    [[nodiscard]] Result<std::uint32_t> add_material(const AcousticMaterial& material);
    // Adds a draw of a mesh added before with a material added before. Fails with
    // ErrorCode::invalid_argument naming the field for an unknown mesh or material index or a non-finite
    // transform entry, with ErrorCode::unsupported if host memory runs out; the scene is then unchanged.
    [[nodiscard]] Result<void> add_draw(const SceneDraw& draw);

    // What the scene holds (counts, the file's extensions, the loader's warnings); the reference is
    // valid as long as the scene.
    const SceneStats& stats() const;
    // Every drawn vertex through its draw's transform (linear in vertices x draws).
    SceneBounds bounds() const;
    // The acoustic materials, indexed by SceneDraw::material; valid as long as the scene.
    const std::vector<AcousticMaterial>& materials() const;
    // The objects of a loaded glTF scene, in the order its node tree is walked, and their class names
    // (SceneInstance); empty for a scene built with add_mesh / add_draw. Valid as long as the scene.
    const std::vector<SceneInstance>& instances() const;
    const std::vector<std::string>& classes() const;
    // Effects the scene file asks for (glTF scene extras "vksonar": {"effects": {...}}), as JSON text;
    // empty when it asks for none. Valid as long as the scene.
    const std::string& effects_json() const;

private:
    friend struct detail::Access; // src/core/access.h
    std::unique_ptr<SceneData> data_;
};

// Sonar pose in the world frame: position in metres, orientation as roll, pitch, yaw in degrees
// (rotation R = Rz(yaw) Ry(pitch) Rx(roll), REP-103). Yaw 0 looks along world +x.
// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct Pose {
    double x_m = 0, y_m = 0, z_m = 0;
    double roll_deg = 0, pitch_deg = 0, yaw_deg = 0;
};

} // namespace vksonar
