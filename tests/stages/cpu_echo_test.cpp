// Tests of the CPU echo stage (src/stages/cpu_echo.cpp) against docs/pipeline.md §3: the sonar
// equation term by term on hand-computed inputs, in float and double.
// Every tolerance is justified next to it.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "cpu_stage_support.h"

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
    cpu::echo<Real>(plan, depth.data(), material.data(), normals.data(), echo.data());

    for (std::size_t p : {pa, pb, pc, pd, pe}) {
        // Hand-computed inputs in double from the contract.
        const std::uint32_t c = std::uint32_t(p % plan.columns), j = std::uint32_t(p / plan.columns);
        const double u = (2.0 * (c + 0.5) / plan.slice_columns - 1.0) * plan.tan_half_h;
        const double v = (2.0 * (j + 0.5) / plan.rows - 1.0) * plan.tan_half_v;
        const double z = plan.depth_a / (double(depth[p]) - plan.depth_b);
        const double r = z * std::sqrt(1 + u * u + v * v);
        const std::uint32_t m = material[p] == shared::kNoMaterial ? 0u : material[p];
        const double f = plan.materials[m].model == shared::kScatterLambert ? double(normals[4 * p + 3]) : 1.0;
        const double omega = (2 * plan.tan_half_h / plan.slice_columns) * (2 * plan.tan_half_v / plan.rows) /
                             std::pow(1 + u * u + v * v, 1.5);
        const double psi = std::atan2(-v, std::sqrt(1 + u * u));
        const double bv =
            math_f64::pattern_power(shared::kPatternSinc, plan.vpattern_k, plan.vpattern_halfwidth_rad, psi);
        double expected = Math<double>::echo_energy(double(plan.materials[m].backscatter_linear), f, omega, r,
                                                    plan.alpha_db_per_m, bv, true, true);
        if (r < 0.5 || r >= 40.0) expected = 0.0;
        // float storage of the result: 6e-8; in float arithmetic, about ten roundings plus exp/pow of
        // arguments ~10 (relative 1e-6): 1e-5.
        const double tol = std::is_same_v<Real, double> ? 2e-7 : 1e-5;
        EXPECT_NEAR(echo[2 * p], expected, tol * expected) << "pixel " << p;
        EXPECT_NEAR(echo[2 * p + 1], r, tol * r);
    }
    EXPECT_EQ(echo[2 * pd], 0.0f);
    EXPECT_EQ(echo[2 * pe], 0.0f);
    EXPECT_GT(echo[2 * pa], 0.0f);
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

} // namespace
} // namespace vksonar
