// Scene loading: bundled scenes, the y-up -> z-up mapping, node transforms, acoustic materials,
// primitive handling, the add_mesh builder, and a corpus of malformed files that must fail cleanly.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "scene/gltf_draco.h"
#include "scene/scene_data.h"
#include "vksonar/scene.h"

namespace vksonar {
namespace {

constexpr double pi = 3.14159265358979323846;

std::string test_file(const std::string& rel) {
    return std::string(VKSONAR_TEST_DIR) + "/data/" + rel;
}
std::string asset_file(const std::string& rel) {
    return std::string(VKSONAR_ASSET_DIR) + "/scenes/" + rel;
}

using Vec3 = std::array<double, 3>;

Vec3 transform_point(const std::array<double, 16>& m, const Vec3& p) {
    Vec3 out{};
    for (int r = 0; r < 3; ++r)
        out[r] = m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r];
    return out;
}

Vec3 local_vertex(const SceneData& d, const MeshRange& mesh, std::uint32_t v) {
    const float* p = &d.positions[3 * std::size_t(mesh.first_vertex + v)];
    return {p[0], p[1], p[2]};
}

// World positions of every vertex a draw uses.
std::vector<Vec3> world_vertices(const SceneData& d, const SceneDraw& draw) {
    const MeshRange& mesh = d.meshes[draw.mesh];
    std::vector<Vec3> out;
    for (std::uint32_t v = 0; v < mesh.vertex_count; ++v)
        out.push_back(transform_point(draw.world_from_local, local_vertex(d, mesh, v)));
    return out;
}

struct Box {
    Vec3 lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
    void add(const Vec3& p) {
        for (int k = 0; k < 3; ++k)
            lo[k] = std::min(lo[k], p[k]), hi[k] = std::max(hi[k], p[k]);
    }
    Vec3 centre() const { return {(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2}; }
};

Box draw_box(const SceneData& d, const SceneDraw& draw) {
    Box b;
    for (const Vec3& p : world_vertices(d, draw))
        b.add(p);
    return b;
}

Box scene_box(const SceneData& d) {
    Box b;
    for (const SceneDraw& draw : d.draws)
        for (const Vec3& p : world_vertices(d, draw))
            b.add(p);
    return b;
}

Scene load_ok(const std::string& path) {
    Result<Scene> r = Scene::load_gltf(path);
    EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
    if (!r.ok()) return Scene{};
    return std::move(r).value();
}

// Every draw refers to an existing mesh and material, and index ranges are consistent.
void expect_consistent(const SceneData& d) {
    std::uint64_t triangles = 0;
    for (const SceneDraw& draw : d.draws) {
        ASSERT_LT(draw.mesh, d.meshes.size());
        ASSERT_LT(draw.material, d.materials.size());
        triangles += d.meshes[draw.mesh].index_count / 3;
    }
    EXPECT_EQ(d.stats.triangles, triangles);
    EXPECT_EQ(d.stats.draws, d.draws.size());
    EXPECT_EQ(d.stats.meshes, d.meshes.size());
    for (const MeshRange& m : d.meshes) {
        EXPECT_EQ(m.index_count % 3, 0u);
        ASSERT_LE(std::size_t(m.first_index) + m.index_count, d.indices.size());
        ASSERT_LE(3 * (std::size_t(m.first_vertex) + m.vertex_count), d.positions.size());
        for (std::uint32_t i = 0; i < m.index_count; ++i)
            ASSERT_LT(d.indices[m.first_index + i], m.vertex_count);
    }
    for (float x : d.positions)
        ASSERT_TRUE(std::isfinite(x));
}

// ---- bundled scenes ----------------------------------------------------------------------------

struct BundledCase {
    const char* file;
    std::size_t draws, meshes, materials;
    std::uint64_t triangles;
    Box bounds; // expected world bounds, each side within 0.5 m
};

class BundledScene : public ::testing::TestWithParam<BundledCase> {};

TEST_P(BundledScene, LoadsWithExpectedContents) {
    const BundledCase& c = GetParam();
    const Scene scene = load_ok(asset_file(c.file));
    const SceneData& d = scene_data(scene);
    EXPECT_EQ(d.draws.size(), c.draws);
    EXPECT_EQ(d.meshes.size(), c.meshes);
    EXPECT_EQ(d.materials.size(), c.materials);
    EXPECT_EQ(scene.stats().triangles, c.triangles);
    EXPECT_LT(scene.stats().triangles, 20000u);
    EXPECT_EQ(scene.stats().skipped_primitives, 0u);
    EXPECT_TRUE(scene.stats().warnings.empty()) << scene.stats().warnings.front();
    EXPECT_TRUE(scene.effects_json().empty());
    expect_consistent(d);
    const Box b = scene_box(d);
    for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(b.lo[k], c.bounds.lo[k], 0.5) << "axis " << k;
        EXPECT_NEAR(b.hi[k], c.bounds.hi[k], 0.5) << "axis " << k;
    }
    for (const AcousticMaterial& m : scene.materials()) {
        EXPECT_FALSE(m.name.empty());
        EXPECT_LT(m.backscatter_db, -5.0);
        EXPECT_GT(m.backscatter_db, -40.0);
    }
}

INSTANTIATE_TEST_SUITE_P(
    Scenes, BundledScene,
    ::testing::Values(BundledCase{"default.gltf", 7, 5, 3, 5852, {{-5, -30, -5.1}, {55, 30, 5}}},
                      BundledCase{"harbour.gltf", 12, 5, 4, 4004, {{-20, -40, -8.1}, {60, 40, 2}}},
                      BundledCase{"tilted_seafloor.gltf", 6, 6, 2, 4940, {{-4.5, -30, -13.3}, {54.5, 30, -2.7}}}),
    [](const auto& param_info) {
        std::string name = param_info.param.file;
        return name.substr(0, name.find('.'));
    });

TEST(BundledScene, DefaultObjectsSitAheadOfTheSonarOnTheSeabed) {
    const Scene scene = load_ok(asset_file("default.gltf"));
    const SceneData& d = scene_data(scene);
    ASSERT_FALSE(d.draws.empty());
    ASSERT_EQ(d.materials[0].name, "seabed_sand");
    EXPECT_DOUBLE_EQ(d.materials[0].backscatter_db, -30.0);
    int objects = 0;
    for (const SceneDraw& draw : d.draws) {
        const Box b = draw_box(d, draw);
        if (draw.material == 0) { // the seabed: flat at z = -5 m, small relief
            EXPECT_NEAR(b.lo[2], -5.0, 0.1);
            EXPECT_NEAR(b.hi[2], -5.0, 0.1);
            continue;
        }
        ++objects;
        const Vec3 c = b.centre();
        const double range = std::hypot(c[0], c[1]);
        EXPECT_GT(range, 5.0);
        EXPECT_LT(range, 30.0);
        EXPECT_LT(std::abs(std::atan2(c[1], c[0])), 40.0 * pi / 180.0);
        EXPECT_NEAR(b.lo[2], -5.0, 0.05) << "object rests on the seabed";
        EXPECT_TRUE(d.materials[draw.material].name == "steel" || d.materials[draw.material].name == "concrete");
    }
    EXPECT_EQ(objects, 6);
}

TEST(BundledScene, TiltedSeafloorRisesAwayFromTheSonar) {
    const Scene scene = load_ok(asset_file("tilted_seafloor.gltf"));
    const SceneData& d = scene_data(scene);
    ASSERT_FALSE(d.draws.empty());
    const double slope = std::tan(10.0 * pi / 180.0);
    const auto plane_z = [&](double x) { return -8.0 + slope * (x - 25.0); };
    for (const Vec3& p : world_vertices(d, d.draws[0]))
        ASSERT_NEAR(p[2], plane_z(p[0]), 0.2);
    for (std::size_t i = 1; i < d.draws.size(); ++i) { // rocks rest on the slope
        double lowest = 1e300;
        for (const Vec3& p : world_vertices(d, d.draws[i]))
            lowest = std::min(lowest, p[2] - plane_z(p[0]));
        EXPECT_LT(std::abs(lowest), 0.6) << "draw " << i;
    }
}

// ---- frames and transforms ---------------------------------------------------------------------

TEST(SceneFrame, GltfYUpMapsToWorldZUp) {
    const Scene scene = load_ok(test_file("scenes/plane_10m.gltf"));
    const SceneData& d = scene_data(scene);
    ASSERT_EQ(d.draws.size(), 1u);
    const auto& m = d.draws[0].world_from_local;
    const Vec3 up = transform_point(m, {0, 1, 0});
    EXPECT_EQ(up, (Vec3{0, 0, 1}));
    EXPECT_EQ(transform_point(m, {0, 0, 1}), (Vec3{0, -1, 0}));
    EXPECT_EQ(transform_point(m, {1, 0, 0}), (Vec3{1, 0, 0}));

    const Box b = draw_box(d, d.draws[0]);
    EXPECT_NEAR(b.lo[0], 10.0, 1e-6);
    EXPECT_NEAR(b.hi[0], 10.0, 1e-6);
    EXPECT_NEAR(b.lo[1], -2.0, 1e-6);
    EXPECT_NEAR(b.hi[1], 2.0, 1e-6);
    EXPECT_NEAR(b.lo[2], -2.0, 1e-6);
    EXPECT_NEAR(b.hi[2], 2.0, 1e-6);

    // Front faces (counter-clockwise) face the sonar at the origin: normal along -x.
    const MeshRange& mesh = d.meshes[0];
    for (std::uint32_t t = 0; t < mesh.index_count; t += 3) {
        Vec3 p[3];
        for (int k = 0; k < 3; ++k)
            p[k] = transform_point(m, local_vertex(d, mesh, d.indices[mesh.first_index + t + k]));
        const Vec3 u{p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]};
        const Vec3 v{p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]};
        EXPECT_LT(u[1] * v[2] - u[2] * v[1], 0.0);
    }
}

TEST(SceneFrame, NodeHierarchyIsHonoured) {
    const Scene scene = load_ok(test_file("scenes/node_transform.gltf"));
    const SceneData& d = scene_data(scene);
    ASSERT_EQ(d.draws.size(), 2u);
    EXPECT_EQ(d.meshes.size(), 1u) << "a mesh used by two nodes is stored once";
    EXPECT_EQ(d.draws[0].mesh, d.draws[1].mesh);

    // Draw 0: parent T(1,2,3) * child T(0.5,0,0) R(+90 deg about glTF y: (x,y,z) -> (z,y,-x)) S(2).
    // Local (1,0,0): S -> (2,0,0), R -> (0,0,-2), T -> (0.5,0,-2), parent -> (1.5,2,1) glTF -> world (1.5,-1,2).
    // Local (0,1,0): (0,2,0) -> (0,2,0) -> (0.5,2,0) -> (1.5,4,3) -> world (1.5,-3,4).
    // Local (0,0,1): (0,0,2) -> (2,0,0) -> (2.5,0,0) -> (3.5,2,3) -> world (3.5,-3,2).
    const std::vector<Vec3> expected0{{1.5, -1, 2}, {1.5, -3, 4}, {3.5, -3, 2}};
    // Draw 1: matrix columns (0,1,0), (-1,0,0), (0,0,1), translation (10,0,0).
    // (1,0,0) -> (10,1,0) -> world (10,0,1); (0,1,0) -> (9,0,0) -> (9,0,0); (0,0,1) -> (10,0,1) -> (10,-1,0).
    const std::vector<Vec3> expected1{{10, 0, 1}, {9, 0, 0}, {10, -1, 0}};
    const std::vector<Vec3> got0 = world_vertices(d, d.draws[0]);
    const std::vector<Vec3> got1 = world_vertices(d, d.draws[1]);
    ASSERT_EQ(got0.size(), 3u);
    ASSERT_EQ(got1.size(), 3u);
    for (std::size_t v = 0; v < 3; ++v)
        for (int k = 0; k < 3; ++k) {
            EXPECT_NEAR(got0[v][k], expected0[v][k], 1e-9) << "vertex " << v << " axis " << k;
            EXPECT_NEAR(got1[v][k], expected1[v][k], 1e-9) << "vertex " << v << " axis " << k;
        }
}

// ---- materials, primitive kinds, effects ----------------------------------------------------------

TEST(SceneMaterials, ExtrasParsedAndDefaultsApplied) {
    const Scene scene = load_ok(test_file("scenes/primitives.gltf"));
    const auto& mats = scene.materials();
    ASSERT_EQ(mats.size(), 5u); // four from the file + the implicit default
    EXPECT_EQ(mats[0].name, "mud");
    EXPECT_DOUBLE_EQ(mats[0].backscatter_db, -27.0);
    EXPECT_EQ(mats[0].model, AcousticMaterial::Model::lambert);
    EXPECT_EQ(mats[1].name, "steel");
    EXPECT_DOUBLE_EQ(mats[1].backscatter_db, -12.0);
    EXPECT_EQ(mats[1].model, AcousticMaterial::Model::constant);
    EXPECT_EQ(mats[2].name, "plain"); // no extras: documented defaults
    EXPECT_DOUBLE_EQ(mats[2].backscatter_db, -30.0);
    EXPECT_EQ(mats[2].model, AcousticMaterial::Model::lambert);
    EXPECT_DOUBLE_EQ(mats[3].backscatter_db, -20.0);
    EXPECT_EQ(mats[4].name, "default");
    EXPECT_DOUBLE_EQ(mats[4].backscatter_db, -30.0);
    EXPECT_EQ(mats[4].model, AcousticMaterial::Model::lambert);

    const SceneData& d = scene_data(scene);
    ASSERT_EQ(d.draws.size(), 5u);
    const std::vector<std::uint32_t> draw_materials{0, 1, 2, 4, 3};
    for (std::size_t i = 0; i < d.draws.size(); ++i)
        EXPECT_EQ(d.draws[i].material, draw_materials[i]) << i;

    const std::vector<std::string>& w = scene.stats().warnings;
    const auto warned = [&](const char* word) {
        return std::any_of(w.begin(), w.end(), [&](const std::string& s) { return s.find(word) != std::string::npos; });
    };
    EXPECT_TRUE(warned("roughness")) << "unknown extras.vksonar key is reported";
}

TEST(SceneMaterials, ScatteringModelsAndFacetParameters) {
    const Scene scene = load_ok(test_file("scenes/rough_materials.gltf"));
    const auto& mats = scene.materials();
    ASSERT_EQ(mats.size(), 4u);
    EXPECT_EQ(mats[0].model, AcousticMaterial::Model::rough);
    EXPECT_DOUBLE_EQ(mats[0].backscatter_db, -31.0);
    EXPECT_DOUBLE_EQ(mats[0].rms_slope, 0.15);
    EXPECT_DOUBLE_EQ(mats[0].reflection_db, -9.0);
    EXPECT_EQ(mats[1].model, AcousticMaterial::Model::constant) << "lommel_seeliger is the constant model's name too";
    EXPECT_EQ(mats[2].model, AcousticMaterial::Model::lambert);
    EXPECT_EQ(mats[3].model, AcousticMaterial::Model::rough);
    EXPECT_DOUBLE_EQ(mats[3].rms_slope, AcousticMaterial{}.rms_slope) << "documented default";
    EXPECT_DOUBLE_EQ(mats[3].reflection_db, AcousticMaterial{}.reflection_db) << "documented default";

    // A facet parameter on a model that ignores it is said once, naming the material and the key.
    const std::vector<std::string>& w = scene.stats().warnings;
    const auto count = std::count_if(w.begin(), w.end(), [](const std::string& s) {
        return s.find("'mud'") != std::string::npos && s.find("extras.vksonar.rms_slope ignored") != std::string::npos;
    });
    EXPECT_EQ(count, 1) << ::testing::PrintToString(w);
    EXPECT_EQ(w.size(), 1u) << ::testing::PrintToString(w);
}

TEST(SceneMaterials, ValidateNamesTheRoughModelsBadParameter) {
    AcousticMaterial m;
    m.model = AcousticMaterial::Model::rough;
    EXPECT_TRUE(m.validate().ok());
    for (double slope : {0.0, 0.0099, 1.01, -0.1, std::nan(""), std::numeric_limits<double>::infinity()}) {
        m.rms_slope = slope;
        EXPECT_NE(m.validate().error().message.find("rms_slope = "), std::string::npos) << slope;
    }
    m.rms_slope = 0.01;
    EXPECT_TRUE(m.validate().ok()) << "the lower bound is allowed";
    m.rms_slope = 1.0;
    EXPECT_TRUE(m.validate().ok()) << "the upper bound is allowed";
    for (double db : {0.5, std::nan(""), -std::numeric_limits<double>::infinity()}) {
        m.reflection_db = db;
        EXPECT_NE(m.validate().error().message.find("reflection_db = "), std::string::npos) << db;
    }
    m.model = AcousticMaterial::Model::lambert;
    EXPECT_TRUE(m.validate().ok()) << "lambert does not use the facet parameters";
}

TEST(ScenePrimitives, IndexTypesStripsFansAndSkipping) {
    const Scene scene = load_ok(test_file("scenes/primitives.gltf"));
    const SceneData& d = scene_data(scene);
    expect_consistent(d);
    // u8 quad (2), u32 triangle (1), non-indexed (1), strip of 4 (2), fan of 5 (3).
    ASSERT_EQ(d.meshes.size(), 5u);
    const std::vector<std::uint32_t> counts{6, 3, 3, 6, 9};
    for (std::size_t i = 0; i < counts.size(); ++i)
        EXPECT_EQ(d.meshes[i].index_count, counts[i]) << i;
    EXPECT_EQ(scene.stats().triangles, 9u);

    const auto mesh_indices = [&](std::size_t i) {
        const MeshRange& m = d.meshes[i];
        return std::vector<std::uint32_t>(d.indices.begin() + m.first_index,
                                          d.indices.begin() + m.first_index + m.index_count);
    };
    EXPECT_EQ(mesh_indices(0), (std::vector<std::uint32_t>{0, 2, 1, 0, 3, 2}));
    EXPECT_EQ(mesh_indices(2), (std::vector<std::uint32_t>{0, 1, 2}));
    EXPECT_EQ(mesh_indices(3), (std::vector<std::uint32_t>{0, 1, 3, 3, 1, 2})); // strip [0,1,3,2], winding kept
    EXPECT_EQ(mesh_indices(4), (std::vector<std::uint32_t>{0, 1, 2, 0, 2, 3, 0, 3, 4}));

    EXPECT_EQ(scene.stats().skipped_primitives, 3u); // POINTS, LINES, all-degenerate
    const std::vector<std::string>& w = scene.stats().warnings;
    for (const char* word : {"POINTS", "LINES", "degenerate"}) {
        EXPECT_TRUE(std::any_of(w.begin(), w.end(), [&](const std::string& s) {
            return s.find(word) != std::string::npos && s.find("primitives.gltf") != std::string::npos;
        })) << word;
    }
}

TEST(SceneEffects, SceneExtrasEffectsKeptAsJson) {
    const Scene scene = load_ok(test_file("scenes/primitives.gltf"));
    ASSERT_FALSE(scene.effects_json().empty());
    const nlohmann::json effects = nlohmann::json::parse(scene.effects_json());
    EXPECT_EQ(effects, (nlohmann::json{{"speckle", "off"}, {"tvg", "on"}}));
}

// ---- GLB --------------------------------------------------------------------------------------

std::vector<char> read_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void write_bytes(const std::string& path, const std::vector<char>& bytes) {
    std::ofstream out(path, std::ios::binary);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

void append_u32(std::vector<char>& out, std::uint32_t v) {
    for (int k = 0; k < 4; ++k)
        out.push_back(static_cast<char>((v >> (8 * k)) & 0xff));
}

// A GLB of a glTF document and its BIN chunk (each padded to 4 bytes, as the spec asks).
std::vector<char> pack_glb(const nlohmann::json& doc, std::vector<char> bin) {
    std::string text = doc.dump();
    while (text.size() % 4)
        text += ' ';
    while (bin.size() % 4)
        bin.push_back(0);
    std::vector<char> glb{'g', 'l', 'T', 'F'};
    append_u32(glb, 2);
    append_u32(glb, static_cast<std::uint32_t>(12 + 8 + text.size() + 8 + bin.size()));
    append_u32(glb, static_cast<std::uint32_t>(text.size()));
    append_u32(glb, 0x4E4F534Au);
    glb.insert(glb.end(), text.begin(), text.end());
    append_u32(glb, static_cast<std::uint32_t>(bin.size()));
    append_u32(glb, 0x004E4942u);
    glb.insert(glb.end(), bin.begin(), bin.end());
    return glb;
}

// Packs plane_10m.gltf + plane_10m.bin into a GLB, as an exporter would.
// with_empty_uri: the BIN chunk's buffer with "uri": "" (against the spec, which leaves uri out; tinygltf and
// earlier builds read it as the BIN chunk)
std::vector<char> make_plane_glb(bool with_empty_uri = false) {
    nlohmann::json doc = nlohmann::json::parse(read_bytes(test_file("scenes/plane_10m.gltf")));
    doc["buffers"][0].erase("uri");
    if (with_empty_uri) doc["buffers"][0]["uri"] = "";
    return pack_glb(doc, read_bytes(test_file("scenes/plane_10m.bin")));
}

std::string temp_path(const std::string& name) {
    const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "vksonar_scene_test";
    std::filesystem::create_directories(dir);
    return (dir / name).string();
}

// Warnings are printed one per line like errors, so names and keys from the file are escaped there too.
TEST(SceneWarnings, ControlCharactersFromTheFileAreEscaped) {
    std::ifstream in(test_file("bad_gltf/bad_backscatter.gltf"));
    nlohmann::json doc = nlohmann::json::parse(in);
    doc["materials"][0]["name"] = "quay\nwall";
    doc["materials"][0]["extras"]["vksonar"] = {{"backscatter_db", -20.0}, {"rough\tness", 1}};
    const std::string path = temp_path("control_chars_in_names.gltf");
    std::ofstream(path) << doc.dump();
    const Scene scene = load_ok(path);
    EXPECT_EQ(scene_data(scene).materials.at(0).name, "quay\nwall"); // the name itself is kept as written
    const std::vector<std::string>& w = scene.stats().warnings;
    ASSERT_EQ(w.size(), 1u);
    EXPECT_NE(w[0].find("material 0 'quay\\nwall': unknown key extras.vksonar.rough\\tness ignored"), std::string::npos)
        << w[0];
}

// extras.vksonar keys the loader does not read are never dropped in silence: a scene's (it holds effects
// only: a sonar key there is not a config layer) and a node's or mesh's (class only), each one warning
// naming the place and the key; a mesh drawn by two nodes warns once.
TEST(SceneWarnings, UnknownExtrasKeysOfScenesNodesAndMeshes) {
    std::ifstream in(test_file("scenes/node_transform.gltf"));
    nlohmann::json doc = nlohmann::json::parse(in);
    doc["scenes"][0]["extras"]["vksonar"] = {{"beams", 10}, {"effects", {{"speckle", "off"}}}};
    doc["nodes"][2]["extras"]["vksonar"] = {{"klass", "x"}};
    doc["meshes"][0]["extras"]["vksonar"] = {{"class", "tri"}, {"material", "steel"}};
    const std::string path = temp_path("unknown_extras_keys.gltf");
    std::ofstream(path) << doc.dump();
    const Scene scene = load_ok(path);
    EXPECT_FALSE(scene.effects_json().empty()); // the effects are still read
    const std::vector<std::string>& w = scene.stats().warnings;
    ASSERT_EQ(w.size(), 3u) << ::testing::PrintToString(w);
    const auto has = [&](const std::string& text) {
        return std::any_of(w.begin(), w.end(), [&](const std::string& x) { return x.find(text) != std::string::npos; });
    };
    EXPECT_TRUE(has("scene 0: extras.vksonar.beams ignored: a scene's extras.vksonar holds effects only"))
        << ::testing::PrintToString(w);
    EXPECT_TRUE(has("unknown key extras.vksonar.klass ignored")) << ::testing::PrintToString(w);
    EXPECT_TRUE(has("mesh 0: unknown key extras.vksonar.material ignored")) << ::testing::PrintToString(w);
}

// A class on a node without a mesh (an exporter's empty parent holding a diver's parts, Blender's custom
// property on it) holds for the meshes below it, unless one sets its own; its unknown keys are warned about
// as a mesh node's are. It was dropped in silence, and the child took its mesh's class.
TEST(SceneWarnings, AParentsClassHoldsForTheMeshesBelowIt) {
    std::ifstream in(test_file("scenes/node_transform.gltf"));
    nlohmann::json doc = nlohmann::json::parse(in);
    ASSERT_FALSE(doc["nodes"][1].contains("mesh")); // "parent", holding node 0 ("child")
    doc["nodes"][1]["extras"]["vksonar"] = {{"class", "diver"}, {"clas", "typo"}};
    doc["meshes"][0]["extras"]["vksonar"] = {{"class", "tri"}};
    const std::string path = temp_path("parent_class.gltf");
    std::ofstream(path) << doc.dump();
    const Scene scene = load_ok(path);
    const auto class_of = [&](const std::string& node) {
        for (const SceneInstance& i : scene_data(scene).instances)
            if (i.node == node) return i.class_name;
        return std::string("(no instance)");
    };
    EXPECT_EQ(class_of("child"), "diver");
    EXPECT_EQ(class_of("by_matrix"), "tri"); // not below the parent: its mesh's class
    const std::vector<std::string>& w = scene.stats().warnings;
    EXPECT_TRUE(std::any_of(w.begin(), w.end(), [](const std::string& x) {
        return x.find("node 1: unknown key extras.vksonar.clas ignored") != std::string::npos;
    })) << ::testing::PrintToString(w);
    doc["nodes"][0]["extras"]["vksonar"] = {{"class", "hose"}}; // a child's own class wins
    std::ofstream(path) << doc.dump();
    const Scene own = load_ok(path);
    for (const SceneInstance& i : scene_data(own).instances) {
        if (i.node == "child") {
            EXPECT_EQ(i.class_name, "hose");
        }
    }
}

// Animations are not played (a scene is static): one warning says so, where they had been dropped in silence.
TEST(SceneWarnings, AnimationsAreIgnoredWithAWarning) {
    std::ifstream in(test_file("scenes/node_transform.gltf"));
    nlohmann::json doc = nlohmann::json::parse(in);
    doc["animations"] =
        nlohmann::json::array({{{"channels", nlohmann::json::array()}, {"samplers", nlohmann::json::array()}}});
    const std::string path = temp_path("animated.gltf");
    std::ofstream(path) << doc.dump();
    const Scene scene = load_ok(path);
    const std::vector<std::string>& w = scene.stats().warnings;
    ASSERT_EQ(w.size(), 1u) << ::testing::PrintToString(w);
    EXPECT_NE(w[0].find("1 animation(s) ignored"), std::string::npos) << w[0];
}

// Effects put in the file's top-level extras (where a person might look for "the scene's") are not
// read, and the loader says where they go instead of dropping them in silence.
TEST(SceneWarnings, TopLevelExtrasVksonarSaysWhereEffectsGo) {
    std::ifstream in(test_file("scenes/node_transform.gltf"));
    nlohmann::json doc = nlohmann::json::parse(in);
    doc["extras"]["vksonar"] = {{"effects", {{"speckle", "off"}}}};
    const std::string path = temp_path("top_level_extras.gltf");
    std::ofstream(path) << doc.dump();
    const Scene scene = load_ok(path);
    EXPECT_TRUE(scene.effects_json().empty()); // not read: effects belong to a scene
    const std::vector<std::string>& w = scene.stats().warnings;
    ASSERT_EQ(w.size(), 1u) << ::testing::PrintToString(w);
    EXPECT_EQ(w[0], path + ": extras.vksonar at the file's top level ignored: a scene's effects go in "
                           "scenes[N].extras.vksonar.effects");
}

// Objects for ground-truth labels (SceneInstance): the node index + 1, the class from the node's
// extras, else its mesh's, else the mesh's name; every draw of a node carries its id.
TEST(SceneObjects, IdsAreNodeIndicesAndClassesComeFromExtrasOrTheMeshName) {
    std::ifstream in(test_file("scenes/node_transform.gltf"));
    nlohmann::json doc = nlohmann::json::parse(in);
    // node 0 'child' (mesh 0, under node 1 'parent'), node 2 'by_matrix' (mesh 0)
    doc["nodes"][2]["extras"]["vksonar"]["class"] = "special";
    const std::string named = temp_path("objects_named.gltf");
    std::ofstream(named) << doc.dump();
    Scene scene = load_ok(named);
    ASSERT_EQ(scene.instances().size(), 2u);
    // The node tree is walked from the scene's roots: parent (no mesh), its child, then by_matrix.
    const SceneInstance& child = scene.instances()[0];
    const SceneInstance& by_matrix = scene.instances()[1];
    EXPECT_EQ(child.id, 1u);
    EXPECT_EQ(child.node, "child");
    EXPECT_EQ(child.mesh, "tri");
    EXPECT_EQ(child.class_name, "tri"); // no extras: the mesh's name
    EXPECT_EQ(by_matrix.id, 3u);
    EXPECT_EQ(by_matrix.class_name, "special");
    EXPECT_EQ(scene.classes(), (std::vector<std::string>{"tri", "special"}));
    EXPECT_EQ(child.class_id, 1u);
    EXPECT_EQ(by_matrix.class_id, 2u);
    const SceneData& d = scene_data(scene);
    ASSERT_EQ(d.draws.size(), 2u);
    EXPECT_EQ(d.draws[0].instance, 1u);
    EXPECT_EQ(d.draws[1].instance, 3u);

    // A mesh's class applies to every node of it without one of its own.
    doc["meshes"][0]["extras"]["vksonar"]["class"] = "triangle";
    const std::string meshed = temp_path("objects_mesh_class.gltf");
    std::ofstream(meshed) << doc.dump();
    scene = load_ok(meshed);
    EXPECT_EQ(scene.instances()[0].class_name, "triangle");
    EXPECT_EQ(scene.instances()[1].class_name, "special");

    // A class that is not a name is an error naming the node, the key and the value.
    doc["nodes"][2]["extras"]["vksonar"]["class"] = 5;
    const std::string bad = temp_path("objects_bad_class.gltf");
    std::ofstream(bad) << doc.dump();
    auto refused = Scene::load_gltf(bad);
    ASSERT_FALSE(refused);
    EXPECT_NE(refused.error().message.find("node 2: extras.vksonar.class = 5 is not a name"), std::string::npos)
        << refused.error().message;
}

TEST(SceneObjects, BundledScenesNameTheirClasses) {
    const Scene harbour = load_ok(asset_file("harbour.gltf"));
    EXPECT_EQ(harbour.classes(), (std::vector<std::string>{"seabed", "wall", "pier", "piling", "crate"}));
    const auto pilings = std::count_if(harbour.instances().begin(), harbour.instances().end(),
                                       [](const SceneInstance& i) { return i.class_name == "piling"; });
    EXPECT_EQ(pilings, 8); // 4 x 2 piles under the pier
    const Scene tilted = load_ok(asset_file("tilted_seafloor.gltf"));
    EXPECT_EQ(tilted.classes(), (std::vector<std::string>{"seabed", "rock", "block"}));
    const Scene standard = load_ok(asset_file("default.gltf"));
    EXPECT_EQ(standard.classes(), (std::vector<std::string>{"seabed", "piling", "pipe", "crate", "sphere"}));
    for (const SceneDraw& draw : scene_data(standard).draws)
        EXPECT_GT(draw.instance, 0u) << "every draw of a loaded scene belongs to an object";
}

TEST(SceneGlb, RoundTripMatchesTheGltf) {
    const std::string path = temp_path("plane_roundtrip.glb");
    write_bytes(path, make_plane_glb());
    const Scene glb = load_ok(path);
    const Scene gltf = load_ok(test_file("scenes/plane_10m.gltf"));
    const Scene generated = load_ok(test_file("scenes/plane_10m.glb"));
    for (const Scene* s : {&glb, &generated}) {
        EXPECT_EQ(scene_data(*s).positions, scene_data(gltf).positions);
        EXPECT_EQ(scene_data(*s).indices, scene_data(gltf).indices);
        ASSERT_EQ(scene_data(*s).draws.size(), 1u);
        EXPECT_EQ(scene_data(*s).draws[0].world_from_local, scene_data(gltf).draws[0].world_from_local);
    }
}

TEST(SceneGlb, EveryTruncationFailsCleanly) {
    const std::vector<char> glb = make_plane_glb();
    const std::string path = temp_path("plane_truncated.glb");
    for (std::size_t n = 0; n < glb.size(); ++n) {
        write_bytes(path, std::vector<char>(glb.begin(), glb.begin() + static_cast<std::ptrdiff_t>(n)));
        const Result<Scene> r = Scene::load_gltf(path);
        ASSERT_FALSE(r.ok()) << "prefix of " << n << " bytes loaded";
        EXPECT_NE(r.error().message.find("plane_truncated.glb"), std::string::npos) << r.error().message;
        EXPECT_EQ(r.error().message.find('\n'), std::string::npos) << r.error().message;
    }
}

// What the audit's checks must not refuse (a reviewer's): a GLB whose BIN buffer says "uri": "", and a matrix
// beside default translation / rotation / scale; a matrix beside a translation that moves it is refused.
TEST(SceneGlb, LenientWhereNothingIsAmbiguous) {
    const std::string glb_path = temp_path("plane_empty_uri.glb");
    write_bytes(glb_path, make_plane_glb(/*with_empty_uri=*/true));
    const Scene glb = load_ok(glb_path);
    EXPECT_EQ(scene_data(glb).positions, scene_data(load_ok(test_file("scenes/plane_10m.gltf"))).positions);

    nlohmann::json doc = nlohmann::json::parse(read_bytes(test_file("scenes/plane_10m.gltf")));
    doc["buffers"][0]["uri"] = (std::filesystem::path(test_file("scenes/plane_10m.bin"))).filename().string();
    auto& node = doc["nodes"][0];
    node.erase("translation");
    node.erase("rotation");
    node.erase("scale");
    node["matrix"] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    node["translation"] = {0, 0, 0};
    node["rotation"] = {0, 0, 0, 1};
    node["scale"] = {1, 1, 1};
    const std::string path = temp_path("matrix_and_trs.gltf"); // beside a copy of its buffer
    write_bytes((std::filesystem::path(path).parent_path() / doc["buffers"][0]["uri"].get<std::string>()).string(),
                read_bytes(test_file("scenes/plane_10m.bin")));
    const auto load_text = [&](const nlohmann::json& d) {
        const std::string text = d.dump();
        write_bytes(path, std::vector<char>(text.begin(), text.end()));
        return Scene::load_gltf(path);
    };
    const Result<Scene> defaults = load_text(doc);
    EXPECT_TRUE(defaults.ok()) << (defaults.ok() ? "" : defaults.error().message);
    node["translation"] = {1, 0, 0};
    const Result<Scene> moved = load_text(doc);
    ASSERT_FALSE(moved.ok());
    EXPECT_NE(moved.error().message.find("has both a matrix and translation"), std::string::npos)
        << moved.error().message;
}

// A node whose transform flattens its mesh (a zero scale) loads, and says that nothing of it is drawn.
TEST(SceneGlb, AZeroScaleIsAWarning) {
    nlohmann::json doc = nlohmann::json::parse(read_bytes(test_file("scenes/primitives.gltf")));
    ASSERT_TRUE(doc["nodes"].is_array() && !doc["nodes"].empty());
    std::size_t with_mesh = 0;
    while (with_mesh < doc["nodes"].size() && !doc["nodes"][with_mesh].contains("mesh"))
        ++with_mesh;
    ASSERT_LT(with_mesh, doc["nodes"].size());
    doc["nodes"][with_mesh].erase("matrix");
    doc["nodes"][with_mesh]["scale"] = {0.0, 0.0, 0.0};
    const std::string path = temp_path("zero_scale.gltf");
    const std::string text = doc.dump();
    write_bytes(path, std::vector<char>(text.begin(), text.end()));
    const Scene scene = load_ok(path);
    const auto& w = scene.stats().warnings;
    const std::string expected = "node " + std::to_string(with_mesh) + ": its transform flattens its meshes";
    EXPECT_TRUE(std::any_of(w.begin(), w.end(), [&](const std::string& s) { return s.find(expected) != s.npos; }))
        << (w.empty() ? std::string("no warnings") : w.front());
}

// An id written as a whole-number float (0.0): tinygltf reads it as no value, so a mesh, a child, a material
// or the indices were dropped in silence (a material's backscatter became the default's; the vertices read
// as a plain triangle list). Refused, naming the field.
TEST(SceneGlb, IdsWrittenAsFloatsAreRefusedNamingTheField) {
    const nlohmann::json doc = nlohmann::json::parse(read_bytes(test_file("scenes/primitives.gltf")));
    std::size_t with_mesh = 0;
    while (with_mesh < doc["nodes"].size() && !doc["nodes"][with_mesh].contains("mesh"))
        ++with_mesh;
    ASSERT_LT(with_mesh, doc["nodes"].size());
    const std::string node = "nodes[" + std::to_string(with_mesh) + "]";
    const auto refused = [](nlohmann::json d, const std::string& field) {
        const std::string path = temp_path("float_id.gltf");
        const std::string text = d.dump();
        write_bytes(path, std::vector<char>(text.begin(), text.end()));
        const Result<Scene> loaded = Scene::load_gltf(path);
        ASSERT_FALSE(loaded.ok()) << field;
        EXPECT_NE(loaded.error().message.find(field + " = "), std::string::npos) << loaded.error().message;
        EXPECT_NE(loaded.error().message.find("without a fraction"), std::string::npos) << loaded.error().message;
    };
    nlohmann::json mesh = doc;
    mesh["nodes"][with_mesh]["mesh"] = mesh["nodes"][with_mesh]["mesh"].get<double>();
    refused(mesh, node + ".mesh");
    nlohmann::json indices = doc;
    auto& primitive = indices["meshes"][0]["primitives"][0];
    ASSERT_TRUE(primitive.contains("indices"));
    primitive["indices"] = primitive["indices"].get<double>();
    refused(indices, "meshes[0].primitives[0].indices");
    nlohmann::json scenes = doc;
    ASSERT_TRUE(scenes.contains("scenes"));
    scenes["scenes"][0]["nodes"][0] = scenes["scenes"][0]["nodes"][0].get<double>();
    refused(scenes, "scenes[0].nodes[0]");
}

// An accessor without a bufferView (and not sparse) holds zeros, as glTF says: a primitive whose POSITION is
// one is all-degenerate and skipped with the usual warning, the rest of the mesh drawn. It was refused.
TEST(SceneGlb, AnAccessorWithoutABufferViewIsZeros) {
    nlohmann::json doc = nlohmann::json::parse(read_bytes(test_file("scenes/primitives.gltf")));
    const Scene plain = load_ok(test_file("scenes/primitives.gltf"));
    doc["accessors"].push_back({{"componentType", 5126}, {"count", 3}, {"type", "VEC3"}});
    doc["meshes"][0]["primitives"].push_back({{"attributes", {{"POSITION", doc["accessors"].size() - 1}}}});
    const std::string path = temp_path("zero_accessor.gltf");
    const std::string text = doc.dump();
    write_bytes(path, std::vector<char>(text.begin(), text.end()));
    const Scene zeros = load_ok(path);
    EXPECT_EQ(zeros.stats().triangles, plain.stats().triangles);
    EXPECT_EQ(zeros.stats().skipped_primitives, plain.stats().skipped_primitives + 1);
    const auto& w = zeros.stats().warnings;
    EXPECT_TRUE(std::any_of(w.begin(), w.end(), [](const std::string& s) {
        return s.find("primitive 8: skipped (all 1 triangles are degenerate)") != s.npos;
    })) << (w.empty() ? std::string("no warnings") : w.back());
}

// Skins (glTF "Skins": a skinned mesh's node transform is ignored; its joints' J IBM place it). A rig whose
// mesh node sits under a moved armature (FBX2glTF, Mixamo): the bone's J IBM is the identity, the vertices
// stay as written (x 10 m); the node's own transform had put it at 16 m. One whose mesh node carries the
// transform the bind baked into IBM (Blender): J IBM is that transform (x 13 m). A posed joint: drawn
// rigidly where the first joint holds it, with a warning that says so.
TEST(SceneGlb, ASkinnedMeshIsPlacedByItsJoints) {
    // nodes, scene roots, the skin's joints, its inverse bind matrices (translations), and instance translations
    // (EXT_mesh_gpu_instancing) for the skinned node, if any
    const auto load_skinned = [](const nlohmann::json& nodes, const std::vector<int>& roots,
                                 const std::vector<int>& joints,
                                 const std::vector<std::array<float, 3>>& ibm_translations,
                                 const std::vector<std::array<float, 3>>& instances = {}) {
        nlohmann::json doc = nlohmann::json::parse(read_bytes(test_file("scenes/plane_10m.gltf")));
        std::vector<char> bin = read_bytes(test_file("scenes/plane_10m.bin"));
        const auto add_floats = [&](const std::vector<float>& values, std::size_t count, const char* type) {
            while (bin.size() % 4)
                bin.push_back(0);
            const std::size_t offset = bin.size();
            const char* bytes = reinterpret_cast<const char*>(values.data());
            bin.insert(bin.end(), bytes, bytes + values.size() * sizeof(float));
            doc["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", offset}, {"byteLength", bin.size() - offset}});
            doc["accessors"].push_back({{"bufferView", doc["bufferViews"].size() - 1},
                                        {"componentType", 5126},
                                        {"count", count},
                                        {"type", type}});
            return doc["accessors"].size() - 1;
        };
        std::vector<float> ibm;
        for (const auto& t : ibm_translations) // column-major translations
            ibm.insert(ibm.end(), {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, t[0], t[1], t[2], 1});
        const std::size_t ibm_accessor = add_floats(ibm, ibm_translations.size(), "MAT4");
        doc["nodes"] = nodes;
        if (!instances.empty()) {
            std::vector<float> moves;
            for (const auto& t : instances)
                moves.insert(moves.end(), t.begin(), t.end());
            const std::size_t moves_accessor = add_floats(moves, instances.size(), "VEC3");
            for (auto& node : doc["nodes"])
                if (node.contains("skin"))
                    node["extensions"]["EXT_mesh_gpu_instancing"]["attributes"]["TRANSLATION"] = moves_accessor;
            doc["extensionsUsed"] = {"EXT_mesh_gpu_instancing"};
        }
        doc["buffers"][0]["byteLength"] = bin.size();
        doc["buffers"][0].erase("uri");
        doc["scenes"][0]["nodes"] = roots;
        doc["skins"] = nlohmann::json::array({{{"joints", joints}, {"inverseBindMatrices", ibm_accessor}}});
        const std::string path = temp_path("skinned.glb");
        write_bytes(path, pack_glb(doc, bin));
        return Scene::load_gltf(path);
    };
    const auto skinned = [&](const nlohmann::json& nodes, const std::vector<int>& roots, const std::vector<int>& joints,
                             const std::vector<std::array<float, 3>>& ibm_translations,
                             const std::vector<std::array<float, 3>>& instances = {}) {
        Result<Scene> loaded = load_skinned(nodes, roots, joints, ibm_translations, instances);
        EXPECT_TRUE(loaded.ok()) << (loaded.ok() ? "" : loaded.error().message);
        return loaded.ok() ? std::move(loaded.value()) : Scene{};
    };
    const auto refused = [&](const nlohmann::json& nodes, const std::vector<int>& roots, const std::vector<int>& joints,
                             const std::vector<std::array<float, 3>>& ibm_translations, const std::string& why) {
        const Result<Scene> loaded = load_skinned(nodes, roots, joints, ibm_translations);
        ASSERT_FALSE(loaded.ok()) << why;
        EXPECT_NE(loaded.error().message.find(why), std::string::npos) << loaded.error().message;
    };
    const auto warned = [](const Scene& scene, const std::string& text) {
        const auto& w = scene.stats().warnings;
        return std::any_of(w.begin(), w.end(), [&](const std::string& s) { return s.find(text) != s.npos; });
    };
    // under a moved armature: nodes 0 armature (x + 6), 1 bone, 2 the plane; IBM = the bone's world, inverted
    const nlohmann::json armature = {{{"name", "armature"}, {"translation", {6, 0, 0}}, {"children", {1, 2}}},
                                     {{"name", "bone"}},
                                     {{"name", "plane"}, {"mesh", 0}, {"skin", 0}}};
    const Scene rig = skinned(armature, {0}, {1}, {{-6, 0, 0}});
    EXPECT_NEAR(rig.bounds().min_m[0], 10.0, 1e-6);
    EXPECT_NEAR(rig.bounds().max_m[0], 10.0, 1e-6);
    EXPECT_TRUE(warned(rig, "node 2: skin drawn in its bind pose"));
    // the bind's transform in IBM: the plane's node at x + 3, its bone at x + 1, IBM = bone^-1 plane = x + 2
    const nlohmann::json baked = {{{"name", "plane"}, {"mesh", 0}, {"skin", 0}, {"translation", {3, 0, 0}}},
                                  {{"name", "bone"}, {"translation", {1, 0, 0}}}};
    const Scene blender = skinned(baked, {0, 1}, {1}, {{2, 0, 0}});
    EXPECT_NEAR(blender.bounds().min_m[0], 13.0, 1e-6);
    // posed: a second joint (the armature) whose J IBM differs from the bone's, which has moved up 1 m
    nlohmann::json posed = armature;
    posed[1]["translation"] = {0, 1, 0}; // glTF y: the world's z
    const Scene moved = skinned(posed, {0}, {1, 0}, {{-6, 0, 0}, {-6, 0, 0}});
    EXPECT_NEAR(moved.bounds().min_m[0], 10.0, 1e-6);
    EXPECT_NEAR(moved.bounds().min_m[2], -2.0 + 1.0, 1e-6);
    EXPECT_TRUE(warned(moved, "skin drawn rigidly where its first joint holds it"));
    // glTF: at least one inverse bind matrix per joint (the rest unused); fewer, or a joint outside the scene,
    // are refused
    EXPECT_NEAR(skinned(armature, {0}, {1}, {{-6, 0, 0}, {0, 0, 0}}).bounds().min_m[0], 10.0, 1e-6);
    refused(armature, {0}, {1, 0}, {{-6, 0, 0}}, "inverseBindMatrices holds 1 matrices for 2 joints");
    nlohmann::json stray = armature;
    stray.push_back({{"name", "not in the scene"}});
    refused(stray, {0}, {3}, {{0, 0, 0}}, "joint 3 is not a node of the scene");
    // instanced and skinned: each instance through the skin's placement (x 10, y 0 and -5 in the world)
    const Scene twice = skinned(armature, {0}, {1}, {{-6, 0, 0}}, {{0, 0, 0}, {0, 0, 5}});
    EXPECT_EQ(twice.stats().triangles, 4u);
    EXPECT_NEAR(twice.bounds().min_m[0], 10.0, 1e-6);
    EXPECT_NEAR(twice.bounds().min_m[1], -7.0, 1e-6);
}

// A class on a mesh node is its own object's: the objects placed below it (rocks on a seabed) keep theirs,
// where a class on an empty parent is passed down.
TEST(SceneGlb, AMeshParentsClassStaysItsOwn) {
    std::ifstream in(test_file("scenes/node_transform.gltf"));
    nlohmann::json doc = nlohmann::json::parse(in);
    doc["nodes"][2]["children"] = {1}; // by_matrix (a mesh) now holds parent, which holds child
    doc["scenes"][0]["nodes"] = {2};
    doc["nodes"][2]["extras"]["vksonar"] = {{"class", "seafloor"}};
    const std::string path = temp_path("mesh_parent_class.gltf");
    std::ofstream(path) << doc.dump();
    const Scene scene = load_ok(path);
    for (const SceneInstance& i : scene_data(scene).instances) {
        if (i.node == "child") {
            EXPECT_NE(i.class_name, "seafloor");
        }
        if (i.node == "by_matrix") {
            EXPECT_EQ(i.class_name, "seafloor");
        }
    }
}

TEST(SceneGlb, FileWithoutScenesDrawsItsRootNodes) {
    nlohmann::json doc = nlohmann::json::parse(read_bytes(test_file("scenes/primitives.gltf")));
    doc.erase("scenes");
    doc.erase("scene");
    const std::string path = temp_path("no_scenes.gltf");
    const std::string text = doc.dump();
    write_bytes(path, std::vector<char>(text.begin(), text.end()));
    const Scene scene = load_ok(path);
    EXPECT_EQ(scene_data(scene).draws.size(), 5u);
    EXPECT_TRUE(scene.effects_json().empty());
    const auto& w = scene.stats().warnings;
    EXPECT_TRUE(std::any_of(w.begin(), w.end(), [](const std::string& s) { return s.find("no scenes") != s.npos; }));
}

// Random byte corruption of a small glTF never crashes; failures are one-line errors naming the file.
TEST(SceneCorruption, RandomMutationsNeverCrash) {
    const std::vector<char> original = read_bytes(test_file("scenes/primitives.gltf"));
    ASSERT_FALSE(original.empty());
    const std::string path = temp_path("mutated.gltf");
    std::mt19937 rng(1234);
    const char alphabet[] = "0123456789-.eE[]{}\",: ntruefalsnul\\";
    int failures = 0;
    for (int trial = 0; trial < 300; ++trial) {
        std::vector<char> bytes = original;
        const int edits = 1 + static_cast<int>(rng() % 4);
        for (int e = 0; e < edits; ++e)
            bytes[rng() % bytes.size()] = alphabet[rng() % (sizeof alphabet - 1)];
        write_bytes(path, bytes);
        const Result<Scene> r = Scene::load_gltf(path);
        if (r.ok()) {
            expect_consistent(scene_data(*r));
            continue;
        }
        ++failures;
        EXPECT_NE(r.error().message.find("mutated.gltf"), std::string::npos) << r.error().message;
        EXPECT_EQ(r.error().message.find('\n'), std::string::npos) << r.error().message;
        EXPECT_NE(r.error().code, ErrorCode::internal) << r.error().message;
    }
    EXPECT_GT(failures, 0);
}

// ---- malformed input ---------------------------------------------------------------------------

struct BadCase {
    const char* file;
    ErrorCode code;
    const char* keyword;
};

// gtest would print the parameter as raw bytes (pointer values); show the file and keyword instead.
void PrintTo(const BadCase& c, std::ostream* os) {
    *os << c.file << " (expects '" << c.keyword << "')";
}

const BadCase bad_cases[] = {
    {"truncated_json.gltf", ErrorCode::parse, "invalid JSON"},
    {"not_json.gltf", ErrorCode::parse, "invalid JSON"},
    {"empty.gltf", ErrorCode::parse, "empty"},
    {"top_level_array.gltf", ErrorCode::parse, "not an object"},
    {"deep_nesting.gltf", ErrorCode::parse, "nests deeper"},
    {"duplicate_key.gltf", ErrorCode::parse, "member 'nodes' is given twice in one object"},
    // node transforms glTF forbids or no scene has (an audit's): taken in silence before
    {"matrix_and_translation.gltf", ErrorCode::parse, "nodes[0]: has both a matrix and translation / rotation / scale"},
    {"projective_matrix.gltf", ErrorCode::parse, "node 0: matrix is not affine: its last row is 0.5 0 0 1"},
    {"translation_past_float.gltf", ErrorCode::parse, "node 0: its world transform reaches 1e+39"},
    {"bad_magic.glb", ErrorCode::parse, "magic"},
    {"json_named_glb.glb", ErrorCode::parse, "magic"},
    {"truncated.glb", ErrorCode::parse, "truncated"},
    {"bin_chunk_overrun.glb", ErrorCode::parse, "BIN chunk"},
    {"glb_version1.glb", ErrorCode::unsupported, "version 1"},
    // (an audit's: it blamed a "BIN chunk length 1952805747", read from the JSON text)
    {"glb_json_length_short.glb", ErrorCode::parse, "GLB JSON chunk length 4 does not end where a chunk starts"},
    {"uri_bad_percent.gltf", ErrorCode::parse, "has a '%' not followed by two hex digits"},
    {"uri_empty.gltf", ErrorCode::parse, "buffer 0 uri is empty"},
    {"short_buffer.gltf", ErrorCode::parse, "POSITION accessor 0: count 4"},
    {"view_past_buffer.gltf", ErrorCode::parse, "past the end of buffer 0"},
    {"huge_count.gltf", ErrorCode::parse, "count 4294967295"},
    {"negative_count.gltf", ErrorCode::parse, "accessors[1].count = -3: must be an integer >= 0"},
    // What tinygltf took without a word (an audit's): a negative offset read as 0, a translation of
    // strings ignored, a glTF 1.0 file read as 2.0, a matrix one number short.
    {"negative_byte_offset.gltf", ErrorCode::parse, "bufferViews[1].byteOffset = -4: must be an integer >= 0"},
    {"translation_not_numbers.gltf", ErrorCode::parse,
     "nodes[0].translation = [\"x\",0,0]: must be an array of 3 numbers"},
    {"asset_version_1.gltf", ErrorCode::unsupported, "asset.version = \"1.0\": vksonar reads glTF 2.x"},
    {"matrix_15_numbers.gltf", ErrorCode::parse, "nodes[0].matrix = "},
    {"index_out_of_range.gltf", ErrorCode::parse, "index 2 = 7 is out of range"},
    {"missing_position.gltf", ErrorCode::parse, "missing POSITION"},
    {"nan_position.gltf", ErrorCode::parse, "mesh 0 primitive 0: POSITION accessor 0 has NaN at vertex 1"},
    {"inf_position.gltf", ErrorCode::parse, "Inf at vertex 1"},
    {"missing_bin.gltf", ErrorCode::io, "missing.bin"},
    {"wrong_size_bin.gltf", ErrorCode::parse, "wrong_size.bin"},
    {"bad_data_uri.gltf", ErrorCode::parse, "byteLength 46 is more than its data uri holds (42 bytes)"},
    // (a primitive whose stream is not one: refused by name without libdraco, as not Draco with it)
    {"draco_required.gltf", gltf::draco_available() ? ErrorCode::parse : ErrorCode::unsupported,
     gltf::draco_available() ? "KHR_draco_mesh_compression: the stream is not a Draco triangle mesh"
                             : "unsupported required extension KHR_draco_mesh_compression"},
    {"meshopt_bad_stream.gltf", ErrorCode::parse, "EXT_meshopt_compression: the compressed data does not decode"},
    {"node_cycle.gltf", ErrorCode::parse, "cycle"},
    {"bad_mesh_index.gltf", ErrorCode::parse, "mesh 5 does not exist"},
    {"bad_backscatter.gltf", ErrorCode::parse, "backscatter_db"},
    {"backscatter_above_0db.gltf", ErrorCode::parse,
     "material 0 'mirror': extras.vksonar.backscatter_db = 6 (expected -100 to 0 dB)"},
    {"bad_model.gltf", ErrorCode::parse, "phong"},
    {"bad_rms_slope.gltf", ErrorCode::parse, "material 0 'glass': extras.vksonar.rms_slope = 0 (expected 0.01 to 1)"},
    {"bad_reflection.gltf", ErrorCode::parse, "extras.vksonar.reflection_db = 3 (expected -100 to 0 dB"},
    {"bad_rms_slope_type.gltf", ErrorCode::parse, "extras.vksonar.rms_slope = \"smooth\" is not a finite number"},
    {"missing_asset.gltf", ErrorCode::parse, "asset"},
    {"index_count_not_multiple.gltf", ErrorCode::parse, "multiple of 3"},
    {"position_not_float.gltf", ErrorCode::unsupported, "float VEC3"},
    {"bad_default_scene.gltf", ErrorCode::parse, "scene 3"},
    // Names from the file are quoted in messages; control characters in them come out escaped.
    {"newline_in_name.gltf", ErrorCode::parse, "material 0 'quay\\nwall\\x01'"},
    {"newline_in_extension.gltf", ErrorCode::unsupported, "unsupported required extension KHR_\\nmade_up\\r"},
};

class BadGltf : public ::testing::TestWithParam<BadCase> {};

TEST_P(BadGltf, FailsWithAClearOneLineError) {
    const BadCase& c = GetParam();
    const Result<Scene> r = Scene::load_gltf(test_file(std::string("bad_gltf/") + c.file));
    ASSERT_FALSE(r.ok());
    const std::string& msg = r.error().message;
    EXPECT_EQ(r.error().code, c.code) << msg;
    EXPECT_NE(msg.find(c.file), std::string::npos) << msg;
    EXPECT_NE(msg.find(c.keyword), std::string::npos) << "expected '" << c.keyword << "' in: " << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
    EXPECT_LT(msg.size(), 600u) << msg;
}

INSTANTIATE_TEST_SUITE_P(Corpus, BadGltf, ::testing::ValuesIn(bad_cases), [](const auto& param_info) {
    std::string name = param_info.param.file;
    std::replace(name.begin(), name.end(), '.', '_');
    return name;
});

TEST(BadGltf, CorpusAndTableAgree) {
    std::set<std::string> listed;
    for (const BadCase& c : bad_cases)
        listed.insert(c.file);
    std::set<std::string> on_disk;
    for (const auto& entry : std::filesystem::directory_iterator(test_file("bad_gltf"))) {
        const std::string ext = entry.path().extension().string();
        if (ext == ".gltf" || ext == ".glb") on_disk.insert(entry.path().filename().string());
    }
    EXPECT_EQ(listed, on_disk);
}

TEST(BadGltf, MissingFileIsAnIoError) {
    const Result<Scene> r = Scene::load_gltf(test_file("bad_gltf/does_not_exist.gltf"));
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::io);
    EXPECT_NE(r.error().message.find("does_not_exist.gltf"), std::string::npos);
    EXPECT_NE(r.error().message.find("not found"), std::string::npos);

    const Result<Scene> dir = Scene::load_gltf(test_file("bad_gltf"));
    ASSERT_FALSE(dir.ok());
    EXPECT_EQ(dir.error().code, ErrorCode::io);
}

// ---- builder API ----------------------------------------------------------------------------------

TEST(SceneBuilder, AddMeshValidatesItsArrays) {
    Scene scene;
    const float tri[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    const std::uint32_t idx[3] = {0, 1, 2};
    const std::uint32_t bad_idx[3] = {0, 1, 3};
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const float nan_tri[9] = {0, 0, 0, 1, nan, 0, 0, 1, 0};

    const auto expect_invalid = [](const Result<std::uint32_t>& r, const char* word) {
        ASSERT_FALSE(r.ok());
        EXPECT_EQ(r.error().code, ErrorCode::invalid_argument);
        EXPECT_NE(r.error().message.find(word), std::string::npos) << r.error().message;
    };
    expect_invalid(scene.add_mesh(nullptr, 3, idx, 3), "null");
    expect_invalid(scene.add_mesh(tri, 3, nullptr, 3), "null");
    expect_invalid(scene.add_mesh(tri, 3, idx, 2), "multiple of 3");
    expect_invalid(scene.add_mesh(tri, 3, bad_idx, 3), "out of range");
    expect_invalid(scene.add_mesh(nan_tri, 3, idx, 3), "vertex 1");
    EXPECT_TRUE(scene_data(scene).meshes.empty()) << "a rejected mesh leaves no trace";
    EXPECT_TRUE(scene_data(scene).positions.empty());

    const Result<std::uint32_t> mesh = scene.add_mesh(tri, 3, idx, 3);
    ASSERT_TRUE(mesh.ok()) << mesh.error().message;
    EXPECT_EQ(mesh.value(), 0u);
    ASSERT_EQ(scene.materials().size(), 1u) << "the default material exists once a mesh does";
    EXPECT_DOUBLE_EQ(scene.materials()[0].backscatter_db, -30.0);

    AcousticMaterial steel;
    steel.name = "steel";
    steel.backscatter_db = -10;
    const auto added_steel = scene.add_material(steel);
    ASSERT_TRUE(added_steel.ok()) << added_steel.error().message;
    const std::uint32_t steel_index = added_steel.value();
    EXPECT_EQ(steel_index, 1u);

    SceneDraw draw;
    draw.mesh = mesh.value();
    draw.material = steel_index;
    draw.world_from_local[12] = 5.0;
    ASSERT_TRUE(scene.add_draw(draw).ok());
    ASSERT_TRUE(scene.add_draw(draw).ok());
    EXPECT_EQ(scene.stats().draws, 2u);
    EXPECT_EQ(scene.stats().meshes, 1u);
    EXPECT_EQ(scene.stats().triangles, 2u);

    SceneDraw bad = draw;
    bad.mesh = 7;
    EXPECT_EQ(scene.add_draw(bad).error().code, ErrorCode::invalid_argument);
    bad = draw;
    bad.material = 9;
    EXPECT_EQ(scene.add_draw(bad).error().code, ErrorCode::invalid_argument);
    bad = draw;
    bad.world_from_local[5] = std::numeric_limits<double>::infinity();
    EXPECT_EQ(scene.add_draw(bad).error().code, ErrorCode::invalid_argument);
    EXPECT_EQ(scene.stats().draws, 2u);

    // Second mesh: indices stay mesh-local, first_vertex offsets them.
    const Result<std::uint32_t> second = scene.add_mesh(tri, 3, idx, 3);
    ASSERT_TRUE(second.ok());
    EXPECT_EQ(scene_data(scene).meshes[1].first_vertex, 3u);
    EXPECT_EQ(scene_data(scene).meshes[1].first_index, 3u);
    EXPECT_EQ(scene_data(scene).indices[3], 0u);
}

TEST(SceneBuilder, MovedFromSceneIsEmptyAndUsable) {
    Scene a = load_ok(test_file("scenes/plane_10m.gltf"));
    ASSERT_EQ(scene_data(a).draws.size(), 1u);
    Scene b(std::move(a));
    EXPECT_EQ(scene_data(b).draws.size(), 1u);
    EXPECT_TRUE(scene_data(a).draws.empty()); // NOLINT(bugprone-use-after-move): moved-from state is specified
    EXPECT_EQ(a.stats().draws, 0u);
    Scene c;
    c = std::move(b);
    EXPECT_EQ(scene_data(c).draws.size(), 1u);
    EXPECT_EQ(scene_data(c).source_path, test_file("scenes/plane_10m.gltf"));
}

} // namespace
} // namespace vksonar
