// Tests of the CPU beamform stage (src/stages/cpu_beamform_profile.cpp and cpu_beamform.cpp) against docs/pipeline.md
// §4: energy conservation, resampling weights, side lobes, float vs double. Every tolerance is justified next to it.
#include <gtest/gtest.h>

#include <filesystem>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "cpu_stage_support.h"
#include "stages/gpu_cpu_support.h"
#include "vk/profile_bands.h"
#include "vk/resample_walk.h"
#include "vk/vulkan_backend_impl.h"

namespace vksonar {
namespace {

using namespace stage_testing;

template <class Real> class CpuBeamform : public ::testing::Test {};
TYPED_TEST_SUITE(CpuBeamform, Precisions);

struct BeamformOut {
    std::vector<float> profiles, beams, polar;
};

template <class Real> BeamformOut run_beamform(const Plan& plan, const std::vector<float>& echo2) {
    BeamformOut o;
    o.profiles.assign(std::size_t(plan.bins) * plan.columns, -1.0f);
    o.beams.assign(std::size_t(plan.bins) * plan.beams, -1.0f);
    o.polar.assign(std::size_t(plan.bins) * plan.beams, -1.0f);
    cpu::beamform<Real>(plan, echo2.data(), o.profiles.data(), o.beams.data(), o.polar.data());
    return o;
}

// Random echo: energies in (0, 1) at ranges inside the window and at least a bin from its edges (so
// the tent kernel keeps every share: the window gates what lies beyond), a third of the pixels empty.
std::vector<float> random_echo(const Plan& plan, double* total) {
    std::mt19937 rng(1234);
    std::uniform_real_distribution<double> uni(0.0, 1.0);
    std::vector<float> e(std::size_t(plan.rows) * plan.columns * 2, 0.0f);
    *total = 0;
    const double lo = plan.config.range_min_m + plan.bin_width_m, hi = plan.config.range_max_m - plan.bin_width_m;
    for (std::size_t p = 0; p < e.size() / 2; ++p) {
        if (uni(rng) < 0.33) continue;
        const double r = lo + uni(rng) * (hi - lo);
        e[2 * p] = float(uni(rng));
        e[2 * p + 1] = float(r);
        *total += e[2 * p];
    }
    return e;
}

TYPED_TEST(CpuBeamform, TentKernelConservesEnergyAndIsBitIdenticalRunToRun) {
    using Real = TypeParam;
    SceneBuilder b;
    b.material(-20.0);
    SonarConfig config = small_config();
    config.effects.horizontal_pattern = EffectMode::off;
    const Plan plan = plan_for(config, b.scene);
    double total = 0;
    const std::vector<float> echo2 = random_echo(plan, &total);
    const BeamformOut a = run_beamform<Real>(plan, echo2);
    const BeamformOut again = run_beamform<Real>(plan, echo2);
    EXPECT_EQ(0, std::memcmp(a.polar.data(), again.polar.data(), a.polar.size() * sizeof(float)));
    EXPECT_EQ(0, std::memcmp(a.profiles.data(), again.profiles.data(), a.profiles.size() * sizeof(float)));

    double sum_profiles = 0, sum_beams = 0, sum_polar = 0;
    for (float x : a.profiles)
        sum_profiles += x;
    for (float x : a.beams)
        sum_beams += x;
    for (float x : a.polar)
        sum_polar += x;
    // ~1400 values of ~0.5 summed per column into ~128 bins: float accumulation error ~ sqrt(rows) eps
    // per bin, float storage 6e-8; 1e-5 relative covers float arithmetic with a wide margin, double
    // arithmetic only sees the float roundings of the stored intermediates (1e-6).
    const double tol = (std::is_same_v<Real, double> ? 1e-6 : 1e-5) * total;
    EXPECT_NEAR(sum_profiles, total, tol);
    EXPECT_NEAR(sum_beams, total, tol);
    EXPECT_NEAR(sum_polar, total, tol);
    for (std::size_t i = 0; i < a.polar.size(); ++i)
        EXPECT_EQ(a.polar[i], a.beams[i]); // pattern off: copy
}

TYPED_TEST(CpuBeamform, RangeKernelsPlaceEnergyInTheContractsBins) {
    using Real = TypeParam;
    SceneBuilder b;
    b.material(-20.0);
    for (RangeKernel kernel : {RangeKernel::nearest, RangeKernel::tent}) {
        SonarConfig config = small_config();
        config.range_kernel = kernel;
        config.effects.horizontal_pattern = EffectMode::off;
        const Plan plan = plan_for(config, b.scene);
        const double w = plan.bin_width_m, r0 = plan.config.range_min_m;
        struct Case {
            double r, e;
        };
        // column 0: bin centre of bin 10; column 1: a quarter into bin 20; column 2: just above range_min;
        // column 3: just below range_max.
        const Case cases[4] = {
            {r0 + 10.5 * w, 1.0}, {r0 + 20.25 * w, 2.0}, {r0 + 0.1 * w, 4.0}, {r0 + (plan.bins - 0.1) * w, 8.0}};
        std::vector<float> echo2(std::size_t(plan.rows) * plan.columns * 2, 0.0f);
        for (int c = 0; c < 4; ++c) {
            echo2[2 * (std::size_t(7) * plan.columns + c)] = float(cases[c].e);
            echo2[2 * (std::size_t(7) * plan.columns + c) + 1] = float(cases[c].r);
        }
        const BeamformOut o = run_beamform<Real>(plan, echo2);
        auto prof = [&](std::uint32_t k, std::uint32_t c) {
            return double(o.profiles[std::size_t(k) * plan.columns + c]);
        };
        // Tolerances: ranges are stored as float (ulp ~2e-6 m at 20 m, i.e. 7e-6 of a 0.31 m bin).
        const double tol = 1e-4;
        if (kernel == RangeKernel::nearest) {
            EXPECT_EQ(prof(10, 0), 1.0);
            EXPECT_EQ(prof(20, 1), 2.0);
            EXPECT_EQ(prof(0, 2), 4.0);
            EXPECT_EQ(prof(plan.bins - 1, 3), 8.0);
        } else {
            EXPECT_NEAR(prof(10, 0), 1.0, tol);
            // t = 19.75: 0.25 to bin 19, 0.75 to bin 20
            EXPECT_NEAR(prof(19, 1), 0.25 * 2.0, tol * 2);
            EXPECT_NEAR(prof(20, 1), 0.75 * 2.0, tol * 2);
            // The window gates: t = -0.4 puts 0.4 of the energy below bin 0 (dropped), 0.6 into bin 0;
            // t = bins - 0.6 puts 0.6 into the last bin and 0.4 above it (dropped).
            EXPECT_NEAR(prof(0, 2), 0.6 * 4.0, tol * 4);
            EXPECT_NEAR(prof(plan.bins - 1, 3), 0.6 * 8.0, tol * 8);
        }
        // What stays inside the window: all of it, except the tent's shares beyond the edges.
        const bool tent = kernel == RangeKernel::tent;
        const double kept[4] = {1.0, 2.0, tent ? 0.6 * 4.0 : 4.0, tent ? 0.6 * 8.0 : 8.0};
        for (int c = 0; c < 4; ++c) {
            double s = 0;
            for (std::uint32_t k = 0; k < plan.bins; ++k)
                s += prof(k, c);
            EXPECT_NEAR(s, kept[c], 1e-5 * kept[c]); // float roundings of the shares only
        }
    }
}

TYPED_TEST(CpuBeamform, ResampleAndSidelobeFollowTheirFormulas) {
    using Real = TypeParam;
    SceneBuilder b;
    b.material(-20.0);
    SonarConfig config = small_config();
    config.horizontal_beamwidth_deg = 4.0; // several side-lobe taps
    const Plan plan = plan_for(config, b.scene);
    ASSERT_TRUE(plan.effects.horizontal_pattern);
    ASSERT_GT(plan.sidelobe_taps, 3u);
    double total = 0;
    const std::vector<float> echo2 = random_echo(plan, &total);
    const BeamformOut o = run_beamform<Real>(plan, echo2);
    // The far side lobes (plan.h far_cells) from their definition: each profile column's two cell shares
    // (first cell 1 - s, second s); with the phase channels (a line array's sinc^2) the cells also
    // take the energy times cos and sin of the column's phase 2k u; each channel is convolved with
    // far_weight[cells - 1 + a - b]; a beam reads l0 - cos l1 - sin l2 back (at least 0) with its own
    // shares and phase.
    const std::uint32_t cells = plan.far_cells;
    ASSERT_GT(cells, 1u) << "a 4-degree beam's 3-beamwidth kernel stops short of the fan";
    ASSERT_EQ(plan.far_channels, plan.line_array ? 3u : 1u);
    auto share_in = [&](const std::vector<float>& table, std::uint32_t j, std::uint32_t c) {
        const float* bc = table.data() + 8 * std::size_t(j);
        return std::uint32_t(bc[0]) == c ? 1.0 - bc[2] : std::uint32_t(bc[1]) == c ? double(bc[2]) : 0.0;
    };
    auto phase_in = [&](const std::vector<float>& table, std::uint32_t j, std::uint32_t m) {
        return m == 0 ? 1.0 : double(table[8 * std::size_t(j) + 3 + m]);
    };
    auto share = [&](std::uint32_t j, std::uint32_t c) { return share_in(plan.far_beam_cell, j, c); };
    auto phase = [&](std::uint32_t j, std::uint32_t m) { return phase_in(plan.far_beam_cell, j, m); };
    ASSERT_EQ(plan.far_column_cell.size(), 8 * std::size_t(plan.columns));
    double max_rel = 0;
    for (std::uint32_t k = 0; k < plan.bins; ++k) {
        std::vector<double> far(3 * std::size_t(cells), 0.0);
        for (std::uint32_t m = 0; m < plan.far_channels; ++m) {
            std::vector<double> cell(cells, 0.0);
            for (std::uint32_t c = 0; c < cells; ++c)
                for (std::uint32_t i = 0; i < plan.columns; ++i)
                    cell[c] += share_in(plan.far_column_cell, i, c) * phase_in(plan.far_column_cell, i, m) *
                               o.profiles[std::size_t(k) * plan.columns + i];
            for (std::uint32_t a = 0; a < cells; ++a)
                for (std::uint32_t c = 0; c < cells; ++c)
                    far[m * cells + a] += double(plan.far_weight[cells - 1 + a - c]) * cell[c];
        }
        for (std::uint32_t j = 0; j < plan.beams; ++j) {
            double B = 0; // resample from the definition: every column, weight by the table
            for (std::uint32_t c = 0; c < plan.columns; ++c) {
                const double w = plan.column_beam[c] == j       ? plan.column_weight[c]
                                 : plan.column_beam[c] + 1 == j ? 1.0 - plan.column_weight[c]
                                                                : 0.0;
                B += w * o.profiles[std::size_t(k) * plan.columns + c];
            }
            double P = 0; // the near kernel: every column the plan gives beam j, by its weight
            for (std::uint32_t t = 0; t < plan.near_column_count[j]; ++t) {
                const std::int64_t c = plan.near_column_begin[j] + std::int64_t(t);
                ASSERT_TRUE(c >= 0 && c < std::int64_t(plan.columns));
                P += double(plan.near_column_weight[j * plan.near_column_taps + t]) *
                     o.profiles[std::size_t(k) * plan.columns + std::size_t(c)];
            }
            double level = 0;
            for (std::uint32_t m = 0; m < plan.far_channels; ++m)
                for (std::uint32_t c = 0; c < cells; ++c)
                    level += (m == 0 ? 1.0 : -phase(j, m)) * share(j, c) * far[m * cells + c];
            P += std::max(level, 0.0);
            const double gotB = o.beams[std::size_t(k) * plan.beams + j],
                         gotP = o.polar[std::size_t(k) * plan.beams + j];
            // Sums of positive float terms (the resample's ~4, the near kernel's ~25 columns, the far
            // cells' few dozen, each stored once in float): float arithmetic is good to ~1e-6 relative.
            EXPECT_NEAR(gotB, B, 2e-6 * B + 1e-30);
            EXPECT_NEAR(gotP, P, 2e-6 * P + 1e-30);
            if (P > 0) max_rel = std::max(max_rel, std::abs(gotP - P) / P);
        }
    }
    this->RecordProperty("max_rel_sidelobe", std::to_string(max_rel));
}
// The near kernel weighs each profile column by the horizontal pattern at its own direction (docs/pipeline.md
// §4, "Side lobes"): one column's unit profile in bin k gives beam j exactly b_h^2 at their separation,
// wherever the column falls between beams. The pattern is the test's own: the sinc^2 of a uniform line
// array whose two-way -3 dB width is the beamwidth, at the separation in sine (line_array, columns
// uniform in steering angle: column c at (1 - (2c + 1) / columns) hfov / 2) or in angle (planar, the
// pixel columns' azimuths as the depth pass renders them). Far side lobes off, so that the kernel's
// taps are the whole pattern out to the reach (3 beamwidths) and 0 beyond. Bin k holds column k's
// impulse (a third of the columns, those within +-2 beams of five steering angles), so every beam of
// a bin hears one column. Cases: the default 512 x 1 deg line array, a planar fan, and 65 beams 2 deg
// apart with 1 deg beams (the tent put a target midway between two such beams 3 dB down in both, where
// the pattern says 18 dB).
TYPED_TEST(CpuBeamform, NearKernelIsThePatternAtEachColumnsDirection) {
    using Real = TypeParam;
    SceneBuilder b;
    b.material(-20.0);
    struct Case {
        const char* name;
        BeamGeometry geometry;
        std::uint32_t beams;
    };
    for (const Case& kase : {Case{"line_array", BeamGeometry::line_array, 512},
                             Case{"planar", BeamGeometry::planar, 512}, Case{"sparse", BeamGeometry::line_array, 65}}) {
        SonarConfig config; // the default sonar: 130 x 20 deg, 1 deg sinc beams
        config.beam_geometry = kase.geometry;
        config.beams = kase.beams;
        config.far_sidelobe_cell = 0.0;
        config.effects.horizontal_pattern = EffectMode::on;
        const Plan plan = plan_for(config, b.scene);
        ASSERT_EQ(plan.line_array, kase.geometry == BeamGeometry::line_array);
        ASSERT_EQ(plan.far_cells, 0u);
        const std::uint32_t columns = plan.profile_columns, beams = plan.beams;
        const double hbw = config.horizontal_beamwidth_deg * kDeg;
        const double reach = config.sidelobe_kernel_beamwidths * hbw;
        const double half = 0.5 * config.hfov_deg * kDeg;
        auto beam_angle = [&](std::uint32_t j) { return (1.0 - (2.0 * j + 1.0) / beams) * half; };
        auto column_angle = [&](std::uint32_t c) {
            if (plan.line_array) return (1.0 - (2.0 * c + 1.0) / columns) * half;
            return plan.column_azimuth_rad[c]; // planar: the pixel grid's own azimuths (checked elsewhere)
        };
        auto pattern = [&](double sep) { // sep: in sine (line array) or angle (planar)
            const double angle = plan.line_array ? std::asin(std::clamp(sep, -1.0, 1.0)) : sep;
            const double x = testing::sinc_half_power_x() * std::sin(angle) / std::sin(0.5 * hbw);
            if (std::abs(x) < 1e-12) return 1.0;
            return (std::sin(x) / x) * (std::sin(x) / x);
        };
        // The impulses: columns within +-2 beams of these steering angles, one bin each.
        std::vector<std::uint32_t> impulse_columns;
        for (double steer_deg : {0.0, 20.0, -40.0, 55.0, -63.0}) {
            const double steer = steer_deg * kDeg;
            for (std::uint32_t c = 0; c < columns; ++c)
                if (std::abs(column_angle(c) - steer) <= 2.0 * config.hfov_deg * kDeg / beams)
                    impulse_columns.push_back(c);
        }
        ASSERT_LE(impulse_columns.size(), std::size_t(plan.bins));
        const std::size_t T = cpu::profile_column_stride(plan);
        std::vector<Real> acc(cpu::beamform_accumulator_count(plan), Real(0));
        for (std::size_t i = 0; i < impulse_columns.size(); ++i)
            acc[impulse_columns[i] * T + i] = Real(1);
        std::vector<Real> weights(std::max<std::size_t>(cpu::resample_weight_count(plan), 1));
        cpu::resample_weights<Real>(plan, weights.data());
        std::vector<float> beam_profiles(std::size_t(plan.bins) * beams), polar(std::size_t(plan.bins) * beams);
        cpu::beamform_beams<Real>(plan, acc.data(), weights.data(), beam_profiles.data(), polar.data(), 0, plan.bins);
        double worst_main_lobe_db = 0, worst = 0;
        std::size_t checked = 0;
        for (std::size_t i = 0; i < impulse_columns.size(); ++i) {
            const std::uint32_t c = impulse_columns[i];
            for (std::uint32_t j = 0; j < beams; ++j) {
                const double sep = plan.line_array ? std::sin(column_angle(c)) - std::sin(beam_angle(j))
                                                   : column_angle(c) - beam_angle(j);
                const double reach_units = plan.line_array ? std::sin(reach) : reach;
                const double got = polar[i * beams + j];
                if (std::abs(sep) > reach_units * (1 + 1e-6)) {
                    ASSERT_EQ(got, 0.0) << kase.name << " column " << c << " beam " << j << ": beyond the reach";
                    continue;
                }
                if (std::abs(std::abs(sep) - reach_units) < 1e-6 * reach_units) continue; // on the reach: either
                const double expected = pattern(sep);
                // One product of a float weight and 1: the pattern rounded to float (6e-8 relative), and the
                // separation of two float-free doubles: 1e-6 relative plus 1e-9 near the nulls.
                ASSERT_NEAR(got, expected, 1e-6 * expected + 1e-9)
                    << kase.name << " column " << c << " (" << column_angle(c) / kDeg << " deg) beam " << j << " ("
                    << beam_angle(j) / kDeg << " deg)";
                worst = std::max(worst, std::abs(got - expected));
                if (expected > 0.5)
                    worst_main_lobe_db = std::max(worst_main_lobe_db, std::abs(testing::to_db(got / expected)));
                ++checked;
            }
        }
        std::printf("[near kernel] %-10s %zu columns, %zu cells within the reach: worst %.2g absolute, %.2g dB in "
                    "the main lobe's upper half\n",
                    kase.name, impulse_columns.size(), checked, worst, worst_main_lobe_db);
        EXPECT_GT(checked, 100u);
    }
}

// A point's whole horizontal pattern, the near kernel and the far side lobes' grid together (docs/pipeline.md
// §4, "Side lobes"): a unit impulse in each profile column between two beams near broadside and near 40
// deg, every beam of the default 512-beam fan against the test's own sinc^2 at the column's separation (in
// sine with the line array, in angle planar).
// - Within the kernel's reach R (3 beamwidths) the near weights are the pattern less what the grid gives
//   the same column at the same beam, so the two add up to the pattern: to 1e-6 of it, plus the float
//   roundings of the grid's cells (1e-7 of the lobes' envelope 1 / x^2; 1e-6 allowed).
// - Past R the grid alone (cells 1.5 beamwidths wide), its weights fitted over where a column and a beam
//   fall in their cells (plan_beams.cpp fit_far_weights). The line array's three channels keep the crests
//   and nulls: the error as a fraction of the envelope, measured rms 0.0046 and at most 0.076 at single
//   beams; each side lobe's energy (the sum over its beams) within 0.12 dB of the pattern's, lobes 1 to 11.
//   Before (the grid's share ramped in from R / 2 to R, its weights the envelope averaged over a cell): rms
//   0.017, worst 0.18, the second side lobe 1.9 dB low and lobes 3 to 6 0.4 to 0.5 dB high, within R up
//   to 0.2 of pattern + envelope off; before that
//   (the grid fed through the tent's beams) rms 0.053, the nulls up to 0.138.
// - Planar, one channel (the grid carries the lobes' mean level, not their crests): exact within R as
//   above, although some near weights are negative there (the grid's mean at the pattern's nulls), and no
//   scan cell below 0 (far_scan_cell); past R each pair of neighbouring side lobes' energy within 0.45 dB
//   of the pattern's (measured 0.38; 0.65 before, and within R up to 0.35 of pattern + envelope off).
TEST(FarSidelobes, APointHearsItsWholePatternFromEveryBeam) {
    SceneBuilder b;
    b.material(-20.0);
    for (const BeamGeometry geometry : {BeamGeometry::line_array, BeamGeometry::planar}) {
        const bool line = geometry == BeamGeometry::line_array;
        SonarConfig config; // the default sonar: 130 x 20 deg, 512 1-deg sinc beams
        config.beam_geometry = geometry;
        config.effects.horizontal_pattern = EffectMode::on;
        const Plan plan = plan_for(config, b.scene);
        ASSERT_EQ(plan.line_array, line);
        ASSERT_GT(plan.far_cells, 0u);
        ASSERT_EQ(plan.far_channels, line ? 3u : 1u);
        const std::uint32_t columns = plan.profile_columns, beams = plan.beams;
        const double hbw = config.horizontal_beamwidth_deg * kDeg, half = 0.5 * config.hfov_deg * kDeg;
        const double reach = config.sidelobe_kernel_beamwidths * hbw;
        const double reach_units = line ? std::sin(reach) : reach;
        const double x_per_sine = testing::sinc_half_power_x() / std::sin(0.5 * hbw);
        auto beam_angle = [&](std::uint32_t j) { return (1.0 - (2.0 * j + 1.0) / beams) * half; };
        auto column_angle = [&](std::uint32_t c) {
            if (line) return (1.0 - (2.0 * c + 1.0) / columns) * half; // the cone columns' steering angles
            return plan.column_azimuth_rad[c]; // planar: the pixel grid's own azimuths (checked elsewhere)
        };
        auto separation = [&](std::uint32_t c, std::uint32_t j) {
            return line ? std::sin(column_angle(c)) - std::sin(beam_angle(j)) : column_angle(c) - beam_angle(j);
        };
        auto x_of = [&](double sep) { return x_per_sine * (line ? sep : std::sin(sep)); };
        std::vector<std::uint32_t> impulse_columns;
        for (const double steer_deg : {0.3, 40.0})
            for (std::uint32_t c = 0; c < columns; ++c)
                if (std::abs(column_angle(c) - steer_deg * kDeg) < 0.3 * kDeg) impulse_columns.push_back(c);
        ASSERT_GE(impulse_columns.size(), 6u);
        const std::size_t T = cpu::profile_column_stride(plan);
        std::vector<float> acc(cpu::beamform_accumulator_count(plan), 0.0f);
        for (std::size_t i = 0; i < impulse_columns.size(); ++i)
            acc[impulse_columns[i] * T + i] = 1.0f;
        std::vector<float> weights(std::max<std::size_t>(cpu::resample_weight_count(plan), 1));
        cpu::resample_weights<float>(plan, weights.data());
        std::vector<float> beam_profiles(std::size_t(plan.bins) * beams), polar(std::size_t(plan.bins) * beams);
        cpu::beamform_beams<float>(plan, acc.data(), weights.data(), beam_profiles.data(), polar.data(), 0, plan.bins);
        EXPECT_GE(*std::min_element(polar.begin(), polar.end()), 0.0f);
        const bool negative_weights = std::any_of(plan.near_column_weight.begin(), plan.near_column_weight.end(),
                                                  [](float w) { return w < 0.0f; });
        if (!line) {
            EXPECT_TRUE(negative_weights) << "the planar case is meant to cover negative near weights";
        }
        constexpr int kLobes = 12; // the main lobe (0) and side lobes 1 to 11, by |x| / pi
        double near_worst = 0, sum_sq = 0, worst = 0, null_fill = 0, lobe_worst_db = 0;
        std::size_t near_n = 0, far_n = 0;
        for (std::size_t i = 0; i < impulse_columns.size(); ++i) {
            double got_lobe[kLobes] = {}, exact_lobe[kLobes] = {};
            for (std::uint32_t j = 0; j < beams; ++j) {
                const double sep = separation(impulse_columns[i], j), x = x_of(sep);
                // planar: nothing from behind a beam's baffled aperture (90 deg or more away)
                const double exact = !line && std::abs(sep) >= 0.5 * kPi ? 0.0
                                     : std::abs(x) < 1e-12               ? 1.0
                                                                         : (std::sin(x) / x) * (std::sin(x) / x);
                const double envelope = std::min(1.0, 1.0 / (x * x)), got = polar[i * beams + j];
                const int lobe = static_cast<int>(std::abs(x) / kPi);
                if (lobe < kLobes) {
                    got_lobe[lobe] += got;
                    exact_lobe[lobe] += exact;
                }
                if (std::abs(sep) < reach_units * (1.0 - 1e-6)) {
                    ASSERT_NEAR(got, exact, 1e-6 * (exact + envelope))
                        << (line ? "line array" : "planar") << " column " << impulse_columns[i] << " beam " << j;
                    near_worst = std::max(near_worst, std::abs(got - exact) / (exact + envelope));
                    ++near_n;
                    continue;
                }
                const double err = std::abs(got - exact) / envelope;
                worst = std::max(worst, err);
                sum_sq += err * err;
                ++far_n;
                if (exact < 0.05 * envelope) null_fill = std::max(null_fill, got / envelope);
            }
            // Side lobes past the reach's (R reaches into lobe 2): alone with the crests, in pairs without.
            for (int lobe = 1; lobe + (line ? 0 : 1) < kLobes; lobe += line ? 1 : 2) {
                const double got = got_lobe[lobe] + (line ? 0.0 : got_lobe[lobe + 1]);
                const double exact = exact_lobe[lobe] + (line ? 0.0 : exact_lobe[lobe + 1]);
                lobe_worst_db = std::max(lobe_worst_db, std::abs(testing::to_db(got / exact)));
            }
        }
        const double rms = std::sqrt(sum_sq / double(far_n));
        std::printf("[whole pattern] %-10s %zu columns: within the reach %zu beams, worst %.2g of pattern + "
                    "envelope; past it %zu, error / envelope rms %.4f, worst %.4f, nulls up to %.3f; side lobes' "
                    "energy within %.2f dB\n",
                    line ? "line array" : "planar", impulse_columns.size(), near_n, near_worst, far_n, rms, worst,
                    null_fill, lobe_worst_db);
        EXPECT_GT(near_n, 100u);
        if (line) {
            EXPECT_LT(rms, 0.008);
            EXPECT_LT(worst, 0.12);
            EXPECT_LT(null_fill, 0.08);
            EXPECT_LT(lobe_worst_db, 0.25);
        } else {
            EXPECT_LT(lobe_worst_db, 0.45);
        }
    }
}

// The horizontal pattern forced on with no kernel (a reach short of the next beam: K = 0) is the tent: the
// scan is the resampled beam profiles, and each beam's columns are the tent's few (also on a full circle,
// where the resample's seam beams gather from both ends of the pixel grid).
TYPED_TEST(CpuBeamform, ThePatternWithNoKernelIsTheTent) {
    using Real = TypeParam;
    SceneBuilder b;
    b.material(-20.0);
    for (const double hfov : {40.0, 360.0}) {
        SonarConfig config = small_config();
        config.hfov_deg = hfov;
        config.beams = hfov > 180.0 ? 64 : 32;
        config.sidelobe_kernel_beamwidths = 0.1; // 0.2 deg against beams 1.25 or 5.6 deg apart
        config.effects.horizontal_pattern = EffectMode::on;
        const Plan plan = plan_for(config, b.scene);
        ASSERT_TRUE(plan.effects.horizontal_pattern);
        ASSERT_EQ(plan.sidelobe_taps, 1u);
        ASSERT_EQ(plan.circular, hfov > 180.0);
        EXPECT_LE(plan.near_column_taps, 4u * plan.columns / plan.beams) << "hfov " << hfov;
        double total = 0;
        const std::vector<float> echo2 = random_echo(plan, &total);
        const BeamformOut o = run_beamform<Real>(plan, echo2);
        // The same terms, the tent's weights stored as floats and a seam beam's columns summed from the
        // seam on (the resample sums them in index order): float sums of <= 4 terms, 2e-6 relative.
        for (std::size_t i = 0; i < o.polar.size(); ++i)
            ASSERT_NEAR(o.polar[i], o.beams[i], 2e-6 * o.beams[i]) << "hfov " << hfov << " cell " << i;
    }
}

// A kernel asked to reach across the fan (bench accuracy's reference: 1000 beamwidths) hears every column
// from every beam, also where the beams' table caps its reach in beams (K = beams - 1) and a line array's
// beams lie closer in sine at the edges than at broadside; on a full circle every column once.
TEST(NearKernel, AKernelAcrossTheFanHearsEveryColumnOnce) {
    SceneBuilder b;
    b.material(-20.0);
    for (const double hfov : {130.0, 360.0}) {
        SonarConfig config;
        config.hfov_deg = hfov;
        config.beams = 128;
        config.sidelobe_kernel_beamwidths = 1000.0;
        const Plan plan = plan_for(config, b.scene);
        ASSERT_EQ(plan.far_cells, 0u);
        ASSERT_EQ(plan.near_column_begin.size(), plan.beams);
        for (std::uint32_t j = 0; j < plan.beams; ++j) {
            // zero weights at either end are left out: a null may fall on the first or last column
            const std::uint32_t count = plan.near_column_count[j];
            EXPECT_GE(count + 2, plan.profile_columns) << "hfov " << hfov << " beam " << j;
            EXPECT_LE(count, plan.profile_columns) << "hfov " << hfov << " beam " << j;
        }
    }
}

// Backend

// A seabed tilted down ahead, a box on it and a wall behind: every stage has work to do.
SceneData test_scene() {
    SceneBuilder b;
    const std::uint32_t bed = b.material(-30.0), box = b.material(-15.0),
                        wall = b.material(-25.0, AcousticMaterial::Model::constant);
    b.draw(b.mesh({0.5f, -30.f, -1.0f, 45.f, -30.f, -6.0f, 45.f, 30.f, -6.0f, 0.5f, 30.f, -1.0f}, {0, 1, 2, 0, 2, 3}),
           bed);
    const double lo[3] = {12.0, -1.0, -3.0}, hi[3] = {13.5, 1.5, -1.0};
    b.draw(b.box(lo, hi), box, yaw_translate(20.0, 0, 0, 0));
    b.draw(b.quad_x(0.0, -20.0, 20.0, -8.0, 8.0), wall, yaw_translate(-15.0, 30.0, 0.0, 0.0));
    return b.scene;
}

Frame sized_frame(const Plan& plan) {
    Frame f;
    f.beams = plan.beams;
    f.bins = plan.bins;
    f.columns = plan.columns;
    f.rows = plan.rows;
    f.clean.resize(std::size_t(plan.bins) * plan.beams);
    return f;
}

TEST(CpuBackend, RunsTheContractsStagesAndFillsRequestedIntermediates) {
    const SceneData scene = test_scene();
    for (bool incidence : {true, false}) {
        SonarConfig config = small_config();
        config.effects.incidence = incidence ? EffectMode::on : EffectMode::off;
        const Plan plan = plan_for(config, scene);
        auto backend = cpu::make_backend(plan, scene);
        ASSERT_TRUE(backend);
        EXPECT_STREQ(backend->name(), "cpu");
        Frame frame = sized_frame(plan);
        Pose pose;
        pose.yaw_deg = 5.0;
        const SaveFlags mask = SaveFlags::depth | SaveFlags::normals | SaveFlags::echo | SaveFlags::profiles;
        auto r = backend->render(pose, mask, frame);
        ASSERT_TRUE(r.ok()) << r.error().message;
        const std::vector<std::string> expected = incidence
                                                      ? std::vector<std::string>{"depth", "normals", "echo", "beamform"}
                                                      : std::vector<std::string>{"depth", "echo", "beamform"};
        EXPECT_EQ(frame.stages_run, expected);
        ASSERT_EQ(frame.times.size(), expected.size());
        for (std::size_t i = 0; i < expected.size(); ++i) {
            EXPECT_EQ(frame.times[i].stage, expected[i]);
            EXPECT_GE(frame.times[i].ms, 0.0);
        }
        const std::size_t pixels = std::size_t(plan.rows) * plan.columns;
        EXPECT_EQ(frame.depth.size(), pixels);
        EXPECT_EQ(frame.material.size(), pixels);
        EXPECT_EQ(frame.normals.size(), incidence ? 4 * pixels : 0u);
        EXPECT_EQ(frame.echo.size(), 2 * pixels);
        EXPECT_EQ(frame.profiles.size(), std::size_t(plan.bins) * plan.columns);
        EXPECT_EQ(frame.beam_profiles.size(), std::size_t(plan.bins) * plan.beams);
        ASSERT_EQ(frame.clean.size(), std::size_t(plan.bins) * plan.beams);
        double sum = 0;
        for (float x : frame.clean) {
            ASSERT_TRUE(std::isfinite(x));
            ASSERT_GE(x, 0.0f);
            sum += x;
        }
        EXPECT_GT(sum, 0.0);

        // Same pose again: bit-identical scan, and no new buffers (the frame's data pointer is kept).
        const std::vector<float> first = frame.clean;
        const float* data = frame.clean.data();
        frame.times.clear();
        frame.stages_run.clear();
        auto r2 = backend->render(pose, mask, frame);
        ASSERT_TRUE(r2.ok());
        EXPECT_EQ(frame.clean.data(), data);
        EXPECT_EQ(0, std::memcmp(first.data(), frame.clean.data(), first.size() * sizeof(float)));
    }
}

TEST(CpuBackend, NonFinitePoseIsAnErrorNamingTheField) {
    const SceneData scene = test_scene();
    const Plan plan = plan_for(small_config(), scene);
    auto backend = cpu::make_backend(plan, scene);
    Frame frame = sized_frame(plan);
    Pose pose;
    pose.pitch_deg = std::numeric_limits<double>::quiet_NaN();
    auto r = backend->render(pose, SaveFlags::none, frame);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("pitch"), std::string::npos) << r.error().message;
}

TEST(CpuBackend, DoubleAndFloatPrecisionAgree) {
    const SceneData scene = test_scene();
    SonarConfig config = small_config();
    config.cpu_precision = Precision::f32;
    const Plan p32 = plan_for(config, scene);
    config.cpu_precision = Precision::f64;
    const Plan p64 = plan_for(config, scene);
    Frame f32 = sized_frame(p32), f64 = sized_frame(p64);
    Pose pose;
    pose.yaw_deg = -3.0;
    ASSERT_TRUE(cpu::make_backend(p32, scene)->render(pose, SaveFlags::echo, f32).ok());
    ASSERT_TRUE(cpu::make_backend(p64, scene)->render(pose, SaveFlags::echo, f64).ok());
    double total32 = 0, total64 = 0, peak = 0;
    for (std::size_t i = 0; i < f64.clean.size(); ++i) {
        total32 += f32.clean[i];
        total64 += f64.clean[i];
        peak = std::max(peak, double(f64.clean[i]));
    }
    ASSERT_GT(total64, 0.0);
    // Per cell, relative to the scan's peak: a cell that holds only a small tent share of a pixel
    // has an ill-conditioned relative error (its share moves with the pixel's range), so cells are
    // compared against the peak.
    double max_rel_peak = 0;
    for (std::size_t i = 0; i < f64.clean.size(); ++i) {
        max_rel_peak = std::max(max_rel_peak, std::abs(double(f32.clean[i]) - f64.clean[i]) / peak);
    }
    // Both share the float depth buffer, so the differences are float arithmetic in the later
    // stages: per-pixel energies agree to a few 1e-6 (about ten roundings and an exp of ~-4), and a
    // range moved by float rounding (~1e-6 of a bin) moves that much of a pixel's tent weight.
    EXPECT_NEAR(total32 / total64, 1.0, 1e-5);
    EXPECT_LT(max_rel_peak, 1e-5);
    // Per pixel: relative, except near the vertical pattern's first null, which the depth pass covers
    // (src/core/plan_grid.cpp). There the pattern b -> 0 while its float error, from x = k sin(psi) rounded
    // to float (~1e-7 relative), falls only as sqrt(b) (|db| = |2 a a'| x 1e-7, a the amplitude, at most
    // ~1e-7 on the main lobe's flank): each pixel is measured against max(E, 1e-3 x E0), E0 its f64 echo
    // without the pattern, so near the null its error must stay below 1e-7 of E0 (measured: the worst
    // pixel of the frame at 1.3e-5 of that scale; 1.06e-4 relative to E alone, next to the null).
    Plan flat64 = p64;
    flat64.effects.vertical_pattern = false;
    Frame e0 = sized_frame(flat64);
    ASSERT_TRUE(cpu::make_backend(flat64, scene)->render(pose, SaveFlags::echo, e0).ok());
    double max_rel_pixel = 0;
    for (std::size_t p = 0; p < f64.echo.size(); p += 2) {
        if (!(f64.echo[p] > 0)) continue;
        const double d = std::abs(double(f32.echo[p]) - f64.echo[p]);
        max_rel_pixel = std::max(max_rel_pixel, d / std::max(double(f64.echo[p]), 1e-3 * e0.echo[p]));
    }
    EXPECT_LT(max_rel_pixel, 1e-4);
    RecordProperty("f32_vs_f64_total", std::to_string(total32 / total64 - 1.0));
    RecordProperty("f32_vs_f64_max_cell_over_peak", std::to_string(max_rel_peak));
    RecordProperty("f32_vs_f64_max_pixel", std::to_string(max_rel_pixel));
    std::printf("f32 vs f64: total %.3g, max cell / peak %.3g, max pixel %.3g\n", total32 / total64 - 1.0, max_rel_peak,
                max_rel_pixel);
}

// ---- GPU vs CPU (tests/stages/gpu_cpu_support.h; tolerances: tests/tolerances.h) ------------------

using namespace ::vksonar::testing;

class BeamformGpuCpu : public GpuCpuScene {};

// The GPU frame's beamform passes against the CPU's from the GPU's own echo: the largest relative error
// of the range profiles, the beam profiles (before the side lobes) and the scan (floor kBeamformRelFloor
// x each array's peak), and the scan's in dB over the cells above the ambient noise floor. Each pass is
// compared, so that a failure names the first one that differs.
struct BeamformErrors {
    double profiles = 0, beam_profiles = 0, polar = 0, polar_db = 0;
    std::size_t above = 0;
};

double max_relative_error(const float* gpu, const float* cpu, std::size_t n) {
    double peak = 0;
    for (std::size_t i = 0; i < n; ++i)
        peak = std::max(peak, std::abs(double(cpu[i])));
    double worst = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const double a = gpu[i], b = cpu[i];
        worst = std::max(worst, std::abs(a - b) / std::max(std::abs(b), kBeamformRelFloor * peak));
    }
    return worst;
}

BeamformErrors beamform_errors(const Frame& g, const Plan& plan, const char* what) {
    const std::size_t profile_cells = std::size_t(plan.bins) * plan.profile_columns;
    const std::size_t cells = std::size_t(plan.bins) * plan.beams;
    std::vector<float> profiles(std::size_t(plan.bins) * std::max(plan.columns, plan.profile_columns));
    std::vector<float> beam_profiles(cells), polar(cells);
    cpu::beamform<float>(plan, g.echo.data(), profiles.data(), beam_profiles.data(), polar.data());
    BeamformErrors e;
    EXPECT_EQ(g.profiles.size(), profile_cells) << what;
    EXPECT_EQ(g.beam_profiles.size(), cells) << what;
    if (g.profiles.size() == profile_cells)
        e.profiles = max_relative_error(g.profiles.data(), profiles.data(), profile_cells);
    if (g.beam_profiles.size() == cells)
        e.beam_profiles = max_relative_error(g.beam_profiles.data(), beam_profiles.data(), cells);
    e.polar = max_relative_error(g.clean.data(), polar.data(), cells);
    // The scan in dB over the cells above the ambient noise floor (clean is relative to SL).
    const SonarConfig& cfg = plan.config;
    const double floor = std::pow(10.0, (cfg.noise_terms().floor_db() - cfg.source_level_db) / 10.0);
    for (std::size_t i = 0; i < cells; ++i) {
        if (!(polar[i] > floor)) continue;
        ++e.above;
        e.polar_db = std::max(e.polar_db, std::abs(10.0 * std::log10(double(g.clean[i]) / double(polar[i]))));
    }
    std::printf("[beamform] %s: max rel profiles %.2e, beam profiles %.2e, scan %.2e; max %.2e dB over %zu cells "
                "above the noise floor\n",
                what, e.profiles, e.beam_profiles, e.polar, e.polar_db, e.above);
    return e;
}

// tests/tolerances.h: lavapipe 1e-5 relative (4.3e-5 dB), a GPU 1e-4 relative and 5e-3 dB.
void expect_beamform_agrees(const BeamformErrors& e, const char* what) {
    const bool cpu_device = vulkan_device_is_cpu();
    const double rel = cpu_device ? kBeamformRelTol : kBeamformGpuRelTol;
    const double db = cpu_device ? 10.0 * std::log10(1.0 + kBeamformRelTol) : kBeamformGpuDbTol;
    EXPECT_LE(e.profiles, rel) << what << ": range profiles";
    EXPECT_LE(e.beam_profiles, rel) << what << ": beam profiles (resample)";
    EXPECT_LE(e.polar, rel) << what << ": scan (side lobes)";
    EXPECT_GT(e.above, 100u) << what;
    EXPECT_LE(e.polar_db, db) << what;
}

TEST_P(BeamformGpuCpu, MatchesOnTheSameInput) {
    auto p = render_pair(GetParam().file, quiet_config(), GetParam().pose, kSaveAll);
    ASSERT_TRUE(p);
    const std::string name = std::filesystem::path(GetParam().file).stem().string();
    const BeamformErrors e = beamform_errors(p->gpu->frame, renderer_plan(p->gpu->renderer), name.c_str());
    expect_beamform_agrees(e, name.c_str());
}

// The same with one part of the beamform stage changed at a time, on the default scene: a failure that
// shows in one configuration only names the part (the far side lobes, the footprint kernel, the cone
// gather, the tier views).
TEST(BeamformGpuCpuParts, EachPartMatchesOnTheSameInput) {
    const std::vector<std::pair<const char*, void (*)(SonarConfig&)>> parts{
        {"horizontal pattern off (no side-lobe passes)",
         [](SonarConfig& c) { c.effects.horizontal_pattern = EffectMode::off; }},
        {"tent range kernel", [](SonarConfig& c) { c.range_kernel = RangeKernel::tent; }},
        {"planar beams", [](SonarConfig& c) { c.beam_geometry = BeamGeometry::planar; }},
        {"vertical side lobes off", [](SonarConfig& c) { c.effects.vertical_sidelobes = EffectMode::off; }},
        // The near kernel's columns wrapped across the seam, runs of beams whose columns span both ends.
        {"a full circle (the near kernel's columns wrap)",
         [](SonarConfig& c) {
             c.hfov_deg = 360.0;
             c.beams = 256;
             c.horizontal_beamwidth_deg = 3.0;
         }},
        // Beams 2 deg apart with 1 deg beams (the columns follow the beamwidth: many a beam), no far grid.
        {"sparse beams, the kernel to the fan's edges",
         [](SonarConfig& c) {
             c.beams = 65;
             c.sidelobe_kernel_beamwidths = 1000.0;
         }},
        // 256 far cells (the cap): the per-channel convolve would loop 66k times in one invocation, past
        // lavapipe's limit (its last cells went unwritten); it takes a workgroup row per cell instead.
        {"the far grid at its 256 cells",
         [](SonarConfig& c) {
             c.hfov_deg = 45.0;
             c.beams = 256;
             c.horizontal_beamwidth_deg = 0.5;
             c.sidelobe_kernel_beamwidths = 0.5;
             c.far_sidelobe_cell = 0.2;
         }},
        // beam_focus none: every bin reads its focus band's weights (a lane at a time on the GPU, the loop
        // over beams on the CPU, the AVX2 groups over each band's own columns), 40 bands over 0.5-8 m.
        {"focus bands (an unfocused array)",
         [](SonarConfig& c) {
             c.beam_focus = BeamFocus::none;
             c.range_max_m = 8.0;
         }},
        {"the pattern forced on with no kernel (the tent's weights)",
         [](SonarConfig& c) {
             c.beams = 65;
             c.sidelobe_kernel_beamwidths = 0.1;
             c.effects.horizontal_pattern = EffectMode::on;
         }},
    };
    const SceneCase scene = bundled_scenes().front();
    for (const auto& [what, change] : parts) {
        SonarConfig config = quiet_config();
        change(config);
        auto p = render_pair(scene.file, config, scene.pose, kSaveAll);
        ASSERT_TRUE(p) << what;
        if (std::strstr(what, "256 cells") != nullptr) {
            EXPECT_EQ(renderer_plan(p->gpu->renderer).far_cells, shared::kMaxFarCells);
        }
        if (std::strstr(what, "focus") != nullptr) {
            EXPECT_GT(renderer_plan(p->gpu->renderer).near_bands, 10u);
        }
        expect_beamform_agrees(beamform_errors(p->gpu->frame, renderer_plan(p->gpu->renderer), what), what);
    }
}

INSTANTIATE_TEST_SUITE_P(BundledScenes, BeamformGpuCpu, ::testing::ValuesIn(bundled_scenes()), scene_name);

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
        auto plan = make_plan(config, scene_data(scene.value()));
        ASSERT_TRUE(plan) << plan.error().message;
        // Else the renders below would compare the gather with itself.
        EXPECT_TRUE(vk::resample_can_walk(plan.value(), kBeamsPerInvocation));
        auto walked = render_once(Backend::vulkan, config, scene.value(), pose, SaveFlags::profiles);
        RendererOptions gather;
        gather.resample = ResampleMethod::gather;
        auto gathered = render_once(Backend::vulkan, config, scene.value(), pose, SaveFlags::profiles, 1, gather);
        ASSERT_TRUE(walked && gathered);
        EXPECT_EQ(walked->frame.beam_profiles, gathered->frame.beam_profiles);
        EXPECT_EQ(walked->frame.clean, gathered->frame.clean);
        const auto lit = std::count_if(walked->frame.beam_profiles.begin(), walked->frame.beam_profiles.end(),
                                       [](float v) { return v > 0.0f; });
        EXPECT_GT(lit, 1000); // the scene is in view: equal frames are not two empty ones
    }
}

// A frame in the CPU-device layout and in the GPU layout: the same bits, and not two empty frames. Returns
// the CPU-device layout's (null where a render failed).
std::unique_ptr<testing::Rendered> expect_layouts_agree(const SonarConfig& config, const Scene& scene,
                                                        const Pose& pose) {
    RendererOptions columns, lanes;
    columns.layout = WorkLayout::cpu_device;
    lanes.layout = WorkLayout::gpu;
    auto a = render_once(Backend::vulkan, config, scene, pose, SaveFlags::profiles, 1, columns);
    auto b = render_once(Backend::vulkan, config, scene, pose, SaveFlags::profiles, 1, lanes);
    if (!a || !b) {
        ADD_FAILURE() << "a render failed";
        return nullptr;
    }
    EXPECT_EQ(a->frame.profiles, b->frame.profiles);
    EXPECT_EQ(a->frame.clean, b->frame.clean);
    const auto lit =
        std::count_if(a->frame.profiles.begin(), a->frame.profiles.end(), [](float v) { return v > 0.0f; });
    EXPECT_GT(lit, 1000); // equal frames are not two empty ones
    return a;
}

// The beamform passes' two layouts (RendererOptions::layout): for a CPU device one invocation per
// column walking all its bins and 16 beams per resample/sidelobe invocation (lavapipe), for a GPU 32
// per column, each adding to every 32nd bin, and 4 beams (kGpuDeviceShape). Each output keeps one
// writer and the order of its additions, so the frames are the same bits; on lavapipe both run here.
// Planar columns and the line array's cone gather with its tier views (in the GPU layout both take a
// block of 32 rows at once, profile.comp column_block_rows and gather_block_rows, over 164 rows: the
// blocks hand on their first columns and the last one is short), the tent kernel (two bins a pixel: lanes meet at a
// pixel's edge bins), and 6 pixel columns a beam, where a row gives a cone column more pixels than the block's lists
// hold (the GPU layout then walks the rows one by one).
TEST(WorkLayout, GpuLayoutGivesTheSameBitsAsCpuDeviceLayout) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard validation;
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/harbour.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    struct Case {
        BeamGeometry geometry;
        RangeKernel kernel;
        double pixels_per_beam;
    };
    const Case cases[] = {{BeamGeometry::line_array, RangeKernel::footprint, 2.0},
                          {BeamGeometry::planar, RangeKernel::footprint, 2.0},
                          {BeamGeometry::line_array, RangeKernel::tent, 2.0},
                          {BeamGeometry::line_array, RangeKernel::footprint, 6.0}};
    for (const auto& [geometry, kernel, pixels_per_beam] : cases) {
        SCOPED_TRACE(std::string(geometry == BeamGeometry::planar ? "planar" : "line array") +
                     (kernel == RangeKernel::tent ? ", tent" : ", footprint") + ", " + std::to_string(pixels_per_beam) +
                     " pixels a beam");
        SonarConfig config = quiet_config();
        config.beam_geometry = geometry;
        config.range_kernel = kernel;
        config.pixels_per_beam = pixels_per_beam;
        Pose pose;
        pose.pitch_deg = 10.0;
        expect_layouts_agree(config, scene.value(), pose);
    }
}

// Lavapipe ends an invocation's loops after 65535 iterations in all; one profile.comp invocation walking
// every row of its cone columns at `--quality accurate` (298 rows, 11 slices and 12 tier views) came to
// about 80k, and the rows past the limit were never added: the CPU-device layout left 4293 scan cells
// off the GPU layout's, beams near broadside up to 99 % short in the nadir rows. The host now walks the
// rows in bands (src/vk/profile_bands.h), each within half the limit by its estimate, and the two
// layouts give the same bits again. Also: every band follows the one before, and the estimate of a
// band stays within the budget unless it is one row.
TEST(WorkLayout, RowBandsKeepAnAccurateFrameWhole) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard validation;
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    auto accurate = apply_quality(quiet_config(), "accurate");
    ASSERT_TRUE(accurate) << accurate.error().message;
    const SonarConfig config = accurate.value();
    auto plan = make_plan(config, scene_data(scene.value()));
    ASSERT_TRUE(plan) << plan.error().message;
    ASSERT_TRUE(plan->line_array);
    ASSERT_GT(plan->views, plan->slices) << "the tier views make the long walks";
    // Every band follows the one before, and its estimate stays within the budget unless it is one row.
    auto bands_of = [](const Plan& q, const char* name) {
        const auto bands = vk::profile_row_bands(q, kCpuDeviceShape, false);
        EXPECT_FALSE(bands.empty());
        EXPECT_EQ(bands.front().row_begin, 0u);
        EXPECT_EQ(bands.back().row_end, q.rows);
        for (std::size_t i = 0; i < bands.size(); ++i) {
            EXPECT_LT(bands[i].row_begin, bands[i].row_end);
            if (i > 0) {
                EXPECT_EQ(bands[i].row_begin, bands[i - 1].row_end);
            }
            double cost = 0.0;
            for (std::uint32_t row = bands[i].row_begin; row < bands[i].row_end; ++row)
                cost += vk::profile_row_cost(q, kCpuDeviceShape, row);
            if (bands[i].row_end - bands[i].row_begin > 1) {
                EXPECT_LE(cost, vk::kProfileBandBudget) << name;
            }
        }
        EXPECT_EQ(vk::profile_row_bands(q, kCpuDeviceShape, true).size(), 1u); // blocks of rows: one band
        std::printf("[row bands] %s: %u rows in %zu bands\n", name, q.rows, bands.size());
        return bands.size();
    };
    auto balanced = make_plan(quiet_config(), scene_data(scene.value()));
    ASSERT_TRUE(balanced) << balanced.error().message;
    bands_of(balanced.value(), "balanced");
    EXPECT_GT(bands_of(plan.value(), "accurate"), 2u) << "accurate needs several bands, else this tests nothing";
    Pose pose;
    pose.z_m = -2.0;
    pose.pitch_deg = 15.0;
    const auto a = expect_layouts_agree(config, scene.value(), pose);
    ASSERT_TRUE(a);
    // Every row in one dispatch (as before the bands): on lavapipe the loops run out, which profile.comp
    // reports and render() turns into an error, not a frame; a device without the limit renders it whole.
    RendererOptions whole;
    whole.layout = WorkLayout::cpu_device;
    whole.profile_rows = ProfileRows::whole;
    whole.backend = Backend::vulkan;
    auto renderer = Renderer::create(*testing::vulkan_context(), config, scene.value(), whole);
    ASSERT_TRUE(renderer) << renderer.error().message;
    Frame frame = renderer->make_frame();
    auto c = renderer->render(pose, 0, frame);
    if (testing::vulkan_device_is_cpu()) {
        ASSERT_FALSE(c) << "lavapipe let 80k loop iterations run in one invocation";
        EXPECT_EQ(c.error().code, ErrorCode::unsupported);
        EXPECT_NE(c.error().message.find("65535"), std::string::npos) << c.error().message;
        std::printf("[row bands] every row in one dispatch: %s\n", c.error().message.c_str());
    } else {
        ASSERT_TRUE(c) << c.error().message;
        EXPECT_EQ(frame.clean, a->frame.clean);
    }
}

// The bands' estimate takes a pixel's range footprint as a length, not a count of bins: 8192 bins over a
// 20 m window (2.4 mm) put 80 and more bins under a seabed pixel seen at 10 to 20 deg grazing, where the
// estimate's fixed 6 bins let every frame run out of lavapipe's loops (render() refused each one). Now both
// layouts render it, the same bits, in several bands; the default's bands are as they were (6 bins).
TEST(WorkLayout, RowBandsFollowTheFootprintsLengthNotItsBins) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard validation;
    Scene scene; // a flat seabed 3 m below the sonar
    const float seabed[] = {-50, -50, -3, 50, -50, -3, 50, 50, -3, -50, 50, -3};
    const std::uint32_t triangles[] = {0, 1, 2, 0, 2, 3};
    auto mesh = scene.add_mesh(seabed, 4, triangles, 6);
    ASSERT_TRUE(mesh) << mesh.error().message;
    SceneDraw draw;
    draw.mesh = mesh.value();
    ASSERT_TRUE(scene.add_draw(draw));
    SonarConfig config = quiet_config();
    config.beams = 128;
    config.bins = 8192;
    config.range_max_m = 20.0;
    auto plan = make_plan(config, scene_data(scene));
    ASSERT_TRUE(plan) << plan.error().message;
    const auto bands = vk::profile_row_bands(plan.value(), kCpuDeviceShape, false).size();
    std::printf("[row bands] 8192 bins over 20 m: %u rows in %zu bands\n", plan->rows, bands);
    EXPECT_GT(bands, 2u);
    // the default's bins (7.7 cm) keep the estimate's 6 bins a pixel, and so their bands
    auto default_plan = make_plan(quiet_config(), scene_data(scene));
    ASSERT_TRUE(default_plan) << default_plan.error().message;
    EXPECT_LE(vk::kProfileFootprintM / default_plan->bin_width_m, vk::kProfileFootprintBins);
    Pose pose;
    pose.pitch_deg = 10.0;
    expect_layouts_agree(config, scene, pose);
    // Pixels 2.8 deg wide (accuracy.pixels_per_beam 0.09) on the bundled scene: their footprints span their
    // width in range across the row, which the larger pixel side now sizes (with 6 bins the frame was refused).
    auto bundled = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(bundled) << bundled.error().message;
    SonarConfig wide = quiet_config();
    wide.pixels_per_beam = 0.09;
    RendererOptions columns;
    columns.layout = WorkLayout::cpu_device;
    auto rendered = render_once(Backend::vulkan, wide, bundled.value(), pose, SaveFlags::none, 1, columns);
    EXPECT_TRUE(rendered) << "pixels_per_beam 0.09 refused";
}

// Where the walk would add different terms, the host keeps the gather: a full circle (beams 0 and
// beams-1 gather from every column), and a span that holds a column giving its beam nothing.
TEST(ResampleWalk, RefusedWhereTheTermsWouldDiffer) {
    Scene scene;
    SonarConfig config = quiet_config();
    auto fan = make_plan(config, scene_data(scene));
    ASSERT_TRUE(fan) << fan.error().message;
    ASSERT_TRUE(vk::resample_can_walk(fan.value(), kBeamsPerInvocation));
    config.hfov_deg = 360.0;
    auto circle = make_plan(config, scene_data(scene));
    ASSERT_TRUE(circle) << circle.error().message;
    EXPECT_FALSE(vk::resample_can_walk(circle.value(), kBeamsPerInvocation));
    // Beam 40's span reaches back over beam 38's columns, which give beam 40 nothing.
    Plan widened = fan.value();
    widened.beam_column_begin[40] = widened.beam_column_begin[39];
    EXPECT_FALSE(vk::resample_can_walk(widened, kBeamsPerInvocation));
}

} // namespace
} // namespace vksonar
