// KHR_draco_mesh_compression: the bundled harbour encoded by draco's own encoder (draco::Encoder,
// through src/scene/draco_pack.h, as Blender's compressed export does) loads to the plain scene's
// triangles within the quantization step and renders its polar image within the bound that step
// implies, on both backends, and the two backends agree on it; corrupt streams and accessors that
// disagree with the stream are one-line errors naming the primitive. In a build without libdraco the
// file is refused by name (SceneExtensions.AppearanceIsAWarning...).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "cli_support.h"
#include "core/access.h"
#include "scene/draco_pack.h"
#include "scene/gltf_draco.h"
#include "scene/scene_data.h"
#include "stages/gpu_cpu_support.h"
#include "test_support.h"
#include "tolerances.h"
#include "vksonar/vksonar.h"

namespace vksonar {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using testing::fresh_test_dir;
using testing::remove_test_dir;

const std::string kHarbour = VKSONAR_ASSET_DIR "/scenes/harbour.gltf";
constexpr int kBits = 14; // Blender's default position quantization

class SceneDraco : public ::testing::Test {
protected:
    void SetUp() override {
        if (!gltf::draco_available()) GTEST_SKIP() << "this build has no libdraco";
        dir_ = fresh_test_dir("vksonar_draco_");
    }
    void TearDown() override {
        if (!dir_.empty()) remove_test_dir(dir_);
    }
    std::string pack(const std::string& name, int bits = kBits) {
        const std::string out = (dir_ / name).string();
        const std::string error = gltf::write_draco_gltf(kHarbour, out, bits);
        EXPECT_EQ(error, "");
        return out;
    }
    fs::path dir_;
};

// The quantization step of each mesh: Draco quantizes every axis over the mesh's largest extent,
// step = extent / (2^bits - 1), and rounds to the nearest step: a vertex moves by at most step / 2 on
// each axis.
double half_step(const SceneData& d, const MeshRange& m, int bits) {
    double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
    for (std::uint32_t v = 0; v < m.vertex_count; ++v)
        for (int k = 0; k < 3; ++k) {
            const double x = d.positions[(std::size_t(m.first_vertex) + v) * 3 + std::size_t(k)];
            lo[k] = std::min(lo[k], x);
            hi[k] = std::max(hi[k], x);
        }
    const double extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
    return 0.5 * extent / double((1 << bits) - 1);
}

TEST_F(SceneDraco, HarbourDecodesToThePlainTrianglesWithinTheQuantizationStep) {
    const auto plain = Scene::load_gltf(kHarbour);
    const auto draco = Scene::load_gltf(pack("harbour_draco.glb"));
    ASSERT_TRUE(plain.ok()) << plain.error().message;
    ASSERT_TRUE(draco.ok()) << draco.error().message;
    EXPECT_EQ(draco->stats().triangles, plain->stats().triangles);
    EXPECT_EQ(draco->stats().extensions, std::vector<std::string>{"KHR_draco_mesh_compression"});
    EXPECT_TRUE(draco->stats().warnings.empty());
    const SceneData &a = scene_data(*plain), &b = scene_data(*draco);
    ASSERT_EQ(a.draws.size(), b.draws.size());
    for (std::size_t i = 0; i < a.draws.size(); ++i) {
        // The node transforms are kept exactly; the vertices move within half a step on each axis,
        // every decoded vertex near an original one and every original one near a decoded one.
        EXPECT_EQ(a.draws[i].world_from_local, b.draws[i].world_from_local) << "draw " << i;
        EXPECT_EQ(a.draws[i].material, b.draws[i].material) << "draw " << i;
        const MeshRange &ma = a.meshes[a.draws[i].mesh], &mb = b.meshes[b.draws[i].mesh];
        ASSERT_EQ(ma.index_count, mb.index_count) << "draw " << i;
        const double h = half_step(a, ma, kBits) * (1 + 1e-5) + 1e-6; // + float rounding of the result
        auto nearest = [](const SceneData& from, const MeshRange& fm, const SceneData& to, const MeshRange& tm) {
            double worst = 0;
            for (std::uint32_t v = 0; v < fm.vertex_count; ++v) {
                const float* p = &from.positions[(std::size_t(fm.first_vertex) + v) * 3];
                double best = 1e300;
                for (std::uint32_t u = 0; u < tm.vertex_count && best > 0; ++u) {
                    const float* q = &to.positions[(std::size_t(tm.first_vertex) + u) * 3];
                    best = std::min(best, std::max({std::fabs(double(p[0]) - q[0]), std::fabs(double(p[1]) - q[1]),
                                                    std::fabs(double(p[2]) - q[2])}));
                }
                worst = std::max(worst, best);
            }
            return worst;
        };
        const double decoded_to_plain = nearest(b, mb, a, ma), plain_to_decoded = nearest(a, ma, b, mb);
        std::printf("[draco] draw %zu: %u -> %u vertices, half step %.3g m, moved at most %.3g / %.3g m\n", i,
                    ma.vertex_count, mb.vertex_count, h, decoded_to_plain, plain_to_decoded);
        EXPECT_LE(decoded_to_plain, h) << "draw " << i;
        EXPECT_LE(plain_to_decoded, h) << "draw " << i;
    }
    // Quantization really happened (the test would not see a decoder that ignores it otherwise).
    EXPECT_NE(a.positions, b.positions);
}

// The polar image: every vertex moves by at most h = step / 2 per axis (under 2.5 mm for the 80 m
// seabed, a tenth of a bin), so each pixel's range moves by at most sqrt(3) h and a triangle's area by
// at most sqrt(3) h x its perimeter / 2 (first order). The frame's energy is a sum over the lit
// surface: its relative change is bounded by the area bound summed over the triangles relative to their
// area, plus the change of incidence (tilt of a triangle at most 2 sqrt(3) h over its shortest height),
// both computed here from the plain scene; the energy-weighted mean range moves by at most sqrt(3) h
// plus one bin (a pixel whose range crosses a bin edge lands in the next bin). Cell by cell, pixels at
// silhouette edges flip, so a per-cell bound would not be derivable.
TEST_F(SceneDraco, HarbourRendersLikeThePlainSceneWithinTheQuantizationBound) {
    const auto plain = Scene::load_gltf(kHarbour);
    const auto draco = Scene::load_gltf(pack("harbour_draco.glb"));
    ASSERT_TRUE(plain.ok() && draco.ok());
    const SceneData& a = scene_data(*plain);
    double h = 0, area = 0, area_change = 0, tilt = 0;
    for (const SceneDraw& draw : a.draws) {
        const MeshRange& m = a.meshes[draw.mesh];
        const double hm = std::sqrt(3.0) * half_step(a, m, kBits);
        h = std::max(h, hm);
        for (std::uint32_t t = 0; t < m.index_count; t += 3) {
            const float* p[3];
            for (int k = 0; k < 3; ++k)
                p[k] =
                    &a.positions[(std::size_t(m.first_vertex) + a.indices[m.first_index + t + std::uint32_t(k)]) * 3];
            double e[3], perimeter = 0;
            for (int k = 0; k < 3; ++k) {
                const float *u = p[k], *v = p[(k + 1) % 3];
                e[k] = std::hypot(double(u[0]) - v[0], double(u[1]) - v[1], double(u[2]) - v[2]);
                perimeter += e[k];
            }
            const double s = perimeter / 2;
            const double tri = std::sqrt(std::max(0.0, s * (s - e[0]) * (s - e[1]) * (s - e[2])));
            if (tri <= 0) continue;
            area += tri;
            area_change += hm * perimeter / 2;
            const double shortest_height = 2 * tri / std::max({e[0], e[1], e[2]});
            tilt = std::max(tilt, 2 * hm / shortest_height);
        }
    }
    const double energy_bound = area_change / area + 2 * tilt; // Lambert cos^2: d(cos^2)/cos^2 <= 2 tan x d
    std::printf("[draco] sqrt(3) h = %.3g m, area bound %.3g, tilt %.3g rad, energy bound %.3g\n", h,
                area_change / area, tilt, energy_bound);
    SonarConfig config = testing::quiet_config();
    const Pose pose{-10, 0, 2, 0, 15, 0};
    for (Backend backend : {Backend::cpu, Backend::vulkan}) {
        if (backend == Backend::vulkan && testing::vulkan_context() == nullptr) {
            if (testing::vulkan_required()) ADD_FAILURE() << "no Vulkan device";
            continue;
        }
        testing::ValidationGuard guard;
        const auto ra = testing::render_once(backend, config, plain.value(), pose);
        const auto rb = testing::render_once(backend, config, draco.value(), pose);
        ASSERT_TRUE(ra && rb);
        const auto [ea, ma] = testing::energy_and_mean_range(ra->frame);
        const auto [eb, mb] = testing::energy_and_mean_range(rb->frame);
        const double bin = ra->frame.bin_ranges_m[1] - ra->frame.bin_ranges_m[0];
        std::printf("[draco] %s: energy ratio %.6f, mean range %.4f vs %.4f m (bin %.4f m)\n",
                    backend == Backend::cpu ? "cpu" : "vulkan", eb / ea, mb, ma, bin);
        EXPECT_NEAR(eb / ea, 1.0, energy_bound);
        EXPECT_NEAR(mb, ma, h + bin);
    }
}

// GPU and CPU agree on the Draco scene as on every bundled scene (gpu_cpu_test.cpp's criterion).
TEST_F(SceneDraco, GpuAndCpuAgreeOnTheDracoHarbour) {
    if (testing::vulkan_context() == nullptr) {
        if (testing::vulkan_required()) ADD_FAILURE() << "no Vulkan device";
        GTEST_SKIP() << "no Vulkan device";
    }
    const std::string file = pack("harbour_draco.glb");
    testing::ValidationGuard guard;
    SonarConfig config = testing::quiet_config();
    Pose look_down;
    look_down.pitch_deg = 15.0;
    auto p = testing::render_pair(file, config, look_down, SaveFlags::none);
    ASSERT_TRUE(p);
    const testing::CleanAgreement a = testing::compare_clean(config, p->gpu->frame, p->cpu->frame);
    std::printf("[draco] gpu vs cpu: %zu cells above noise floor, %zu over %.1f dB, max %.2f dB\n", a.above, a.over,
                testing::kFrameDbTol, a.max_db);
    ASSERT_GT(a.above, 0u);
    EXPECT_LE(static_cast<double>(a.over), testing::kFrameCellBudget * a.above);
}

void expect_one_line_error(const Result<Scene>& r, const std::string& needle) {
    ASSERT_FALSE(r.ok()) << "expected an error naming " << needle;
    const std::string& m = r.error().message;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    EXPECT_NE(m.find("KHR_draco_mesh_compression"), std::string::npos) << m;
    EXPECT_NE(m.find(needle), std::string::npos) << m;
}

TEST_F(SceneDraco, CorruptStreamsAndDisagreeingAccessorsAreOneLineErrors) {
    const std::string file = pack("harbour_draco.glb");
    std::ifstream in(file, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::size_t first = bytes.find("DRACO");
    ASSERT_NE(first, std::string::npos);
    auto write = [&](const std::string& name, const std::string& content) {
        std::ofstream(dir_ / name, std::ios::binary) << content;
        return Scene::load_gltf((dir_ / name).string());
    };
    // Not a Draco stream at all.
    std::string bad_magic = bytes;
    bad_magic[first] = 'X';
    expect_one_line_error(write("magic.glb", bad_magic), "mesh 0 primitive 0");
    // A stream whose body is overwritten: it fails to decode, or decodes to counts or positions the
    // accessors do not declare; either way the primitive is named.
    std::string garbage = bytes;
    for (std::size_t i = first + 16; i < std::min(garbage.size(), first + 400); ++i)
        garbage[i] = char((i * 131) & 0xff);
    expect_one_line_error(write("garbage.glb", garbage), "mesh 0 primitive 0");

    // Accessors that disagree with the stream (a .gltf, to edit the JSON).
    const std::string text_file = pack("harbour_draco.gltf");
    std::ifstream tin(text_file);
    const json doc = json::parse(tin);
    json more = doc;
    more["accessors"][0]["count"] = more["accessors"][0]["count"].get<std::size_t>() + 1;
    expect_one_line_error(write("count.gltf", more.dump()), "POSITION accessor 0 declares");
    json fewer = doc;
    fewer["accessors"][1]["count"] = fewer["accessors"][1]["count"].get<std::size_t>() - 3;
    expect_one_line_error(write("indices.gltf", fewer.dump()), "indices accessor 1 declares");
    // (The box may be missed by up to 1/64 of the mesh's largest extent, 1.25 m for the 80 m seabed: the
    // slack of coarse quantization, src/scene/gltf_draco.cpp; this one is 10 m off.)
    json box = doc;
    box["accessors"][0]["max"][1] = box["accessors"][0]["min"][1].get<double>() - 10.0;
    box["accessors"][0]["min"][1] = box["accessors"][0]["min"][1].get<double>() - 11.0;
    expect_one_line_error(write("box.gltf", box.dump()), "min/max");
    json attribute = doc;
    attribute["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]["attributes"]["POSITION"] = 7;
    expect_one_line_error(write("attribute.gltf", attribute.dump()), "no attribute 7");
    // A declaration no stream of this size can hold is refused before the decoder runs.
    json huge = doc;
    huge["accessors"][0]["count"] = 400000000;
    expect_one_line_error(write("huge.gltf", huge.dump()), "more than Draco expands to");
}

// The committed seed of the glTF fuzzer (tests/data/scenes/plane_10m_draco.glb: write_draco_gltf of
// plane_10m.gltf at 14 bits) loads to its source's plate within half the quantization step of its 4 m
// extent (1.2e-4 m).
TEST_F(SceneDraco, CommittedDracoPlateEqualsItsSource) {
    const auto plain = Scene::load_gltf(VKSONAR_TEST_DIR "/data/scenes/plane_10m.gltf");
    const auto packed = Scene::load_gltf(VKSONAR_TEST_DIR "/data/scenes/plane_10m_draco.glb");
    ASSERT_TRUE(plain.ok()) << plain.error().message;
    ASSERT_TRUE(packed.ok()) << packed.error().message;
    const SceneBounds a = plain->bounds(), b = packed->bounds();
    for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(b.min_m[k], a.min_m[k], 1.3e-4) << k;
        EXPECT_NEAR(b.max_m[k], a.max_m[k], 1.3e-4) << k;
    }
    EXPECT_EQ(packed->stats().triangles, plain->stats().triangles);
}

} // namespace
} // namespace vksonar
