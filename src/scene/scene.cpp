// Scene: ownership of SceneData and the engine-facing builder (add_mesh / add_material / add_draw).
// The glTF loader (gltf_loader.cpp) fills the same SceneData directly, after its own validation.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <limits>
#include <new>
#include <string>
#include <utility>
#include <vector>

#include "core/plan.h"
#include "scene/scene_data.h"
#include "vksonar/scene.h"

namespace vksonar {

const SceneData& detail::Access::scene(const Scene& scene) {
    return *scene.data_;
}

Scene detail::Access::copy(const Scene& scene) {
    Scene out;
    *out.data_ = *scene.data_;
    return out;
}

Scene::Scene() : data_(std::make_unique<SceneData>()) {}
Scene::~Scene() = default;

// A moved-from Scene stays usable (empty), so data() never dereferences null. Allocating an empty
// SceneData cannot reasonably fail; if it does, terminate is the right answer for a noexcept move.
Scene::Scene(Scene&& other) noexcept : data_(std::make_unique<SceneData>()) {
    data_.swap(other.data_);
}

Scene& Scene::operator=(Scene&& other) noexcept {
    data_.swap(other.data_);
    return *this;
}

Result<std::uint32_t> Scene::add_mesh(const float* positions_xyz, std::uint32_t vertex_count,
                                      const std::uint32_t* indices, std::uint32_t index_count) {
    const auto fail = [](std::string what) {
        return make_error(ErrorCode::invalid_argument, "Scene::add_mesh: " + std::move(what));
    };
    if (vertex_count == 0 || positions_xyz == nullptr) return fail("positions_xyz is null or vertex_count is 0");
    if (index_count == 0 || indices == nullptr) return fail("indices is null or index_count is 0");
    if (index_count % 3 != 0)
        return fail("index_count " + std::to_string(index_count) + " is not a multiple of 3 (triangle list)");

    SceneData& d = *data_;
    constexpr std::uint64_t max_u32 = std::numeric_limits<std::uint32_t>::max();
    if (d.positions.size() / 3 + vertex_count > max_u32 || d.indices.size() + index_count > max_u32)
        return fail("scene would exceed 2^32 vertices or indices");

    for (std::uint32_t v = 0; v < vertex_count; ++v) {
        for (int k = 0; k < 3; ++k) {
            if (!std::isfinite(positions_xyz[3 * std::size_t(v) + std::size_t(k)]))
                return fail("vertex " + std::to_string(v) + " has a NaN or Inf coordinate");
        }
    }
    for (std::uint32_t i = 0; i < index_count; ++i) {
        if (indices[i] >= vertex_count)
            return fail("index " + std::to_string(i) + " = " + std::to_string(indices[i]) +
                        " is out of range (vertex_count " + std::to_string(vertex_count) + ")");
    }

    MeshRange range;
    range.first_index = static_cast<std::uint32_t>(d.indices.size());
    range.index_count = index_count;
    range.first_vertex = static_cast<std::uint32_t>(d.positions.size() / 3);
    range.vertex_count = vertex_count;
    // Out of memory part way (appending, or in the spatial ordering, which rewrites only this mesh's
    // tail of the arrays): the arrays are cut back to their sizes before the call, so the scene is
    // unchanged on failure as for bad input.
    const std::size_t positions_before = d.positions.size(), indices_before = d.indices.size(),
                      meshes_before = d.meshes.size(), materials_before = d.materials.size();
    try {
        d.positions.insert(d.positions.end(), positions_xyz, positions_xyz + 3 * std::size_t(vertex_count));
        d.indices.insert(d.indices.end(), indices, indices + index_count);
        d.meshes.push_back(range);
        order_triangles_spatially(d, range);
        if (d.materials.empty()) d.materials.push_back(AcousticMaterial{"default"});
    } catch (const std::bad_alloc&) {
        d.positions.resize(positions_before); // shrinking: never throws
        d.indices.resize(indices_before);
        d.meshes.resize(meshes_before);
        d.materials.resize(materials_before);
        return make_error(ErrorCode::unsupported, "Scene::add_mesh: out of memory adding " +
                                                      std::to_string(vertex_count) + " vertices and " +
                                                      std::to_string(index_count) + " indices");
    }
    d.stats.meshes = static_cast<std::uint32_t>(d.meshes.size());
    return static_cast<std::uint32_t>(d.meshes.size() - 1);
}

Result<std::uint32_t> Scene::add_material(const AcousticMaterial& material) {
    std::vector<AcousticMaterial>& materials = data_->materials;
    try {
        materials.push_back(material); // (strong guarantee: unchanged if it throws)
    } catch (const std::bad_alloc&) {
        return make_error(ErrorCode::unsupported,
                          "Scene::add_material: out of memory adding material " + std::to_string(materials.size()));
    }
    return static_cast<std::uint32_t>(materials.size() - 1);
}

Result<void> Scene::add_draw(const SceneDraw& draw) {
    SceneData& d = *data_;
    if (draw.mesh >= d.meshes.size())
        return make_error(ErrorCode::invalid_argument, "Scene::add_draw: mesh " + std::to_string(draw.mesh) +
                                                           " does not exist (" + std::to_string(d.meshes.size()) +
                                                           " meshes)");
    if (draw.material >= d.materials.size())
        return make_error(ErrorCode::invalid_argument, "Scene::add_draw: material " + std::to_string(draw.material) +
                                                           " does not exist (" + std::to_string(d.materials.size()) +
                                                           " materials)");
    for (std::size_t k = 0; k < draw.world_from_local.size(); ++k) {
        // Finite also as the float the depth pass's transforms hold (1e39 was taken, became inf there, and
        // the mesh vanished without a word).
        const double v = draw.world_from_local[k];
        if (!std::isfinite(v) || !std::isfinite(static_cast<float>(v)))
            return make_error(ErrorCode::invalid_argument,
                              "Scene::add_draw: world_from_local[" + std::to_string(k) + "] is NaN or Inf (in float)");
    }
    try {
        d.draws.push_back(draw); // (strong guarantee: unchanged if it throws)
    } catch (const std::bad_alloc&) {
        return make_error(ErrorCode::unsupported,
                          "Scene::add_draw: out of memory adding draw " + std::to_string(d.draws.size()));
    }
    d.stats.draws = static_cast<std::uint32_t>(d.draws.size());
    d.stats.triangles += d.meshes[draw.mesh].index_count / 3;
    return {};
}

namespace {
std::string number(double v) {
    char text[32];
    std::snprintf(text, sizeof text, "%g", v);
    return text;
}
} // namespace

Result<void> AcousticMaterial::validate() const {
    const std::string first_problem = [this]() -> std::string {
        // The same physical range as the config's default_backscatter (src/config/config_keys.cpp): 0 dB
        // (1 m^2 per m^2 per sr) is past a perfect Lambertian reflector (-5 dB); below -100 dB no echo
        // reaches a display. NaN stands for "the config's default" (plan.cpp); +-inf is no level.
        if (!std::isnan(backscatter_db) && !(backscatter_db >= -100.0 && backscatter_db <= 0.0))
            return "backscatter_db = " + number(backscatter_db) + " (expected -100 to 0 dB)";
        // a Model cast from a number no model has: the shaders would take it as one model, the plan as another
        if (!(model == Model::lambert || model == Model::constant || model == Model::rough))
            return "model = " + std::to_string(static_cast<int>(model)) + " (expected lambert, constant or rough)";
        if (model != Model::rough) return {}; // the facet parameters mean nothing to the other models
        // m < 0.01 (0.6 deg) makes a mirror whose lobe no pixel grid resolves; m > 1 (45 deg) is past
        // where the Kirchhoff approximation holds (and would make the facet term's peak unbounded).
        if (!(rms_slope >= 0.01 && rms_slope <= 1.0))
            return "rms_slope = " + number(rms_slope) + " (expected 0.01 to 1)";
        // R^2 <= 1 (no interface reflects more than arrives); -100 dB is far below any seabed or target.
        if (!(reflection_db <= 0.0 && reflection_db >= -100.0))
            return "reflection_db = " + number(reflection_db) + " (expected -100 to 0 dB: R^2 <= 1)";
        return {};
    }();
    if (first_problem.empty()) return {};
    return make_error(ErrorCode::invalid_argument, first_problem);
}

double SceneBounds::diagonal_m() const {
    if (empty) return 0.0;
    const double dx = max_m[0] - min_m[0], dy = max_m[1] - min_m[1], dz = max_m[2] - min_m[2];
    return std::sqrt(dx * dx + dy * dy + dz * dz);
}

SceneBounds Scene::bounds() const {
    SceneBounds b;
    const SceneData& d = *data_;
    for (const SceneDraw& draw : d.draws) {
        if (draw.mesh >= d.meshes.size()) continue;
        const MeshRange& mesh = d.meshes[draw.mesh];
        const auto& m = draw.world_from_local; // column-major
        for (std::uint32_t v = 0; v < mesh.vertex_count; ++v) {
            const float* p = &d.positions[(std::size_t(mesh.first_vertex) + v) * 3];
            for (int row = 0; row < 3; ++row) {
                const double w = m[std::size_t(row)] * p[0] + m[std::size_t(4 + row)] * p[1] +
                                 m[std::size_t(8 + row)] * p[2] + m[std::size_t(12 + row)];
                b.min_m[row] = b.empty ? w : std::min(b.min_m[row], w);
                b.max_m[row] = b.empty ? w : std::max(b.max_m[row], w);
            }
            b.empty = false;
        }
    }
    return b;
}

std::optional<AcousticMaterial> acoustic_material_by_name(const std::string& name) {
    struct Entry {
        const char* keyword;
        double backscatter_db;
        AcousticMaterial::Model model;
        double rms_slope, reflection_db; // rough only
    };
    using Model = AcousticMaterial::Model;
    // clang-format off
    static const Entry kTable[] = {
        {"steel", -10, Model::rough, 0.05, -1},   {"iron", -10, Model::rough, 0.05, -1},
        {"metal", -10, Model::rough, 0.05, -1},   {"alumin", -10, Model::rough, 0.05, -1},
        {"concrete", -15, Model::rough, 0.1, -6}, {"stone", -15, Model::rough, 0.15, -6},
        {"rock", -15, Model::rough, 0.2, -6},     {"boulder", -15, Model::rough, 0.2, -6},
        {"brick", -15, Model::rough, 0.1, -6},    {"glass", -15, Model::rough, 0.02, -4},
        {"gravel", -20, Model::lambert, 0, 0},    {"shell", -20, Model::lambert, 0, 0},
        {"wood", -20, Model::lambert, 0, 0},      {"timber", -20, Model::lambert, 0, 0},
        {"rubber", -25, Model::lambert, 0, 0},    {"plastic", -25, Model::lambert, 0, 0},
        {"pvc", -25, Model::lambert, 0, 0},       {"sand", -27, Model::lambert, 0, 0},
        {"mud", -35, Model::lambert, 0, 0},       {"silt", -35, Model::lambert, 0, 0},
        {"clay", -35, Model::lambert, 0, 0},
    };
    // clang-format on
    std::string lower = name;
    std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    for (const Entry& e : kTable) {
        if (lower.find(e.keyword) == std::string::npos) continue;
        AcousticMaterial m;
        m.name = name;
        m.backscatter_db = e.backscatter_db;
        m.model = e.model;
        if (e.model == Model::rough) {
            m.rms_slope = e.rms_slope;
            m.reflection_db = e.reflection_db;
        }
        return m;
    }
    return std::nullopt;
}

const SceneStats& Scene::stats() const {
    return data_->stats;
}
const std::vector<AcousticMaterial>& Scene::materials() const {
    return data_->materials;
}
const std::vector<SceneInstance>& Scene::instances() const {
    return data_->instances;
}
const std::vector<std::string>& Scene::classes() const {
    return data_->classes;
}
const std::string& Scene::effects_json() const {
    return data_->effects_json;
}

namespace {

// The bits of a 10-bit integer spread to every third bit (Morton order in 3-D).
std::uint32_t spread_bits(std::uint32_t x) {
    x &= 0x3ffu;
    x = (x | (x << 16)) & 0x030000ffu;
    x = (x | (x << 8)) & 0x0300f00fu;
    x = (x | (x << 4)) & 0x030c30c3u;
    x = (x | (x << 2)) & 0x09249249u;
    return x;
}

constexpr std::uint32_t kUnset = std::numeric_limits<std::uint32_t>::max();

bool orders_spatially(const MeshRange& mesh) {
    return mesh.index_count / 3 > kClusterTriangles && mesh.vertex_count > 0;
}

// Puts the triangles of `mesh` (in scene.indices, 3 vertex numbers each into its vertices) in the order
// of their centroids along a Morton curve, stable for equal codes.
void sort_triangles(SceneData& scene, const MeshRange& mesh) {
    const std::uint32_t triangles = mesh.index_count / 3, vertex_count = mesh.vertex_count;
    std::uint32_t* const tri = scene.indices.data() + mesh.first_index;
    const float* const pos = scene.positions.data() + 3 * std::size_t(mesh.first_vertex);
    float lo[3] = {std::numeric_limits<float>::max(), std::numeric_limits<float>::max(),
                   std::numeric_limits<float>::max()};
    float hi[3] = {std::numeric_limits<float>::lowest(), std::numeric_limits<float>::lowest(),
                   std::numeric_limits<float>::lowest()};
    for (std::uint32_t v = 0; v < vertex_count; ++v)
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], pos[3 * std::size_t(v) + std::size_t(a)]);
            hi[a] = std::max(hi[a], pos[3 * std::size_t(v) + std::size_t(a)]);
        }
    const double largest =
        std::max({double(hi[0]) - double(lo[0]), double(hi[1]) - double(lo[1]), double(hi[2]) - double(lo[2])});
    // Morton code per triangle, then the triangles by code: a stable LSD radix sort (three passes of 10
    // bits over the 30-bit codes), linear in the triangles where std::sort doubled a million-triangle load.
    // The codes and orders of the passes take turns in four arrays of one number per triangle, three of
    // them one block, which then takes the sorted triangles: 16 bytes per triangle in all.
    std::vector<std::uint32_t> block(3 * std::size_t(triangles)), sorted_order(triangles);
    std::uint32_t* const code_a = block.data();
    std::uint32_t* const code_b = code_a + triangles;
    std::uint32_t* const order_a = code_b + triangles;
    for (std::uint32_t t = 0; t < triangles; ++t) {
        std::uint32_t key = 0;
        for (int a = 0; a < 3; ++a) {
            float c = 0;
            for (int k = 0; k < 3; ++k) {
                const std::uint32_t v = tri[3 * std::size_t(t) + std::size_t(k)];
                c += v < vertex_count ? pos[3 * std::size_t(v) + std::size_t(a)] : lo[a];
            }
            // one scale for all axes (the largest extent): a flat terrain's height must not reorder it
            const float unit = largest > 0 ? float((double(c) / 3.0 - lo[a]) / largest) : 0.0f;
            key |= spread_bits(static_cast<std::uint32_t>(std::clamp(unit, 0.0f, 1.0f) * 1023.0f)) << a;
        }
        code_a[t] = key;
        order_a[t] = t;
    }
    const auto pass = [triangles](int shift, const std::uint32_t* code, const std::uint32_t* order,
                                  std::uint32_t* code_out, std::uint32_t* order_out) {
        std::uint32_t start[1025] = {};
        for (std::uint32_t t = 0; t < triangles; ++t)
            ++start[((code[t] >> shift) & 0x3ffu) + 1];
        for (int b = 0; b < 1024; ++b)
            start[b + 1] += start[b];
        for (std::uint32_t t = 0; t < triangles; ++t) {
            const std::uint32_t slot = start[(code[t] >> shift) & 0x3ffu]++;
            if (code_out) code_out[slot] = code[t];
            order_out[slot] = order[t];
        }
    };
    pass(0, code_a, order_a, code_b, sorted_order.data());
    pass(10, code_b, sorted_order.data(), code_a, order_a);
    pass(20, code_a, order_a, nullptr, sorted_order.data());
    // Triangle t of the sorted mesh is triangle sorted_order[t]: gathered into the block (independent
    // loads, where following the permutation's cycles in place is one long chain of cache misses).
    for (std::uint32_t t = 0; t < triangles; ++t) {
        const std::uint32_t* from = tri + 3 * std::size_t(sorted_order[t]);
        std::copy(from, from + 3, block.data() + 3 * std::size_t(t));
    }
    if (mesh.first_index == 0 && block.size() == scene.indices.size())
        scene.indices.swap(block); // the whole array: no copy
    else
        std::copy(block.begin(), block.end(), tri);
}

// Each run of kClusterTriangles triangles of `tri` (in their final order) gets its own copy of the
// vertices it uses, numbered in order of first use from 0 for the mesh's first run on; returns how many
// copies there are. With `out` null it only counts; otherwise it renumbers `tri` in place and writes the
// copies' positions (from `pos`) to `out`. Out-of-range vertex numbers are kept as they are (the
// clusters skip such a run). `new_index` holds vertex_count kUnset values and is left that way.
std::size_t copy_runs(std::uint32_t* tri, std::uint32_t triangles, const float* pos, std::uint32_t vertex_count,
                      float* out, std::vector<std::uint32_t>& new_index, std::vector<std::uint32_t>& touched) {
    std::size_t copies = 0;
    for (std::uint32_t begin = 0; begin < triangles; begin += kClusterTriangles) {
        for (std::uint32_t v : touched)
            new_index[v] = kUnset;
        touched.clear();
        const std::uint32_t end = std::min(triangles, begin + kClusterTriangles);
        for (std::size_t i = 3 * std::size_t(begin); i < 3 * std::size_t(end); ++i) {
            const std::uint32_t v = tri[i];
            if (v >= vertex_count) continue;
            std::uint32_t& mapped = new_index[v];
            if (mapped == kUnset) {
                mapped = static_cast<std::uint32_t>(copies++);
                touched.push_back(v);
                if (out)
                    std::copy(pos + 3 * std::size_t(v), pos + 3 * std::size_t(v) + 3, out + 3 * std::size_t(mapped));
            }
            if (out) tri[i] = mapped;
        }
    }
    for (std::uint32_t v : touched)
        new_index[v] = kUnset;
    touched.clear();
    return copies;
}

} // namespace

void order_triangles_spatially(SceneData& scene, const MeshRange& mesh_range) {
    const MeshRange mesh = mesh_range; // a copy: the mesh's entry changes below
    if (!orders_spatially(mesh) || scene.meshes.empty() || scene.meshes.back().first_index != mesh.first_index ||
        scene.positions.size() != 3 * (std::size_t(mesh.first_vertex) + mesh.vertex_count))
        return;
    sort_triangles(scene, mesh);
    std::uint32_t* tri = scene.indices.data() + mesh.first_index;
    const std::uint32_t triangles = mesh.index_count / 3;
    const float* pos = scene.positions.data() + 3 * std::size_t(mesh.first_vertex);
    std::vector<std::uint32_t> new_index(mesh.vertex_count, kUnset), touched;
    std::vector<float> copies(3 * copy_runs(tri, triangles, pos, mesh.vertex_count, nullptr, new_index, touched));
    copy_runs(tri, triangles, pos, mesh.vertex_count, copies.data(), new_index, touched);
    // The mesh is the scene's last (its vertices end the array): they are replaced by the runs' copies.
    scene.positions.resize(3 * std::size_t(mesh.first_vertex));
    scene.positions.insert(scene.positions.end(), copies.begin(), copies.end());
    scene.meshes.back().vertex_count = static_cast<std::uint32_t>(copies.size() / 3);
}

void order_triangles_spatially(SceneData& scene) {
    std::size_t vertices = 0;
    std::uint32_t widest = 0; // the most vertices of a mesh that is put in order
    for (const MeshRange& mesh : scene.meshes) {
        if (mesh.first_vertex != vertices || std::size_t(mesh.first_index) + mesh.index_count > scene.indices.size())
            return; // not one after another: not what the loader writes
        vertices += mesh.vertex_count;
        if (orders_spatially(mesh)) widest = std::max(widest, mesh.vertex_count);
    }
    if (widest == 0 || 3 * vertices != scene.positions.size()) return;
    // Each mesh in order, then the number of its vertices with the runs' copies; then one array of
    // exactly that many, filled mesh after mesh.
    std::vector<std::uint32_t> new_index(widest, kUnset), touched;
    std::vector<std::size_t> counts(scene.meshes.size());
    std::size_t total = 0;
    for (std::size_t m = 0; m < scene.meshes.size(); ++m) {
        const MeshRange& mesh = scene.meshes[m];
        counts[m] = mesh.vertex_count;
        if (orders_spatially(mesh)) {
            sort_triangles(scene, mesh);
            std::uint32_t* tri = scene.indices.data() + mesh.first_index;
            const float* pos = scene.positions.data() + 3 * std::size_t(mesh.first_vertex);
            counts[m] = copy_runs(tri, mesh.index_count / 3, pos, mesh.vertex_count, nullptr, new_index, touched);
        }
        total += counts[m];
    }
    std::vector<float> positions(3 * total);
    std::size_t next = 0;
    for (std::size_t m = 0; m < scene.meshes.size(); ++m) {
        MeshRange& mesh = scene.meshes[m];
        const float* pos = scene.positions.data() + 3 * std::size_t(mesh.first_vertex);
        float* out = positions.data() + 3 * next;
        if (orders_spatially(mesh))
            copy_runs(scene.indices.data() + mesh.first_index, mesh.index_count / 3, pos, mesh.vertex_count, out,
                      new_index, touched);
        else
            std::copy(pos, pos + 3 * std::size_t(mesh.vertex_count), out);
        mesh.first_vertex = static_cast<std::uint32_t>(next);
        mesh.vertex_count = static_cast<std::uint32_t>(counts[m]);
        next += counts[m];
    }
    scene.positions.swap(positions);
}

} // namespace vksonar
