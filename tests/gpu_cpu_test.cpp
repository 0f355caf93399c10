// GPU-vs-CPU regression suite: each stage fed the same input on both backends, then whole frames.
// Tolerances and their reasons: tests/tolerances.h.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <filesystem>

#include "core/sonar_math.hpp"
#include "scene/scene_data.h"
#include "stages/cpu_stages.h"
#include "test_support.h"
#include "tolerances.h"
#include "vk/resample_walk.h"
#include "vk/vulkan_backend_impl.h"

namespace vksonar::testing {
namespace {

constexpr std::uint32_t kSaveAll = save_depth | save_normals | save_echo | save_profiles;

struct SceneCase {
    std::string file;
    Pose pose;
};

std::vector<SceneCase> bundled_scenes() {
    std::vector<SceneCase> out;
    Pose look_down;
    look_down.pitch_deg = 15.0; // positive pitch tilts the nose down (REP-103): the seabed is in view
    for (const auto& entry : std::filesystem::directory_iterator(VKSONAR_ASSET_DIR "/scenes")) {
        const std::string ext = entry.path().extension().string();
        if (ext == ".gltf" || ext == ".glb") out.push_back({entry.path().string(), look_down});
    }
    std::sort(out.begin(), out.end(), [](const SceneCase& a, const SceneCase& b) { return a.file < b.file; });
    return out;
}

struct Pair {
    Scene scene;
    std::unique_ptr<Rendered> gpu, cpu;
};

std::unique_ptr<Pair> render_pair(const std::string& file, const SonarConfig& config, const Pose& pose,
                                  std::uint32_t save_mask) {
    auto pair = std::make_unique<Pair>();
    auto scene = Scene::load_gltf(file);
    if (!scene) {
        ADD_FAILURE() << scene.error().message;
        return nullptr;
    }
    pair->scene = std::move(scene.value());
    pair->gpu = render_once(Backend::vulkan, config, pair->scene, pose, save_mask);
    pair->cpu = render_once(Backend::cpu, config, pair->scene, pose, save_mask);
    if (!pair->gpu || !pair->cpu) return nullptr;
    return pair;
}

// Cells where either backend's clean scan is above the noise floor NL - DI - SL, and how many of them
// differ by more than kFrameDbTol (tests/tolerances.h); a value below the floor counts as the floor.
struct CleanAgreement {
    std::size_t above = 0, over = 0;
    double max_db = 0;
};

// Per-pixel echo without the vertical pattern (E0 = E / b), from the same depth, materials and normals
// through the CPU reference: the scale of the pattern's absolute error (kVerticalPatternAbsTol), which
// near the pattern's null no relative tolerance can hold.
std::vector<float> echo_without_vertical_pattern(const Plan& plan, const Frame& f) {
    Plan flat = plan;
    flat.effects.vertical_pattern = false;
    std::vector<float> echo(f.depth.size() * 2);
    cpu::echo<float>(flat, f.depth.data(), f.material.data(), f.normals.data(), echo.data());
    return echo;
}

CleanAgreement compare_clean(const SonarConfig& config, const Frame& g, const Frame& c) {
    const double floor =
        std::pow(10.0, (config.noise_level_db - config.directivity_index_db - config.source_level_db) / 10.0);
    CleanAgreement a;
    for (std::size_t i = 0; i < g.clean.size(); ++i) {
        if (g.clean[i] < floor && c.clean[i] < floor) continue;
        ++a.above;
        const double d = std::abs(to_db(std::max<double>(g.clean[i], floor * 1e-3)) -
                                  to_db(std::max<double>(c.clean[i], floor * 1e-3)));
        a.max_db = std::max(a.max_db, d);
        a.over += d > kFrameDbTol;
    }
    return a;
}

class StageTest : public ::testing::TestWithParam<SceneCase> {
protected:
    void SetUp() override { VKSONAR_REQUIRE_VULKAN(); }
    ValidationGuard validation_;
};

TEST_P(StageTest, DepthDiffersOnlyOnTriangleEdges) {
    auto p = render_pair(GetParam().file, quiet_config(), GetParam().pose, kSaveAll);
    ASSERT_TRUE(p);
    const Frame& g = p->gpu->frame;
    const Frame& c = p->cpu->frame;
    const Plan& plan = renderer_plan(p->gpu->renderer);
    std::size_t hits = 0, mismatched = 0;
    double max_rel_interior = 0, max_abs_range_m = 0;
    for (std::uint32_t row = 0; row < g.rows; ++row) {
        const double v = math_f64::pixel_coord(row, plan.rows, plan.tan_half_v);
        for (std::uint32_t col = 0; col < g.columns; ++col) {
            const std::size_t i = static_cast<std::size_t>(row) * g.columns + col;
            hits += g.depth[i] > 0;
            const bool same_surface = g.material[i] == c.material[i] && (g.depth[i] > 0) == (c.depth[i] > 0);
            const double zg = g.depth[i] > 0 ? plan.depth_a / (g.depth[i] - plan.depth_b) : 0;
            const double zc = c.depth[i] > 0 ? plan.depth_a / (c.depth[i] - plan.depth_b) : 0;
            const double rel = zg > 0 ? std::abs(zg - zc) / zg : 0;
            if (!same_surface || rel > kDepthInteriorRelTol) {
                ++mismatched;
            } else {
                max_rel_interior = std::max(max_rel_interior, rel);
                // The same difference as slant range in metres: r = z |(u, v, 1)|.
                const double u = math_f64::pixel_coord(col % plan.slice_columns, plan.slice_columns, plan.tan_half_h);
                max_abs_range_m = std::max(max_abs_range_m, std::abs(zg - zc) * std::sqrt(1 + u * u + v * v));
            }
        }
    }
    ASSERT_GT(hits, 0u);
    RecordProperty("depth_mismatched_pixels", static_cast<int>(mismatched));
    std::printf("[depth] %s: %zu of %zu hit pixels differ (edges), max interior view-z rel diff %.2e, max slant "
                "range diff %.2e m\n",
                GetParam().file.c_str(), mismatched, hits, max_rel_interior, max_abs_range_m);
    EXPECT_LE(static_cast<double>(mismatched), kDepthEdgePixelBudget * hits);
    EXPECT_LE(max_abs_range_m, kDepthInteriorRelTol * plan.config.range_max_m);
}

// Normals from the GPU's depth through the CPU reference vs the GPU's normals (same tolerance for
// every normal_method: same formulas, same order on both); returns the CPU normals.
std::vector<float> expect_normals_match(const Plan& plan, const Frame& g) {
    const std::size_t pixels = static_cast<std::size_t>(g.rows) * g.columns;
    std::vector<float> normals(pixels * 4);
    cpu::normals<float>(plan, g.depth.data(), normals.data());
    double max_angle_deg = 0, max_cos_diff = 0;
    for (std::size_t i = 0; i < pixels; ++i) {
        if (g.depth[i] <= 0) continue;
        // atan2(|a x b|, a . b), not acos(a . b): acos of two float unit vectors bottoms out at
        // acos(1 - 2^-23) ~ 0.04 deg, which would hide the real difference under rounding.
        const double a[3] = {normals[4 * i], normals[4 * i + 1], normals[4 * i + 2]};
        const double b[3] = {g.normals[4 * i], g.normals[4 * i + 1], g.normals[4 * i + 2]};
        const double cx = a[1] * b[2] - a[2] * b[1], cy = a[2] * b[0] - a[0] * b[2], cz = a[0] * b[1] - a[1] * b[0];
        const double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        const double angle = std::atan2(std::sqrt(cx * cx + cy * cy + cz * cz), dot);
        max_angle_deg = std::max(max_angle_deg, angle * 180.0 / 3.14159265358979);
        max_cos_diff = std::max(max_cos_diff, static_cast<double>(std::abs(normals[4 * i + 3] - g.normals[4 * i + 3])));
    }
    std::printf("[normals] method %u: max angle %.2e deg, max |d cos| %.2e\n", plan.params.normal_method, max_angle_deg,
                max_cos_diff);
    EXPECT_LE(max_angle_deg, kNormalAngleTolDeg);
    EXPECT_LE(max_cos_diff, kNormalCosTol);
    return normals;
}

TEST_P(StageTest, NormalsEchoBeamformMatchOnTheSameInput) {
    auto p = render_pair(GetParam().file, quiet_config(), GetParam().pose, kSaveAll);
    ASSERT_TRUE(p);
    const Frame& g = p->gpu->frame;
    const Plan& plan = renderer_plan(p->gpu->renderer);
    const std::size_t pixels = static_cast<std::size_t>(g.rows) * g.columns;

    expect_normals_match(plan, g);

    // Echo from the GPU's depth, materials and normals.
    std::vector<float> echo(pixels * 2);
    cpu::echo<float>(plan, g.depth.data(), g.material.data(), g.normals.data(), echo.data());
    double max_energy = 0;
    for (std::size_t i = 0; i < pixels; ++i)
        max_energy = std::max(max_energy, static_cast<double>(g.echo[2 * i]));
    ASSERT_GT(max_energy, 0.0);
    // Relative to the value, or near a vertical-pattern null to the pattern's absolute error
    // (kVerticalPatternAbsTol x E0, written as a floor under the value: tests/tolerances.h).
    const std::vector<float> flat = echo_without_vertical_pattern(plan, g);
    double max_rel_echo = 0, max_range_diff = 0;
    for (std::size_t i = 0; i < pixels; ++i) {
        const double a = g.echo[2 * i], b = echo[2 * i];
        const double floor =
            std::max(kEchoRelFloor * max_energy, kVerticalPatternAbsTol / kEchoRelTol * double(flat[2 * i]));
        max_rel_echo = std::max(max_rel_echo, std::abs(a - b) / std::max(std::abs(b), floor));
        max_range_diff = std::max(max_range_diff, static_cast<double>(std::abs(g.echo[2 * i + 1] - echo[2 * i + 1])));
    }
    std::printf("[echo] max rel %.2e, max range diff %.2e m\n", max_rel_echo, max_range_diff);
    EXPECT_LE(max_rel_echo, kEchoRelTol);
    EXPECT_LE(max_range_diff, kRangeAbsTolM);

    // Beamform from the GPU's echo.
    std::vector<float> profiles(static_cast<std::size_t>(plan.bins) * plan.columns);
    std::vector<float> beam_profiles(static_cast<std::size_t>(plan.bins) * plan.beams);
    std::vector<float> polar(beam_profiles.size());
    cpu::beamform<float>(plan, g.echo.data(), profiles.data(), beam_profiles.data(), polar.data());
    double peak = 0;
    for (float v : polar)
        peak = std::max(peak, static_cast<double>(v));
    double max_rel_polar = 0;
    for (std::size_t i = 0; i < polar.size(); ++i) {
        const double a = g.clean[i], b = polar[i];
        max_rel_polar = std::max(max_rel_polar, std::abs(a - b) / std::max(std::abs(b), kBeamformRelFloor * peak));
    }
    // The same comparison in dB over the cells above the ambient noise floor (clean is relative to SL).
    const SonarConfig& cfg = plan.config;
    const double floor = std::pow(10.0, (cfg.noise_level_db - cfg.directivity_index_db - cfg.source_level_db) / 10.0);
    double max_db = 0;
    std::size_t above = 0;
    for (std::size_t i = 0; i < polar.size(); ++i) {
        if (!(polar[i] > floor)) continue;
        ++above;
        max_db = std::max(max_db, std::abs(10.0 * std::log10(double(g.clean[i]) / double(polar[i]))));
    }
    std::printf("[beamform] max rel %.2e, max %.2e dB over %zu cells above the noise floor\n", max_rel_polar, max_db,
                above);
    EXPECT_LE(max_rel_polar, kBeamformRelTol);
    ASSERT_GT(above, 100u);
    EXPECT_LE(max_db, 10.0 * std::log10(1.0 + kBeamformRelTol)); // 4.3e-5 dB
}

TEST_P(StageTest, Sobel5NormalsMatchOnTheSameInput) {
    SonarConfig config = quiet_config();
    config.normal_method = NormalMethod::sobel5;
    auto p = render_pair(GetParam().file, config, GetParam().pose, kSaveAll);
    ASSERT_TRUE(p);
    const Frame& g = p->gpu->frame;
    const Plan& plan = renderer_plan(p->gpu->renderer);
    ASSERT_EQ(plan.params.normal_method, shared::kNormalsSobel5);
    const std::vector<float> sobel5 = expect_normals_match(plan, g);
    // The 5x5 path must actually run: on the same depth, some pixels differ from sobel3 (a scene
    // with no 5x5 smooth region would give none here; a GPU ignoring the method fails above).
    Plan plan3 = plan;
    plan3.params.normal_method = shared::kNormalsSobel3;
    std::vector<float> sobel3(sobel5.size());
    cpu::normals<float>(plan3, g.depth.data(), sobel3.data());
    std::size_t differ = 0;
    for (std::size_t i = 0; i < sobel5.size(); i += 4)
        differ += sobel5[i] != sobel3[i] || sobel5[i + 1] != sobel3[i + 1];
    std::printf("[normals] sobel5 differs from sobel3 in %zu pixels\n", differ);
    EXPECT_GT(differ, 0u);
}

// normal_method = geometric, each backend from its own depth pass: where both cover a pixel with the
// same surface (the depth test's criterion), the face normals agree to the GPU's derivative precision;
// the pixels where they do not are triangle-edge pixels won by a neighbouring triangle on one backend.
TEST_P(StageTest, GeometricNormalsDifferOnlyOnTriangleEdges) {
    SonarConfig config = quiet_config();
    config.normal_method = NormalMethod::geometric;
    auto p = render_pair(GetParam().file, config, GetParam().pose, save_depth | save_normals);
    ASSERT_TRUE(p);
    const Frame& g = p->gpu->frame;
    const Frame& c = p->cpu->frame;
    const Plan& plan = renderer_plan(p->gpu->renderer);
    ASSERT_TRUE(plan.face_normals);
    std::size_t hits = 0, over = 0;
    double max_angle_deg = 0, max_cos_diff = 0, worst_deg = 0;
    for (std::size_t i = 0; i < g.depth.size(); ++i) {
        if (!(g.depth[i] > 0) && !(c.depth[i] > 0)) continue;
        ++hits;
        const bool both = g.depth[i] > 0 && c.depth[i] > 0 && g.material[i] == c.material[i];
        if (!both) {
            ++over;
            continue;
        }
        const double a[3] = {g.normals[4 * i], g.normals[4 * i + 1], g.normals[4 * i + 2]};
        const double b[3] = {c.normals[4 * i], c.normals[4 * i + 1], c.normals[4 * i + 2]};
        const double cx = a[1] * b[2] - a[2] * b[1], cy = a[2] * b[0] - a[0] * b[2], cz = a[0] * b[1] - a[1] * b[0];
        const double angle =
            std::atan2(std::sqrt(cx * cx + cy * cy + cz * cz), a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) * 180.0 /
            3.14159265358979;
        const double dcos = std::abs(double(g.normals[4 * i + 3]) - c.normals[4 * i + 3]);
        worst_deg = std::max(worst_deg, angle);
        if (angle > kGeometricAngleTolDeg || dcos > kGeometricCosTol) {
            ++over;
        } else {
            max_angle_deg = std::max(max_angle_deg, angle);
            max_cos_diff = std::max(max_cos_diff, dcos);
        }
    }
    ASSERT_GT(hits, 0u);
    std::printf("[geometric] %s: %zu of %zu hit pixels differ (edges; worst %.1f deg), elsewhere max angle %.2e "
                "deg, max |d cos| %.2e\n",
                GetParam().file.c_str(), over, hits, worst_deg, max_angle_deg, max_cos_diff);
    EXPECT_LE(static_cast<double>(over), kDepthEdgePixelBudget * hits);
}

TEST_P(StageTest, WholeFrameAgrees) {
    SonarConfig config = quiet_config();
    config.effects.speckle = EffectMode::on; // seeded noise must be identical on both backends
    config.effects.ambient_noise = EffectMode::on;
    auto p = render_pair(GetParam().file, config, GetParam().pose, 0);
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

std::string scene_name(const ::testing::TestParamInfo<SceneCase>& info) {
    return std::filesystem::path(info.param.file).stem().string();
}

INSTANTIATE_TEST_SUITE_P(BundledScenes, StageTest, ::testing::ValuesIn(bundled_scenes()), scene_name);

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
    auto p = render_pair(VKSONAR_ASSET_DIR "/scenes/default.gltf", config, pose, 0);
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
    auto p = render_pair(VKSONAR_ASSET_DIR "/scenes/default.gltf", config, pose, save_echo | save_depth | save_normals);
    ASSERT_TRUE(p);
    const Frame& g = p->gpu->frame;
    const Frame& c = p->cpu->frame;
    // Each backend runs its own depth pass, so pixels next to a triangle edge the two rasterizers
    // decide differently get other normals (kDepthEdgePixelBudget; measured here: 44 of 82677). The rest
    // must agree at kEchoRelTol of max(value, kEchoRelFloor x peak), or, near the vertical pattern's
    // first null (inside the depth pass's coverage), at kVerticalPatternAbsTol of the pixel's echo
    // without the pattern (tests/tolerances.h: there the value is a small difference of larger
    // numbers). Pixels compared: ranges equal to float precision.
    const std::vector<float> flat = echo_without_vertical_pattern(renderer_plan(p->cpu->renderer), c);
    double peak = 0;
    for (std::size_t i = 0; i < c.echo.size() / 2; ++i)
        peak = std::max(peak, double(c.echo[2 * i]));
    std::size_t compared = 0, over = 0;
    for (std::size_t i = 0; i < g.echo.size() / 2; ++i) {
        if (c.echo[2 * i] <= 0 || std::abs(g.echo[2 * i + 1] - c.echo[2 * i + 1]) > 1e-5f * c.echo[2 * i + 1]) continue;
        ++compared;
        const double scale = std::max(
            {double(c.echo[2 * i]), kEchoRelFloor * peak, kVerticalPatternAbsTol / kEchoRelTol * double(flat[2 * i])});
        over += std::abs(double(g.echo[2 * i]) - c.echo[2 * i]) > kEchoRelTol * scale;
    }
    EXPECT_GT(compared, 10000u);
    EXPECT_LE(static_cast<double>(over), kDepthEdgePixelBudget * compared);
    const CleanAgreement a = compare_clean(config, g, c);
    std::printf("[chebyshev] %zu echo pixels compared (%zu over), %zu cells above the floor, %zu over %.1f dB\n",
                compared, over, a.above, a.over, kFrameDbTol);
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

// A hit pixel whose material id lies outside the plan's table reflects with material 0 (the
// config's default backscatter) on both backends: the shared kernel's material_index(). The two
// backends once disagreed here (the GPU gave such a pixel no energy, the CPU material 0). The stale id
// cannot come from the public API (Scene::add_draw refuses it), so the test writes it into the draw.
TEST(MaterialIds, OutOfRangeIdReflectsWithMaterialZeroOnBothBackends) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard validation;
    const SonarConfig config = quiet_config();
    auto make_scene = [](std::uint32_t drawn_material) {
        Scene scene;
        // materials: 0 the scene's implicit default, 1 and 2 these quads' (-20 and -5 dB)
        add_quad(scene, 10.0, 0.0, 0.0, 6.0, 3.0, -20.0);
        add_quad(scene, 14.0, 3.0, 0.0, 2.0, 2.0, -5.0);
        auto& draws = const_cast<SceneData&>(scene.data()).draws;
        draws[0].material = drawn_material;
        return scene;
    };
    const Scene reference = make_scene(0u);
    for (std::uint32_t stale : {3u, 7u, shared::kNoMaterial}) {
        const Scene scene = make_scene(stale);
        for (Backend backend : {Backend::vulkan, Backend::cpu}) {
            auto expected = render_once(backend, config, reference);
            auto got = render_once(backend, config, scene);
            ASSERT_TRUE(expected && got);
            // the quad at 10 m is there, at material 0's level, bit for bit (same backend, same input)
            ASSERT_EQ(scene.materials().size(), 3u);
            EXPECT_GT(sum(got->frame.clean), 0.0);
            EXPECT_EQ(got->frame.clean, expected->frame.clean)
                << "material id " << stale << ", backend " << (backend == Backend::vulkan ? "vulkan" : "cpu");
        }
    }
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
        auto uniform = render_once(Backend::vulkan, config, scene.value(), pose, save_profiles);
        ::setenv("VKSONAR_TABLES", "storage", 1);
        auto storage = render_once(Backend::vulkan, config, scene.value(), pose, save_profiles);
        ::unsetenv("VKSONAR_TABLES");
        auto cpu = render_once(Backend::cpu, config, scene.value(), pose, save_profiles);
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
TEST(ResampleWalk, WalkAndGatherGiveTheSameFrame) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard validation;
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    Pose pose;
    pose.pitch_deg = 15.0;
    struct Case {
        const char* name;
        std::uint32_t beams;
        bool side_lobes;
        double pixels_per_beam;
        BeamSpacing spacing;
    };
    const Case cases[] = {{"512 beams, side lobes", 512, true, 2.0, BeamSpacing::equiangular},
                          {"130 beams, no side lobes", 130, false, 2.0, BeamSpacing::equiangular},
                          {"1 column per beam", 256, true, 1.0, BeamSpacing::equiangular},
                          {"equi-sine table", 200, true, 2.0, BeamSpacing::equisine}};
    for (const Case& k : cases) {
        SCOPED_TRACE(k.name);
        SonarConfig config = quiet_config();
        config.beams = k.beams;
        config.pixels_per_beam = k.pixels_per_beam;
        config.beam_spacing = k.spacing;
        config.effects.horizontal_pattern = k.side_lobes ? EffectMode::on : EffectMode::off;
        auto plan = make_plan(config, scene.value().data());
        ASSERT_TRUE(plan) << plan.error().message;
        // Else the renders below would compare the gather with itself.
        EXPECT_TRUE(vk::resample_can_walk(plan.value(), vk::kBeamsPerInvocation));
        auto walked = render_once(Backend::vulkan, config, scene.value(), pose, save_profiles);
        ::setenv("VKSONAR_RESAMPLE", "gather", 1);
        auto gathered = render_once(Backend::vulkan, config, scene.value(), pose, save_profiles);
        ::unsetenv("VKSONAR_RESAMPLE");
        ASSERT_TRUE(walked && gathered);
        EXPECT_EQ(walked->frame.beam_profiles, gathered->frame.beam_profiles);
        EXPECT_EQ(walked->frame.clean, gathered->frame.clean);
        const auto lit = std::count_if(walked->frame.beam_profiles.begin(), walked->frame.beam_profiles.end(),
                                       [](float v) { return v > 0.0f; });
        EXPECT_GT(lit, 1000); // the scene is in view: equal frames are not two empty ones
    }
}

// Where the walk would add different terms, the host keeps the gather: a full circle (beams 0 and
// beams-1 gather from every column), and a span that holds a column giving its beam nothing.
TEST(ResampleWalk, RefusedWhereTheTermsWouldDiffer) {
    Scene scene;
    SonarConfig config = quiet_config();
    auto fan = make_plan(config, scene.data());
    ASSERT_TRUE(fan) << fan.error().message;
    ASSERT_TRUE(vk::resample_can_walk(fan.value(), vk::kBeamsPerInvocation));
    config.hfov_deg = 360.0;
    auto circle = make_plan(config, scene.data());
    ASSERT_TRUE(circle) << circle.error().message;
    EXPECT_FALSE(vk::resample_can_walk(circle.value(), vk::kBeamsPerInvocation));
    // Beam 40's span reaches back over beam 38's columns, which give beam 40 nothing.
    Plan widened = fan.value();
    widened.beam_column_begin[40] = widened.beam_column_begin[39];
    EXPECT_FALSE(vk::resample_can_walk(widened, vk::kBeamsPerInvocation));
}

TEST(NoiseAcrossBackends, SameSeedSameNoiseMultipliers) {
    VKSONAR_REQUIRE_VULKAN();
    // Where both backends produce the same clean value (every empty cell is exactly 0 on both), the
    // noisy value must be bit-identical: noise is keyed by (seed, frame, beam, bin), not by backend.
    SonarConfig config = quiet_config();
    config.effects.speckle = EffectMode::on;
    config.effects.ambient_noise = EffectMode::on;
    Scene scene;
    add_quad(scene, 10.0, 0.0, 0.0, 2.0, 2.0);
    auto g = render_once(Backend::vulkan, config, scene, {}, 0, 7);
    auto c = render_once(Backend::cpu, config, scene, {}, 0, 7);
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
