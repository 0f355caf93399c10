// GPU-vs-CPU regression suite, whole frames: every bundled scene and preset, patterns, determinism,
// table views, noise. Each stage's own GPU-vs-CPU match on the same input lives with its CPU checks in
// tests/stages/<stage>_test.cpp. Tolerances and their reasons: tests/tolerances.h.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <filesystem>

#include "core/sonar_math.hpp"
#include "scene/scene_data.h"
#include "stages/cpu_stages.h"
#include "stages/gpu_cpu_support.h"
#include "test_support.h"
#include "tolerances.h"
#include "vk/resample_walk.h"
#include "vk/vulkan_backend_impl.h"

namespace vksonar::testing {
namespace {

// The whole frame of each bundled scene on both backends (each stage's own match: tests/stages/).
class FrameTest : public GpuCpuScene {};

TEST_P(FrameTest, WholeFrameAgrees) {
    SonarConfig config = quiet_config();
    config.effects.speckle = EffectMode::on; // seeded noise must be identical on both backends
    config.effects.ambient_noise = EffectMode::on;
    auto p = render_pair(GetParam().file, config, GetParam().pose, SaveFlags::none);
    ASSERT_TRUE(p);
    const Frame& g = p->gpu->frame;
    const Frame& c = p->cpu->frame;
    // The same RNG draws on both: the ratio of noisy to clean intensity of a cell depends only on
    // (seed, frame, beam, bin), so compare the clean scans and check the noise multipliers.
    const CleanAgreement a = compare_clean(config, g, c);
    std::printf("[frame] %s: %zu cells above noise floor, %zu over %.1f dB, max %.2f dB\n", GetParam().file.c_str(),
                a.above, a.over, kFrameDbTol, a.max_db);
    ASSERT_GT(a.above, 0u);
    EXPECT_LE(static_cast<double>(a.over), kFrameCellBudget * a.above);
}

INSTANTIATE_TEST_SUITE_P(BundledScenes, FrameTest, ::testing::ValuesIn(bundled_scenes()), scene_name);

// Whole frame on every bundled preset (the physical model; legacy presets have their own tests):
// the default scene seen with each device's beam table, range window and frequency.
class PresetFrameTest : public ::testing::TestWithParam<std::string> {
protected:
    void SetUp() override { VKSONAR_REQUIRE_VULKAN(); }
    ValidationGuard validation_;
};

std::vector<std::string> physical_presets() {
    std::vector<std::string> out;
    for (const auto& name : preset_names())
        if (name.find("legacy") == std::string::npos) out.push_back(name);
    return out;
}

TEST_P(PresetFrameTest, WholeFrameAgrees) {
    auto preset = load_preset(GetParam());
    ASSERT_TRUE(preset) << preset.error().message;
    SonarConfig config = preset.value();
    config.effects.speckle = EffectMode::on;
    config.effects.ambient_noise = EffectMode::on;
    config.effects.tvg = EffectMode::off;
    Pose pose;
    pose.pitch_deg = 15.0;
    // Short-range presets (5-10 m) look down steeply from 3 m above the default scene's seabed
    // (z = -5 m): slant range 3 / sin(40 deg +- vfov/2) = 3.7-4.9 m, inside their window.
    if (config.range_max_m < 20.0) {
        pose.x_m = 6.0;
        pose.z_m = -2.0;
        pose.pitch_deg = 40.0;
    }
    auto p = render_pair(VKSONAR_ASSET_DIR "/scenes/default.gltf", config, pose, SaveFlags::none);
    ASSERT_TRUE(p);
    const Frame& g = p->gpu->frame;
    const Frame& c = p->cpu->frame;
    std::size_t noise_same = 0, noise_compared = 0;
    for (std::size_t i = 0; i < g.clean.size(); ++i) {
        if (g.clean[i] == c.clean[i]) { // identical input -> identical seeded noise, bit for bit
            ++noise_compared;
            noise_same += g.intensity[i] == c.intensity[i];
        }
    }
    const CleanAgreement a = compare_clean(config, g, c);
    std::printf("[preset] %s: %zu cells above noise floor, %zu over %.1f dB, max %.2f dB\n", GetParam().c_str(),
                a.above, a.over, kFrameDbTol, a.max_db);
    ASSERT_GT(a.above, 0u) << "the preset sees nothing of the default scene: move the pose";
    EXPECT_LE(static_cast<double>(a.over), kFrameCellBudget * a.above); // tolerance: tests/tolerances.h
    EXPECT_EQ(noise_same, noise_compared);
}

std::string preset_test_name(const ::testing::TestParamInfo<std::string>& info) {
    std::string name = info.param;
    for (char& ch : name)
        if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
    return name;
}

INSTANTIATE_TEST_SUITE_P(Presets, PresetFrameTest, ::testing::ValuesIn(physical_presets()), preset_test_name);

// Chebyshev patterns both ways: the vertical one is evaluated per pixel in echo.comp (its A travels in
// SonarParams), the horizontal one sampled into the side-lobe weights on the host.
TEST(PatternFrame, ChebyshevPatternsAgree) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard validation;
    SonarConfig config = quiet_config();
    config.vertical_pattern = BeamPattern::chebyshev;
    config.vertical_sidelobe_db = -35.0;
    config.horizontal_pattern = BeamPattern::chebyshev;
    config.horizontal_sidelobe_db = -25.0;
    Pose pose;
    pose.pitch_deg = 15.0;
    auto p = render_pair(VKSONAR_ASSET_DIR "/scenes/default.gltf", config, pose,
                         SaveFlags::echo | SaveFlags::depth | SaveFlags::normals);
    ASSERT_TRUE(p);
    const Frame& g = p->gpu->frame;
    const Frame& c = p->cpu->frame;
    // The vertical pattern per pixel: the CPU's echo stage on the GPU's depth, materials and normals
    // against the GPU's echo (as EchoGpuCpu does for the default sinc), at kEchoRelTol of
    // max(value, kEchoRelFloor x peak) or, near the pattern's first null (inside the depth pass's
    // coverage), at kVerticalPatternAbsTol of the pixel's echo without the pattern (tests/tolerances.h:
    // there the value is a small difference of larger numbers). Not each backend's own echo: on a GPU
    // the depth pass interpolates depth differently from the CPU rasterizer (view z up to 1e-4 apart,
    // DepthGpuCpu), and the Sobel normals of the grazing seabed turn that into echo differences of
    // up to 6e-4 in a fifth of the pixels (measured on an H200), which is no property of the pattern.
    const Plan& plan = renderer_plan(p->gpu->renderer);
    const std::size_t pixels = static_cast<std::size_t>(g.rows) * g.columns;
    std::vector<float> echo(pixels * 2);
    cpu::echo<float>(plan, g.depth.data(), g.material.data(), g.normals.data(), echo.data());
    const std::vector<float> flat = echo_without_vertical_pattern(plan, g);
    double peak = 0;
    for (std::size_t i = 0; i < pixels; ++i)
        peak = std::max(peak, double(echo[2 * i]));
    ASSERT_GT(peak, 0.0);
    double worst = 0;
    std::size_t worst_pixel = 0, lit = 0;
    for (std::size_t i = 0; i < pixels; ++i) {
        lit += echo[2 * i] > 0;
        const double scale = std::max(
            {double(echo[2 * i]), kEchoRelFloor * peak, kVerticalPatternAbsTol / kEchoRelTol * double(flat[2 * i])});
        const double off = std::abs(double(g.echo[2 * i]) - echo[2 * i]) / scale;
        if (off > worst) worst_pixel = i;
        worst = std::max(worst, off);
    }
    std::printf("[chebyshev] echo on the same input: %zu lit pixels, worst %.2e of max(value, floors) at row %zu "
                "column %zu (b %.3e)\n",
                lit, worst, worst_pixel / g.columns, worst_pixel % g.columns,
                flat[2 * worst_pixel] > 0 ? double(echo[2 * worst_pixel]) / double(flat[2 * worst_pixel]) : 0.0);
    EXPECT_GT(lit, 10000u);
    EXPECT_LE(worst, kEchoRelTol);
    const CleanAgreement a = compare_clean(config, g, c);
    std::printf("[chebyshev] whole frame, each backend its own depth: %zu cells above the floor, %zu over %.1f dB\n",
                a.above, a.over, kFrameDbTol);
    ASSERT_GT(a.above, 0u);
    EXPECT_LE(static_cast<double>(a.over), kFrameCellBudget * a.above); // tolerance: tests/tolerances.h
}

TEST(Determinism, TwoVulkanRunsAreBitIdentical) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard validation;
    SonarConfig config = quiet_config();
    config.effects.speckle = EffectMode::on;
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    Pose pose;
    pose.pitch_deg = 15.0;
    auto a = render_once(Backend::vulkan, config, scene.value(), pose);
    auto b = render_once(Backend::vulkan, config, scene.value(), pose);
    ASSERT_TRUE(a && b);
    EXPECT_EQ(a->frame.clean, b->frame.clean);
    EXPECT_EQ(a->frame.intensity, b->frame.intensity);
    EXPECT_GT(sum(a->frame.clean), 0.0);
}

// The material, resample and side-lobe tables are read through uniform blocks where they fit the
// device's uniform range and through storage buffers where they do not (src/vk/pipelines.h). Both
// views hold the same floats and the shaders sum them in the same order, so the frames must agree
// bit for bit. 512 beams take sidelobe.comp's vec4 stores, 130 (not a multiple of 4) its scalar
// ones; both are also checked against the CPU reference with the whole-frame tolerance.
TEST(TableViews, UniformAndStorageTablesGiveTheSameFrame) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard validation;
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    Pose pose;
    pose.pitch_deg = 15.0;
    for (std::uint32_t beams : {512u, 130u}) {
        SCOPED_TRACE("beams = " + std::to_string(beams));
        SonarConfig config = quiet_config();
        config.beams = beams;
        config.effects.horizontal_pattern = EffectMode::on;
        auto uniform = render_once(Backend::vulkan, config, scene.value(), pose, SaveFlags::profiles);
        RendererOptions storage_tables;
        storage_tables.tables = TableAccess::storage;
        auto storage =
            render_once(Backend::vulkan, config, scene.value(), pose, SaveFlags::profiles, 1, storage_tables);
        auto cpu = render_once(Backend::cpu, config, scene.value(), pose, SaveFlags::profiles);
        ASSERT_TRUE(uniform && storage && cpu);
        EXPECT_EQ(uniform->frame.beam_profiles, storage->frame.beam_profiles);
        EXPECT_EQ(uniform->frame.clean, storage->frame.clean);
        // the side-lobe pass ran: polar differs from the resampled beam profiles
        EXPECT_NE(uniform->frame.clean, uniform->frame.beam_profiles);

        const CleanAgreement a = compare_clean(config, uniform->frame, cpu->frame);
        ASSERT_GT(a.above, 0u);
        EXPECT_LE(static_cast<double>(a.over), kFrameCellBudget * a.above); // tolerance: tests/tolerances.h
    }
}

// resample.comp walks each run's columns once where the host proves (resample_can_walk) that this adds
// the same terms in the same order as gathering each beam's span: the two must give the same bits.
// Cases: side lobes on (beam-major output) and off (range-major output), a beam count that leaves a
// partial run (130), one pixel column per beam, and an equi-sine beam table.
TEST(NoiseAcrossBackends, SameSeedSameNoiseMultipliers) {
    VKSONAR_REQUIRE_VULKAN();
    // Where both backends produce the same clean value (every empty cell is exactly 0 on both), the
    // noisy value must be bit-identical: noise is keyed by (seed, frame, beam, bin), not by backend.
    SonarConfig config = quiet_config();
    config.effects.speckle = EffectMode::on;
    config.effects.ambient_noise = EffectMode::on;
    Scene scene;
    add_quad(scene, 10.0, 0.0, 0.0, 2.0, 2.0);
    auto g = render_once(Backend::vulkan, config, scene, {}, SaveFlags::none, 7);
    auto c = render_once(Backend::cpu, config, scene, {}, SaveFlags::none, 7);
    ASSERT_TRUE(g && c);
    std::size_t compared = 0;
    for (std::size_t i = 0; i < g->frame.clean.size(); ++i) {
        if (g->frame.clean[i] == c->frame.clean[i]) {
            ASSERT_EQ(g->frame.intensity[i], c->frame.intensity[i]) << "cell " << i;
            ++compared;
        }
    }
    EXPECT_GT(compared, g->frame.clean.size() / 2);
}

} // namespace
} // namespace vksonar::testing
