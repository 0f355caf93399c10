// The horizontal-pattern auto rule (issue 5): side lobes that stay below the display floor even for a
// target at the top of the display window are not simulated (kernel stops at the first null).
#include <cmath>
#include <string>

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
    SonarConfig wide = quiet_config(); // 80 dB window: sinc^2 side lobes (-13.3 dB) are visible
    SonarConfig narrow = wide;
    narrow.db_min = 120.0;
    narrow.db_max = 130.0; // 10 dB: the -13.3 dB side lobes of the brightest target fall below the floor
    auto a = render_once(Backend::cpu, wide, scene);
    auto b = render_once(Backend::cpu, narrow, scene);
    ASSERT_TRUE(a && b);
    const Plan& pa = renderer_plan(a->renderer);
    const Plan& pb = renderer_plan(b->renderer);
    const double spacing = pa.beam_angle_rad[0] - pa.beam_angle_rad[1];
    const double bw = wide.horizontal_beamwidth_deg * kPi / 180.0;
    // Wide window: the configured reach (3 beamwidths).
    EXPECT_EQ(pa.sidelobe_taps, 2 * static_cast<std::uint32_t>(std::floor(3.0 * bw / spacing)) + 1);
    // Narrow window: out to the first null only (the plan samples the pattern in 1/2000 of the reach,
    // so allow the null to land one beam either side of the closed form when it sits on a boundary).
    const double null_beams = sinc_first_null_rad(bw) / spacing;
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

} // namespace
} // namespace vksonar::testing
