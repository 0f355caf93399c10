// Tests of the CPU echo stage (src/stages/cpu_echo.cpp) against docs/pipeline.md §3: the sonar
// equation term by term on hand-computed inputs, in float and double.
// Every tolerance is justified next to it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "cpu_stage_support.h"
#include "stages/gpu_cpu_support.h"

namespace vksonar {
namespace {

using namespace stage_testing;

template <class Real> class CpuEchoTyped : public ::testing::Test {};
TYPED_TEST_SUITE(CpuEchoTyped, Precisions);

TYPED_TEST(CpuEchoTyped, PixelMatchesSonarEquationOnHandComputedInputs) {
    using Real = TypeParam;
    SceneBuilder b;
    b.material(-20.0);                                    // material 0: lambert
    b.material(-10.0, AcousticMaterial::Model::constant); // material 1
    b.material(-20.0, AcousticMaterial::Model::rough);    // material 2
    b.scene.materials[2].rms_slope = 0.2;
    b.scene.materials[2].reflection_db = -6.0;
    b.draw(b.quad_x(10, -1, 1, -1, 1), 0);
    const Plan plan = plan_for(small_config(), b.scene);
    const std::size_t n = std::size_t(plan.rows) * plan.columns;
    std::vector<float> depth(n, 0.0f), normals(4 * n, 0.0f), echo(2 * n, -1.0f);
    std::vector<std::uint32_t> material(n, shared::kNoMaterial);
    auto depth_at = [&](double z) { return float(plan.depth_b + plan.depth_a / z); };
    // pixel a: lambert, cos 0.6; b: constant model; c: no material id; d/e: outside the range window.
    const std::size_t pa = 3 * plan.columns + 11, pb = 20 * plan.columns + 50, pc = 31 * plan.columns + 0;
    const std::size_t pd = 10 * plan.columns + 10, pe = 11 * plan.columns + 12;
    depth[pa] = depth_at(7.5);
    material[pa] = 0;
    normals[4 * pa + 3] = 0.6f;
    depth[pb] = depth_at(23.0);
    material[pb] = 1;
    normals[4 * pb + 3] = 0.1f;
    depth[pc] = depth_at(2.0);
    normals[4 * pc + 3] = 0.8f;
    depth[pd] = depth_at(0.47); // slant range 0.485 m < range_min 0.5 m (near plane 0.463 m)
    material[pd] = 0;
    depth[pe] = depth_at(39.99); // slant range > 40 m off axis
    material[pe] = 0;
    // pixel f: rough, 14 deg off normal, where the facet term is ~14x the Lambert term.
    const std::size_t pf = 25 * plan.columns + 70;
    depth[pf] = depth_at(15.0);
    material[pf] = 2;
    normals[4 * pf + 3] = 0.97f;
    cpu::echo<Real>(plan, depth.data(), material.data(), normals.data(), echo.data());

    for (std::size_t p : {pa, pb, pc, pd, pe, pf}) {
        // Hand-computed inputs in double from the contract.
        const std::uint32_t c = std::uint32_t(p % plan.columns), j = std::uint32_t(p / plan.columns);
        const double u = (2.0 * (c + 0.5) / plan.slice_columns - 1.0) * plan.tan_half_h;
        const double v = (2.0 * (j + 0.5) / plan.rows - 1.0) * plan.tan_half_v;
        const double z = plan.depth_a / (double(depth[p]) - plan.depth_b);
        const double r = z * std::sqrt(1 + u * u + v * v);
        const std::uint32_t m = material[p] == shared::kNoMaterial ? 0u : material[p];
        const shared::MaterialGpu& mat = plan.materials[m];
        const double cos_i = normals[4 * p + 3];
        double f = mat.model == shared::kScatterLambert ? cos_i : 1.0;
        if (mat.model == shared::kScatterRough) { // cos + ratio exp(-tan^2 / (2 m^2)) / cos^5, from theta
            const double theta = std::acos(cos_i);
            f = cos_i + double(mat.specular_ratio) * std::exp(-std::pow(std::tan(theta), 2) * mat.inv_two_slope_sq) /
                            std::pow(cos_i, 5);
        }
        const double omega = (2 * plan.tan_half_h / plan.slice_columns) * (2 * plan.tan_half_v / plan.rows) /
                             std::pow(1 + u * u + v * v, 1.5);
        // The sinc^2 vertical pattern averaged over the pixel's height (docs/pipeline.md §3), here by a
        // dense midpoint rule in v: 4000 points, relative error < 1e-9.
        const double dv = 2 * plan.tan_half_v / plan.rows;
        double bv = 0;
        const int points = 4000;
        for (int i = 0; i < points; ++i) {
            const double vi = v + dv * ((i + 0.5) / points - 0.5);
            const double x = plan.vpattern_k * std::sin(std::atan2(-vi, std::sqrt(1 + u * u)));
            const double sinc = x == 0 ? 1.0 : std::sin(x) / x;
            bv += sinc * sinc / points;
        }
        double expected =
            Math<double>::echo_energy(double(mat.backscatter_linear), f, omega, r, plan.alpha_db_per_m, bv, true, true);
        if (r < 0.5 || r >= 40.0) expected = 0.0;
        // float storage of the result: 6e-8; in float arithmetic, about ten roundings plus exp/pow of
        // arguments ~10 (relative 1e-6): 1e-5. The double path reads the same float inputs; the closed
        // form's acos/tan round trip of a cosine near 1 costs ~1e-15 relative. The stage averages the
        // pattern by two-point Gauss-Legendre, exact up to the pattern's 4th derivative term
        // D^4 b_4 / 4320: measured 3e-6 of b at pixel 203 (far off axis, where the pattern bends most
        // between its lobes), and below 1e-7 at the others. So 1e-5 for both precisions.
        const double tol = 1e-5;
        EXPECT_NEAR(echo[2 * p], expected, tol * expected) << "pixel " << p;
        EXPECT_NEAR(echo[2 * p + 1], r, tol * r);
    }
    EXPECT_EQ(echo[2 * pd], 0.0f);
    EXPECT_EQ(echo[2 * pe], 0.0f);
    EXPECT_GT(echo[2 * pa], 0.0f);
    EXPECT_GT(echo[2 * pf], 0.0f);
    // Empty pixels give (0, 0).
    EXPECT_EQ(echo[0], 0.0f);
    EXPECT_EQ(echo[1], 0.0f);
}

TEST(CpuEcho, IncidenceOffIgnoresNormalsAndVerticalPatternOffIsOne) {
    SceneBuilder b;
    b.material(-20.0);
    SonarConfig config = small_config();
    config.effects.incidence = EffectMode::off;
    config.effects.vertical_pattern = EffectMode::off;
    config.effects.absorption = EffectMode::off;
    config.effects.spreading = EffectMode::off;
    const Plan plan = plan_for(config, b.scene);
    const std::size_t n = std::size_t(plan.rows) * plan.columns;
    std::vector<float> depth(n, 0.0f), echo(2 * n);
    std::vector<std::uint32_t> material(n, 0);
    const std::size_t p = 2 * plan.columns + 5; // far off the vertical axis: b_v would be small
    depth[p] = float(plan.depth_b + plan.depth_a / 12.0);
    cpu::echo<double>(plan, depth.data(), material.data(), nullptr, echo.data());
    const std::uint32_t c = 5, j = 2;
    const double u = math_f64::pixel_coord(c, plan.slice_columns, plan.tan_half_h);
    const double v = math_f64::pixel_coord(j, plan.rows, plan.tan_half_v);
    const double r = echo[2 * p + 1];
    const double omega =
        math_f64::pixel_solid_angle(u, v, 2 * plan.tan_half_h / plan.slice_columns, 2 * plan.tan_half_v / plan.rows);
    // f = 1, b = 1, no absorption, footprint r^2 Omega without spreading.
    const double expected = plan.materials[0].backscatter_linear * omega * r * r;
    EXPECT_NEAR(echo[2 * p], expected, 2e-7 * expected); // double arithmetic, float storage
}

// The facet term of the rough model (sonar_math.h specular_facet) against its closed form
// exp(-tan^2(theta) / (2 m^2)) / cos^5(theta), evaluated here from theta, over slopes from a mirror to
// 45 deg and cosines down to 0, denormals and NaN: finite and >= 0 everywhere, exactly 0 at grazing.
TEST(SonarMath, SpecularFacetFollowsItsClosedFormAndVanishesAtGrazing) {
    const std::vector<double> cosines{0.0, 1e-45, 1e-40, 1e-30, 1e-10, 1e-3, 0.05,  0.0785, 0.08,
                                      0.1, 0.3,   0.5,   0.7,   0.9,   0.99, 0.999, 1.0};
    for (double m : {0.01, 0.05, 0.1, 0.3, 0.447, 0.6, 1.0}) {
        const double a = 0.5 / (m * m);
        const double peak = a >= 2.5 ? 1.0 : std::exp(a - 2.5) / std::pow(0.4 * a, 2.5);
        for (double c_in : cosines) {
            // The float path gets the float nearest c_in (and a): the closed form is taken there too.
            const double c = double(float(c_in));
            const double theta = std::acos(c);
            const double arg = std::pow(std::tan(theta), 2) * double(float(a));
            const double expected = c > 0 ? std::exp(-arg) / std::pow(c, 5) : 0.0;
            const double got64 = math_f64::specular_facet(c, double(float(a)));
            const float got32 = math_f32::specular_facet(float(c), float(a));
            ASSERT_TRUE(std::isfinite(got64) && got64 >= 0.0) << "m " << m << " c " << c;
            ASSERT_TRUE(std::isfinite(got32) && got32 >= 0.0f) << "m " << m << " c " << c;
            if (arg < 79.0) {
                // double: a few roundings, the exponential's argument ~80 at most: 1e-13 relative.
                EXPECT_NEAR(got64, expected, 1e-13 * (1 + arg) * expected) << "m " << m << " c " << c;
                // float: the argument carries ~4 roundings (6e-8 each), so exp(-arg) ~2.4e-7 * arg
                // relative, plus ~4 roundings of the rest (c^5, the quotient, exp itself).
                EXPECT_NEAR(got32, expected, 4e-7 * (2 + arg) * expected) << "m " << m << " c " << c;
            } else {
                // Cut where exp(-arg) < e^-80: what is dropped is negligible against the lobe's peak.
                EXPECT_LT(got64, 1e-25 * peak) << "m " << m << " c " << c;
                EXPECT_LT(double(got32), 1e-25 * peak) << "m " << m << " c " << c;
            }
        }
        EXPECT_EQ(math_f64::specular_facet(0.0, a), 0.0);
        EXPECT_EQ(math_f32::specular_facet(std::nanf(""), float(a)), 0.0f);
        EXPECT_EQ(math_f64::specular_facet(1.0, a), 1.0) << "normal incidence is the reference";
    }
}

// The plan's peak of f over all incidences (it sizes the fp16 echo scale): 1 + ratio times the facet
// term's maximum, which a dense sampling finds; an upper bound of f's maximum by less than the
// Lambert term's 1 (exact while m <= sqrt(0.2) = 0.447, where both peak at normal incidence and the
// lobe falls monotonically from there).
TEST(SonarMath, ScatterFactorPeakBoundsTheMaximumOverIncidence) {
    for (double m : {0.02, 0.2, 0.447, 0.5, 0.7, 1.0}) {
        const double ratio = 3.0;
        shared::MaterialGpu mat{1.0f, shared::kScatterRough, float(ratio), float(0.5 / (m * m))};
        const double a = double(mat.inv_two_slope_sq);
        const double peak = scatter_factor_peak(mat);
        double facet_max = 0.0, f_max = 0.0, previous = 1e300;
        bool monotone = true;
        for (int i = 200000; i >= 1; --i) { // theta from 0 towards 90 deg
            const double c = i / 200000.0;
            const double f = math_f64::scatter_factor(mat.model, c, ratio, a);
            facet_max = std::max(facet_max, math_f64::specular_facet(c, a));
            f_max = std::max(f_max, f);
            monotone = monotone && f <= previous;
            previous = f;
        }
        // the sampling step (5e-6 in c) near a smooth maximum: ~1e-9 relative
        EXPECT_NEAR((peak - 1.0) / ratio, facet_max, 1e-8 * facet_max) << "m " << m;
        EXPECT_GE(peak * (1 + 1e-12), f_max) << "m " << m;
        EXPECT_LT(peak - f_max, 1.0) << "m " << m;
        if (m <= 0.447) {
            EXPECT_NEAR(peak, f_max, 1e-12 * peak) << "m " << m;
            EXPECT_TRUE(monotone) << "m " << m;
        }
    }
    shared::MaterialGpu lambert{1.0f, shared::kScatterLambert, 0.0f, 0.0f};
    EXPECT_EQ(scatter_factor_peak(lambert), 1.0);
}

// The plan turns a rough material's parameters into the two table entries, counts rough as
// angle-dependent for the incidence rule, and sizes the fp16 echo scale for the facet peak.
TEST(CpuEcho, RoughMaterialTableIncidenceRuleAndHalfScale) {
    SceneBuilder b;
    const std::uint32_t rough = b.material(-25.0, AcousticMaterial::Model::rough);
    b.scene.materials[rough].rms_slope = 0.05;
    b.scene.materials[rough].reflection_db = -3.0;
    b.draw(b.quad_x(10, -1, 1, -1, 1), rough);
    SonarConfig config = small_config();
    config.intermediates = IntermediatePrecision::fp16;
    const Plan plan = plan_for(config, b.scene);
    const shared::MaterialGpu& mat = plan.materials[rough];
    EXPECT_EQ(mat.model, shared::kScatterRough);
    const double ratio = std::pow(10.0, -0.3) / (8 * kPi * 0.05 * 0.05) / std::pow(10.0, -2.5);
    EXPECT_NEAR(mat.specular_ratio, ratio, 1e-7 * ratio); // float rounding of a double
    EXPECT_NEAR(mat.inv_two_slope_sq, 200.0, 1e-5);

    // fp16: the brightest pixel the plan can produce (the facet peak, at m = 0.05 at normal incidence,
    // on axis, at the near edge of the range gate, where the echo stage still computes: range_min less
    // the kernel's half width) times echo_scale lands in (2^14, 2^15] (docs/pipeline.md §3).
    const double omega = (2 * plan.tan_half_h / plan.slice_columns) * (2 * plan.tan_half_v / plan.rows);
    const double r = plan.gate_min_m;
    EXPECT_LT(r, plan.config.range_min_m);
    const double brightest = double(mat.backscatter_linear) * (1.0 + ratio) * omega / (r * r);
    EXPECT_GT(brightest * plan.params.echo_scale, 16384.0);
    EXPECT_LE(brightest * plan.params.echo_scale, 32768.0 * (1 + 1e-6));

    // The incidence rule on auto (small_config forces it on).
    SonarConfig automatic = small_config();
    automatic.effects.incidence = EffectMode::automatic;
    EXPECT_TRUE(plan_for(automatic, b.scene).effects.incidence) << "rough is angle-dependent: the normals pass runs";
    SceneBuilder c;
    const std::uint32_t constant = c.material(-25.0, AcousticMaterial::Model::constant);
    c.draw(c.quad_x(10, -1, 1, -1, 1), constant);
    EXPECT_FALSE(plan_for(automatic, c.scene).effects.incidence) << "constant alone needs no normals";
}

// Materials an engine fills by hand reach the plan unchecked: the plan refuses a bad facet parameter
// with the material's index, name, field and value.
TEST(CpuEcho, BadRoughParameterFromTheEngineApiIsRefused) {
    SceneBuilder b;
    const std::uint32_t rough = b.material(-25.0, AcousticMaterial::Model::rough);
    b.scene.materials[rough].rms_slope = 0.0;
    b.draw(b.quad_x(10, -1, 1, -1, 1), rough);
    const Result<Plan> plan = make_plan(small_config(), b.scene);
    ASSERT_FALSE(plan.ok());
    EXPECT_EQ(plan.error().code, ErrorCode::invalid_argument);
    EXPECT_NE(plan.error().message.find("material 0 'm0': rms_slope = 0 (expected 0.01 to 1)"), std::string::npos)
        << plan.error().message;
}

// The element pattern scales the sea's noise in beam j as it scales an echo from the beam's direction
// (src/core/noise_floor.cpp): each beam's floor falls by 10 log10 sinc^2(pi w sin theta_j), the SNR stays.
// The beams' angles from the config's equi-angular table; to rounding (1e-9 dB).
TEST(ElementPattern, EachBeamsNoiseFloorFallsWithItsElementPower) {
    SceneBuilder b;
    b.material(-20.0);
    SonarConfig plain, element;
    element.element_width = 0.5;
    const Plan a = plan_for(plain, b.scene), e = plan_for(element, b.scene);
    ASSERT_EQ(a.beams, e.beams);
    const double half = 0.5 * plain.hfov_deg * kDeg;
    for (std::uint32_t j = 0; j < a.beams; ++j) {
        const double theta = (1.0 - (2.0 * j + 1.0) / a.beams) * half;
        const double x = kPi * 0.5 * std::sin(theta);
        const double power = x == 0.0 ? 1.0 : (std::sin(x) / x) * (std::sin(x) / x);
        ASSERT_NEAR(e.beam_floor_db[j] - a.beam_floor_db[j], 10.0 * std::log10(power), 1e-9) << "beam " << j;
    }
    // At the fan's edge (64.9 deg) the floor is 3.16 dB down.
    EXPECT_NEAR(e.beam_floor_db[0] - a.beam_floor_db[0], -3.155, 0.005);
}

// ---- GPU vs CPU (tests/stages/gpu_cpu_support.h; tolerances: tests/tolerances.h) ------------------

using namespace ::vksonar::testing;

class EchoGpuCpu : public GpuCpuScene {};

// The GPU's echo against the CPU's from the GPU's own depth, materials and normals.
void expect_echo_agrees(const SceneCase& scene, const SonarConfig& config, const char* what) {
    auto p = render_pair(scene.file, config, scene.pose, kSaveAll);
    ASSERT_TRUE(p);
    const Frame& g = p->gpu->frame;
    const Plan& plan = renderer_plan(p->gpu->renderer);
    const std::size_t pixels = static_cast<std::size_t>(g.rows) * g.columns;

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
    std::printf("[echo] %s: max rel %.2e, max range diff %.2e m\n", what, max_rel_echo, max_range_diff);
    EXPECT_LE(max_rel_echo, kEchoRelTol) << what;
    EXPECT_LE(max_range_diff, kRangeAbsTolM) << what;
}

TEST_P(EchoGpuCpu, MatchesOnTheSameInput) {
    expect_echo_agrees(GetParam(), quiet_config(), GetParam().file.c_str());
}

// A line array's element pattern (element_width; every pixel times sinc^2 of its direction's sine along
// the array, the sine from the view's basis in float on the GPU): the same tolerances.
TEST(EchoGpuCpuParts, TheElementPatternMatches) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard validation;
    SonarConfig config = quiet_config();
    config.element_width = 0.5;
    expect_echo_agrees(bundled_scenes().front(), config, "element_width 0.5");
}

INSTANTIATE_TEST_SUITE_P(BundledScenes, EchoGpuCpu, ::testing::ValuesIn(bundled_scenes()), scene_name);

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
        auto& draws = const_cast<SceneData&>(scene_data(scene)).draws;
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

} // namespace
} // namespace vksonar
