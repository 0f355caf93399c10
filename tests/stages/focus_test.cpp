// The horizontal pattern out of focus (docs/pipeline.md, "Focus"; src/core/plan_focus.cpp): beam_focus none
// or fixed defocuses the aperture by the quadratic phase phi = pi L^2 / (4 lambda) |1/r - 1/F| (cos^2 of a
// line array's steering angle) that a beam not focused at the echo's range leaves across it. The references
// here integrate the aperture themselves (Simpson, in double) from the beamwidth alone.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdint>
#include <cstdio>
#include <vector>

#include "core/plan_focus.h"
#include "cpu_stage_support.h"
#include "test_support.h"

namespace vksonar {
namespace {

using namespace stage_testing;

// |A(x, phi)|^2 of a uniform (hann: raised-cosine) aperture over s in [-1, 1], normalised to 1 at
// x = phi = 0: composite Simpson on `panels` panels. With 2000 the phase turns at most x + 2 phi < 90 rad
// over the aperture in the test that uses it, 0.09 rad a panel: Simpson's error is below 1e-6 of the peak.
double aperture_power(bool hann, double x, double phi, int panels = 2000) {
    const int n = panels;
    const double h = 2.0 / n;
    std::complex<double> sum = 0.0;
    double norm = 0.0;
    for (int i = 0; i <= n; ++i) {
        const double s = -1.0 + i * h;
        const double w =
            (i == 0 || i == n ? 1.0 : (i % 2 == 1 ? 4.0 : 2.0)) * (hann ? 0.5 * (1.0 + std::cos(kPi * s)) : 1.0);
        sum += w * std::polar(1.0, x * s - phi * s * s);
        norm += w;
    }
    return std::norm(sum / norm);
}

// The x at which the far-field power pattern is one half (the -3 dB beamwidth's half), by bisection.
double half_power_x(bool hann) {
    double lo = 0.5, hi = 3.5;
    for (int i = 0; i < 200; ++i) {
        const double mid = 0.5 * (lo + hi);
        (aperture_power(hann, mid, 0.0) > 0.5 ? lo : hi) = mid;
    }
    return 0.5 * (lo + hi);
}

struct FocusCase {
    const char* name;
    BeamGeometry geometry;
    BeamPattern pattern;
    BeamFocus focus;
    double focus_range_m;
};

// A unit impulse in single profile columns (near broadside and near 40 deg) at bins across the range
// window, every beam against the aperture's defocused pattern at the bin's own range within the band's
// reach (x = 7 phi + 3 pi, or the configured 3 beamwidths), and nothing past it (no far grid here).
// - Against the pattern at the bin's band's phase (Plan::near_band_phase): the table's rows (linear between
//   rows 0.02 rad apart) and its cubic in x, then a float weight. Measured at most 1.2e-5 of the peak (the
//   nearest row alone gave 2.5e-3); 5e-5 allowed.
// - Against the pattern at the bin's own phase: the bands are up to half a step away (0.05 rad, or 3 %).
//   Measured at most 0.019 of the peak, and the main lobe's energy (the sum over the beams within 2 phi + pi
//   of the column) within 0.008 dB; 0.04 and 0.05 dB allowed.
// - The far-field pattern is 29 to 54 dB off at the same cells (asserted above 6 dB, so the test fails with
//   focus ignored).
template <class Real> class CpuFocus : public ::testing::Test {};
TYPED_TEST_SUITE(CpuFocus, Precisions);

TYPED_TEST(CpuFocus, AnImpulseOutOfFocusHearsTheDefocusedAperture) {
    using Real = TypeParam;
    SceneBuilder b;
    b.material(-20.0);
    for (const FocusCase& kase :
         {FocusCase{"line array, unfocused", BeamGeometry::line_array, BeamPattern::sinc, BeamFocus::none, 10.0},
          FocusCase{"line array, hann, focused at 2 m", BeamGeometry::line_array, BeamPattern::hann, BeamFocus::fixed,
                    2.0},
          FocusCase{"planar, focused at 3 m", BeamGeometry::planar, BeamPattern::sinc, BeamFocus::fixed, 3.0}}) {
        SonarConfig config; // the default sonar: 750 kHz, 130 x 20 deg, 512 beams of 1 deg
        config.beam_geometry = kase.geometry;
        config.horizontal_pattern = kase.pattern;
        config.beam_focus = kase.focus;
        config.focus_range_m = kase.focus_range_m;
        config.range_min_m = 0.5;
        config.range_max_m = 8.0;
        config.far_sidelobe_cell = 0.0;
        config.effects.horizontal_pattern = EffectMode::on;
        const Plan plan = plan_for(config, b.scene);
        ASSERT_EQ(plan.far_cells, 0u);
        ASSERT_GT(plan.near_bands, 10u) << kase.name;
        const bool hann = kase.pattern == BeamPattern::hann;
        const std::uint32_t columns = plan.profile_columns, beams = plan.beams;
        const double hbw = config.horizontal_beamwidth_deg * kDeg, half = 0.5 * config.hfov_deg * kDeg;
        const double k = half_power_x(hann) / std::sin(0.5 * hbw);
        const double lambda = config.sound_speed_mps / config.frequency_hz, aperture = k * lambda / kPi;
        const double inverse_focus = kase.focus == BeamFocus::fixed ? 1.0 / kase.focus_range_m : 0.0;
        auto own_phase = [&](std::uint32_t bin) {
            const double r = config.range_min_m + (bin + 0.5) * (config.range_max_m - config.range_min_m) / plan.bins;
            return kPi * aperture * aperture / (4.0 * lambda) * std::abs(1.0 / r - inverse_focus);
        };
        auto beam_angle = [&](std::uint32_t j) { return (1.0 - (2.0 * j + 1.0) / beams) * half; };
        auto column_angle = [&](std::uint32_t c) {
            if (plan.line_array) return (1.0 - (2.0 * c + 1.0) / columns) * half;
            return plan.column_azimuth_rad[c]; // planar: the pixel grid's own azimuths (checked elsewhere)
        };
        // x of column c at beam j, and the share of phi there (cos^2 of a line array's steering angle);
        // planar beams hear nothing from 90 deg on.
        auto x_and_share = [&](std::uint32_t c, std::uint32_t j, double& share) {
            share = plan.line_array ? std::cos(beam_angle(j)) * std::cos(beam_angle(j)) : 1.0;
            return k * (plan.line_array ? std::sin(column_angle(c)) - std::sin(beam_angle(j))
                                        : std::sin(column_angle(c) - beam_angle(j)));
        };
        // Impulses: one column near each steering angle, at every 9th bin (they do not share a bin).
        std::vector<std::uint32_t> impulse_columns;
        for (double steer_deg : {0.1, 39.5}) {
            std::uint32_t best = 0;
            for (std::uint32_t c = 0; c < columns; ++c)
                if (std::abs(column_angle(c) - steer_deg * kDeg) < std::abs(column_angle(best) - steer_deg * kDeg))
                    best = c;
            impulse_columns.push_back(best);
        }
        const std::size_t T = cpu::profile_column_stride(plan);
        std::vector<Real> acc(cpu::beamform_accumulator_count(plan), Real(0));
        std::vector<std::pair<std::uint32_t, std::uint32_t>> impulses; // (column, bin)
        for (std::uint32_t bin = 3; bin < plan.bins; bin += 9) {
            const std::uint32_t c = impulse_columns[impulses.size() % impulse_columns.size()];
            acc[c * T + bin] = Real(1);
            impulses.emplace_back(c, bin);
        }
        std::vector<Real> weights(std::max<std::size_t>(cpu::resample_weight_count(plan), 1));
        cpu::resample_weights<Real>(plan, weights.data());
        std::vector<float> beam_profiles(std::size_t(plan.bins) * beams), polar(std::size_t(plan.bins) * beams);
        cpu::beamform_beams<Real>(plan, acc.data(), weights.data(), beam_profiles.data(), polar.data(), 0, plan.bins);

        double worst_band = 0, worst_own = 0, worst_lobe_db = 0, worst_far_field_db = 0;
        std::size_t checked = 0;
        for (const auto& [c, bin] : impulses) {
            const double band_phase = plan.near_band_phase[plan.near_band_of_bin[bin]];
            const double phase = own_phase(bin);
            ASSERT_LE(std::abs(band_phase - phase), std::max(0.05, 0.031 * phase) + 1e-9)
                << kase.name << " bin " << bin;
            double got_lobe = 0, own_lobe = 0;
            for (std::uint32_t j = 0; j < beams; ++j) {
                double share = 1.0;
                const double x = x_and_share(c, j, share);
                const double got = polar[std::size_t(bin) * beams + j];
                if (!plan.line_array && std::abs(column_angle(c) - beam_angle(j)) >= 0.5 * kPi) {
                    ASSERT_EQ(got, 0.0);
                    continue;
                }
                // A band keeps its pattern out to x = 7 phi + 3 pi (its lobes within 1.1 dB of the far
                // field's past there: the far grid's, when there is one), and at least to the configured reach
                // (3 beamwidths); beyond both nothing here (no far grid). Cells within 1e-6 of an edge: either.
                const double separation = plan.line_array ? std::sin(column_angle(c)) - std::sin(beam_angle(j))
                                                          : column_angle(c) - beam_angle(j);
                const double configured = plan.line_array ? std::sin(3.0 * hbw) : 3.0 * hbw;
                const double band_reach = 7.0 * band_phase * share + 3.0 * kPi;
                const double edge = std::min(std::abs(std::abs(separation) - configured) / configured,
                                             std::abs(std::abs(x) - band_reach) / band_reach);
                if (edge < 1e-6) continue;
                if (std::abs(separation) > configured && std::abs(x) > band_reach) {
                    ASSERT_EQ(got, 0.0) << kase.name << " beam " << j << " bin " << bin;
                    continue;
                }
                const double at_band = aperture_power(hann, x, band_phase * share);
                const double at_own = aperture_power(hann, x, phase * share);
                worst_band = std::max(worst_band, std::abs(got - at_band));
                worst_own = std::max(worst_own, std::abs(got - at_own));
                if (std::abs(x) <= 2.0 * phase * share + kPi) {
                    got_lobe += got;
                    own_lobe += at_own;
                    const double far_field = aperture_power(hann, x, 0.0);
                    if (at_own > 0.1)
                        worst_far_field_db =
                            std::max(worst_far_field_db, std::abs(::vksonar::testing::to_db(far_field / at_own)));
                }
                ++checked;
            }
            worst_lobe_db = std::max(worst_lobe_db, std::abs(::vksonar::testing::to_db(got_lobe / own_lobe)));
        }
        std::printf("[focus] %-34s %u bands, %zu cells: worst %.2g of the peak at the band's phase, %.2g at the "
                    "bin's own; main lobe energy within %.3f dB; the far-field pattern %.1f dB off\n",
                    kase.name, plan.near_bands, checked, worst_band, worst_own, worst_lobe_db, worst_far_field_db);
        EXPECT_GT(checked, 1000u) << kase.name;
        EXPECT_LE(worst_band, 5e-5) << kase.name;
        EXPECT_LE(worst_own, 0.04) << kase.name;
        EXPECT_LE(worst_lobe_db, 0.05) << kase.name;
        EXPECT_GT(worst_far_field_db, 6.0) << kase.name;
    }
}

// The defocused pattern's table (plan_steps::DefocusedPattern) out to the most defocus vksonar takes
// (64 rad) and the widest a band reaches (x = 7 phi + 3 pi): rows 0.02 rad apart to 4 rad then 0.5 %,
// x every 0.1, and past 2 phi + 48 the aperture ends' four-term series. Against Simpson on 40000 panels
// (the phase turns up to 600 rad over the aperture: 0.03 rad a panel), at phases between the rows:
// measured at most 9e-6 of the in-focus peak past 1e-3 of the value; 2e-5 + 3e-3 of it allowed.
TEST(DefocusedPattern, TheTableAndTheEndsSeriesAreTheAperturesIntegral) {
    auto reference = [](bool hann, double x, double phi) { return aperture_power(hann, x, phi, 40000); };
    for (const bool hann : {false, true}) {
        const plan_steps::DefocusedPattern table(hann ? shared::kPatternHann : shared::kPatternSinc, 64.0);
        double worst = 0.0;
        std::size_t checked = 0;
        for (double phi : {0.013, 0.51, 3.77, 4.93, 17.31, 40.4, 63.9}) {
            const double reach = 7.0 * phi + 3.0 * kPi;
            for (int i = 0; i <= 60; ++i) {
                const double x = reach * i / 60.0 + 0.0137;
                const double want = reference(hann, x, phi), got = table.power(x, phi);
                const double excess = std::abs(got - want) - 1e-3 * want;
                worst = std::max(worst, excess);
                EXPECT_LE(std::abs(got - want), 2e-5 + 3e-3 * want)
                    << (hann ? "hann" : "sinc") << " phi " << phi << " x " << x << ": " << got << " vs " << want;
                ++checked;
            }
        }
        std::printf("[defocused table] %s: %zu points, worst %.2g past 1e-3 of the value\n", hann ? "hann" : "sinc",
                    checked, worst);
    }
}

// A phase past 64 rad is refused at plan time with the key and the range where it stays within (a table
// for 300 rad took 44 s and 830 MB; a focus of 1 cm would have needed 21 GB).
TEST(DefocusedPattern, APhasePastTheTableIsAPlanErrorNamingTheRange) {
    SceneBuilder b;
    b.material(-20.0);
    // The plan's error for `config`, "" where it plans.
    auto plan_error = [&](const SonarConfig& config) {
        auto plan = make_plan(config, b.scene);
        return plan.ok() ? std::string() : plan.error().message;
    };
    auto has = [](const std::string& text, const char* part) { return text.find(part) != std::string::npos; };
    SonarConfig config;
    config.beam_focus = BeamFocus::none;
    config.range_min_m = 0.01; // the first bin's centre at 0.049 m: 4.03 / 0.049 = 82 rad
    std::string error = plan_error(config);
    EXPECT_TRUE(has(error, "config: beam_focus = none: the defocus phase")) << error;
    EXPECT_TRUE(has(error, "raise range_min to 0.06")) << error;
    config.beam_focus = BeamFocus::fixed;
    config.focus_range_m = 1e-300; // a denormal focus: infinite phase, refused the same way
    error = plan_error(config);
    EXPECT_TRUE(has(error, "beam_focus = fixed")) << error;
    // The remedy on the worst bin's side of the focus: nearer than F raise range_min, beyond F lower range_max.
    config.bins = 4096;
    config.focus_range_m = 2.0;
    error = plan_error(config);
    EXPECT_TRUE(has(error, "raise range_min to 0.061")) << error;
    config.range_min_m = 0.5;
    config.bins = 512;
    config.focus_range_m = 0.04;
    error = plan_error(config);
    EXPECT_TRUE(has(error, "lower range_max to 0.10")) << error;
    config.focus_range_m = 2.0;
    EXPECT_EQ(plan_error(config), "");
    // Where no near kernel applies the focus (the horizontal pattern off), nothing is tabulated or refused.
    config.range_min_m = 0.01;
    config.effects.horizontal_pattern = EffectMode::off;
    auto plan = make_plan(config, b.scene);
    ASSERT_TRUE(plan.ok()) << plan.error().message;
    EXPECT_EQ(plan->near_bands, 1u);
}

// A second review: the focus reach (x = 7 phi + 3 pi) compared 0 <= 0 for a box pattern (its pattern
// constant is 0) and took every column into a dynamic plan's kernel. The near kernel of a box stops at the
// configured reach: every beam's columns within it (in sine, the line array).
TEST(NearKernel, ABoxKernelStopsAtTheConfiguredReach) {
    SceneBuilder b;
    b.material(-20.0);
    SonarConfig config;
    config.horizontal_pattern = BeamPattern::box;
    config.horizontal_beamwidth_deg = 3.0;
    config.sidelobe_kernel_beamwidths = 0.4;
    config.effects.horizontal_pattern = EffectMode::on;
    const Plan plan = plan_for(config, b.scene);
    ASSERT_FALSE(plan.near_column_begin.empty());
    const double reach = std::sin(0.4 * 3.0 * kDeg);
    for (std::uint32_t j = 0; j < plan.beams; ++j)
        for (std::uint32_t t = 0; t < plan.near_column_count[j]; ++t) {
            const std::uint32_t c = static_cast<std::uint32_t>(plan.near_column_begin[j] + std::int32_t(t));
            const double sep = std::sin(plan.column_azimuth_rad[c]) - std::sin(plan.beam_angle_rad[j]);
            ASSERT_LE(std::abs(sep), reach * (1 + 1e-9)) << "beam " << j << " column " << c;
        }
}

} // namespace
} // namespace vksonar
