// The horizontal-pattern auto rule (issue 5): side lobes that stay below the display floor even for a
// target at the top of the display window are not simulated (kernel stops at the first null).
#include <algorithm>
#include <cmath>
#include <string>

#include "core/plan.h"
#include "core/sonar_math.hpp"

#include "test_support.h"

namespace vksonar::testing {
namespace {

constexpr double kPi = 3.14159265358979323846;

// First null of sinc^2(k sin a) with k set by the -3 dB beamwidth: k sin a = pi. k from bisection on
// sin(x)/x = 1/sqrt(2) (x = 1.3916), independent of the library.
double sinc_first_null_rad(double beamwidth_rad) {
    double lo = 0.1, hi = 3.0;
    for (int i = 0; i < 100; ++i) {
        const double mid = 0.5 * (lo + hi);
        (std::sin(mid) / mid > 1.0 / std::sqrt(2.0) ? lo : hi) = mid;
    }
    const double k = lo / std::sin(beamwidth_rad / 2);
    return std::asin(kPi / k);
}

const EffectState* state(const Plan& plan, const std::string& name) {
    for (const auto& s : plan.effects.states)
        if (s.name == name) return &s;
    return nullptr;
}

TEST(SidelobeAuto, NarrowDisplayWindowKeepsOnlyTheMainLobe) {
    Scene scene;
    add_quad(scene, 10.0, 0.0, 0.0, 1.0, 1.0);
    for (BeamGeometry geometry : {BeamGeometry::planar, BeamGeometry::line_array}) {
        const bool line_array = geometry == BeamGeometry::line_array;
        SCOPED_TRACE(line_array ? "line_array" : "planar");
        SonarConfig wide = quiet_config(); // 80 dB window: sinc^2 side lobes (-13.3 dB) are visible
        wide.beam_geometry = geometry;
        SonarConfig narrow = wide;
        narrow.db_min = 120.0;
        narrow.db_max = 130.0; // 10 dB: the -13.3 dB side lobes of the brightest target fall below the floor
        auto a = render_once(Backend::cpu, wide, scene);
        auto b = render_once(Backend::cpu, narrow, scene);
        ASSERT_TRUE(a && b);
        const Plan& pa = renderer_plan(a->renderer);
        const Plan& pb = renderer_plan(b->renderer);
        // Equiangular beams: in angle the spacing is the same everywhere; with line_array the kernel is
        // in sine, where the edge beams are closest (sin(a0) - sin(a1), a0 the port-most centre).
        const double a0 = pa.beam_angle_rad[0], a1 = pa.beam_angle_rad[1];
        const double spacing = line_array ? std::sin(a0) - std::sin(a1) : a0 - a1;
        const double bw = wide.horizontal_beamwidth_deg * kPi / 180.0;
        auto in_units = [&](double angle) { return line_array ? std::sin(angle) : angle; };
        // Wide window: the configured reach (3 beamwidths).
        EXPECT_EQ(pa.sidelobe_taps, 2 * static_cast<std::uint32_t>(std::floor(in_units(3.0 * bw) / spacing)) + 1);
        // Narrow window: out to the first null only (the plan samples the pattern in 1/2000 of the reach,
        // so allow the null to land one beam either side of the closed form when it sits on a boundary).
        const double null_beams = in_units(sinc_first_null_rad(bw)) / spacing;
        const auto expected = 2 * static_cast<std::uint32_t>(std::floor(null_beams)) + 1;
        EXPECT_NEAR(double(pb.sidelobe_taps), double(expected), 2.0) << "null at " << null_beams << " beams";
        EXPECT_LT(pb.sidelobe_taps, pa.sidelobe_taps);
        const EffectState* why = state(pb, "horizontal_pattern");
        ASSERT_NE(why, nullptr);
        EXPECT_TRUE(why->on);
        EXPECT_NE(why->why.find("main lobe only"), std::string::npos) << why->why;
        EXPECT_EQ(state(pa, "horizontal_pattern")->why.find("main lobe only"), std::string::npos);
        // Set explicitly, the effect keeps the configured kernel whatever the window.
        narrow.effects.horizontal_pattern = EffectMode::on;
        auto c = render_once(Backend::cpu, narrow, scene);
        ASSERT_TRUE(c);
        EXPECT_EQ(renderer_plan(c->renderer).sidelobe_taps, pa.sidelobe_taps);
    }
}

TEST(SidelobeAuto, PatternsWithoutSideLobesKeepTheirKernel) {
    // A Gaussian pattern has no null and no side lobe: nothing to truncate, even for a 10 dB window.
    Scene scene;
    add_quad(scene, 10.0, 0.0, 0.0, 1.0, 1.0);
    SonarConfig config = quiet_config();
    config.horizontal_pattern = BeamPattern::gaussian;
    auto wide = render_once(Backend::cpu, config, scene);
    config.db_min = 120.0;
    config.db_max = 130.0;
    auto narrow = render_once(Backend::cpu, config, scene);
    ASSERT_TRUE(wide && narrow);
    EXPECT_EQ(renderer_plan(narrow->renderer).sidelobe_taps, renderer_plan(wide->renderer).sidelobe_taps);
}

// Dolph-Chebyshev power pattern written here from its definition: T_{N-1}(x0 cos u) in the limit of
// many elements is cosh(sqrt(A^2 - x^2)) inside the main lobe and cos(sqrt(x^2 - A^2)) beyond it, over
// cosh(A), with cosh(A) = R the main-lobe / side-lobe amplitude ratio.
double chebyshev_power(double x, double a) {
    const double amp = x < a ? std::cosh(std::sqrt(a * a - x * x)) : std::cos(std::sqrt(x * x - a * a));
    return amp * amp / (std::cosh(a) * std::cosh(a));
}

TEST(ChebyshevPattern, HalfPowerAtTheBeamEdgesAndEverySideLobeAtTheSetLevel) {
    for (double level_db : {-13.0, -20.0, -30.0, -45.0, -60.0, -100.0}) {
        const double a = std::acosh(std::pow(10.0, -level_db / 20.0));
        EXPECT_NEAR(chebyshev_a(level_db), a, 1e-12 * a);
        // -3 dB where cosh(sqrt(A^2 - x^2)) = cosh(A) / sqrt(2).
        const double x3 = std::sqrt(a * a - std::pow(std::acosh(std::cosh(a) / std::sqrt(2.0)), 2));
        for (double bw_deg : {0.6, 1.0, 20.0}) {
            const double half = 0.5 * bw_deg * kPi / 180.0;
            const double k = pattern_constant(BeamPattern::chebyshev, 2 * half, a);
            EXPECT_NEAR(k, x3 / std::sin(half), 1e-9 * k) << level_db << " dB, " << bw_deg << " deg";
            const std::uint32_t id = shared::kPatternChebyshev;
            EXPECT_NEAR(math_f64::pattern_power(id, k, 0.0, a, half), 0.5, 1e-9);
            EXPECT_NEAR(math_f64::pattern_power(id, k, 0.0, a, -half), 0.5, 1e-9);
            // The library's pattern against the definition over the main lobe and 8 side lobes, in
            // double (1e-12) and float (the float evaluation of cosh/cos near A ~ 12: 1e-5 of the peak).
            const double x_last = std::sqrt(a * a + std::pow(8.5 * kPi, 2));
            for (int i = 0; i <= 400; ++i) {
                const double x = x_last * i / 400.0;
                if (x >= k) break; // beyond endfire for a wide beam
                const double angle = std::asin(x / k);
                const double expected = chebyshev_power(x, a);
                EXPECT_NEAR(math_f64::pattern_power(id, k, 0.0, a, angle), expected, 1e-12) << x;
                EXPECT_NEAR(math_f32::pattern_power(id, float(k), 0.0f, float(a), float(angle)), expected, 1e-5) << x;
            }
            // The plan's side-lobe scan finds the first null where cos(sqrt(x^2 - A^2)) first vanishes,
            // and side lobes at exactly the set level (its sampling step: 1/2000 of the reach).
            const double reach = std::min(6 * 2 * half, 1.4);
            const HorizontalLobes lobes = horizontal_lobes(id, k, 0.0, a, reach);
            const double null_x = std::sqrt(a * a + kPi * kPi / 4);
            if (null_x < k * std::sin(reach)) {
                EXPECT_NEAR(lobes.first_null_rad, std::asin(null_x / k), 2 * reach / 2000) << level_db << " dB";
                EXPECT_NEAR(lobes.peak_sidelobe_db, level_db, 0.05) << level_db << " dB";
            }
        }
    }
}

TEST(ChebyshevPattern, AutoKeepsSideLobesOnlyWhereTheDisplayWindowShowsThem) {
    // -40 dB side lobes: a 30 dB window cannot show them (main lobe only), a 50 dB window can.
    Scene scene;
    add_quad(scene, 10.0, 0.0, 0.0, 1.0, 1.0);
    SonarConfig config = quiet_config();
    config.horizontal_pattern = BeamPattern::chebyshev;
    config.horizontal_sidelobe_db = -40.0;
    config.db_min = 100.0;
    config.db_max = 150.0;
    auto shown = render_once(Backend::cpu, config, scene);
    config.db_min = 120.0;
    auto hidden = render_once(Backend::cpu, config, scene);
    ASSERT_TRUE(shown && hidden);
    EXPECT_EQ(state(renderer_plan(shown->renderer), "horizontal_pattern")->why.find("main lobe only"),
              std::string::npos);
    EXPECT_NE(state(renderer_plan(hidden->renderer), "horizontal_pattern")->why.find("main lobe only"),
              std::string::npos);
    EXPECT_LT(renderer_plan(hidden->renderer).sidelobe_taps, renderer_plan(shown->renderer).sidelobe_taps);
}

} // namespace
} // namespace vksonar::testing
