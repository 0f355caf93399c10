// The grain of speckle and ambient noise across beams (beam_correlation pattern; src/core/plan_grain.cpp, the
// noise stage's grain_draws). Two beams that overlap hear much the same scatterers and element noise: for
// complex normal fields their intensity correlation is |rho|^2, rho the normalized transform of the
// aperture's |w|^2 at their separation. The references are that closed form (sinc^2 for an unshaded
// aperture) or Simpson's rule over the aperture (hann), with the pattern constant from the test's own
// bisection of the -3 dB point: none of it from the code under test.
//
// Tolerances: the plan truncates each beam's filter after two side lobes, which moves an unshaded array's
// correlation by up to 0.04 at some lag and grid phase (1e-4 with hann shading; the reviewer's and the
// author's Python models of the truncation agree); the estimate over N = bins x frames samples of an
// exponential pair has a standard error near 1.5 / sqrt(N), 0.006 at 65536 samples, and each check
// averages twelve pairs. 0.05 (sinc) and 0.01 (hann, gaussian) hold both; drawing every cell on its own
// (the grain ignored) misses by 0.85 and 0.5 at lags 1 and 2, a filter by the power pattern instead of the
// amplitude misses hann's by 0.18, and one without the amplitude's sign misses sinc's lag 4 by 0.25.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include "core/plan.h"
#include "host/host_stages.h"
#include "host/meta_fields.h"
#include "host/rng.h"
#include "host/workers.h"
#include "scene/scene_data.h"
#include "test_support.h"

using namespace vksonar;

namespace {

constexpr double kDeg = kPi / 180.0;
constexpr std::uint32_t kFrames = 16;

Plan grain_plan(const SonarConfig& config) {
    auto plan = make_plan(config, SceneData{});
    EXPECT_TRUE(plan) << plan.error().message;
    return plan ? std::move(plan.value()) : Plan{};
}

SonarConfig grain_config() {
    SonarConfig c = vksonar::testing::quiet_config();
    c.bins = 4096; // samples per frame for the statistics
    c.effects.speckle = EffectMode::on;
    c.effects.ambient_noise = EffectMode::on;
    return c;
}

// grain_config's fan with another pattern, geometry, width, beamwidth and beam count.
SonarConfig fan_config(BeamPattern pattern, BeamGeometry geometry, double hfov_deg, double beamwidth_deg,
                       std::uint32_t beams) {
    SonarConfig c = grain_config();
    c.horizontal_pattern = pattern;
    c.beam_geometry = geometry;
    c.hfov_deg = hfov_deg;
    c.horizontal_beamwidth_deg = beamwidth_deg;
    c.beams = beams;
    return c;
}

// The draws of frames 0 .. kFrames - 1 as the renderer makes them (noise_draws), frame after frame: speckle and
// ambient noise, bins * beams each.
struct Draws {
    std::vector<float> speckle, noise;
};
Draws draws_of(const Plan& p) {
    const std::size_t cells = std::size_t(p.bins) * p.beams;
    Draws d;
    d.speckle.resize(cells * kFrames);
    d.noise.resize(cells * kFrames);
    host::Workers workers(2);
    for (std::uint32_t f = 0; f < kFrames; ++f)
        host::noise_draws(p, 7, f, {d.speckle.data() + f * cells, d.noise.data() + f * cells}, &workers);
    return d;
}

// Pearson's correlation of beam a of one field and beam b of another over every bin of every frame.
double correlation(const Plan& p, const std::vector<float>& field_a, std::uint32_t a, const std::vector<float>& field_b,
                   std::uint32_t b) {
    const std::size_t rows = field_a.size() / p.beams;
    double sa = 0, sb = 0, saa = 0, sbb = 0, sab = 0;
    for (std::size_t r = 0; r < rows; ++r) {
        const double x = field_a[r * p.beams + a], y = field_b[r * p.beams + b];
        sa += x;
        sb += y;
        saa += x * x;
        sbb += y * y;
        sab += x * y;
    }
    const double n = double(rows);
    const double cov = sab / n - sa / n * (sb / n);
    return cov / std::sqrt((saa / n - sa / n * (sa / n)) * (sbb / n - sb / n * (sb / n)));
}
double correlation(const Plan& p, const std::vector<float>& field, std::uint32_t a, std::uint32_t b) {
    return correlation(p, field, a, field, b);
}

// x where a power pattern falls to one half, by bisection on [lo, hi] (power falling there).
template <class F> double half_power_x(F&& power, double lo, double hi) {
    for (int i = 0; i < 200; ++i) {
        const double mid = 0.5 * (lo + hi);
        (power(mid) > 0.5 ? lo : hi) = mid;
    }
    return 0.5 * (lo + hi);
}

// The normalized transform of an aperture weighting's square, rho(x) = int w^2 cos(x s) ds / int w^2 over
// s in [-1, 1] (Simpson, 2000 panels), and its power pattern |int w cos(x s) ds / int w|^2 for the bisection.
template <class W> double aperture_integral(W&& w, double x, int power_of_w) {
    constexpr int n = 2000;
    double sum = 0;
    for (int i = 0; i <= n; ++i) {
        const double s = -1.0 + 2.0 * i / n;
        const double f = std::pow(w(s), power_of_w) * std::cos(x * s);
        sum += f * (i == 0 || i == n ? 1.0 : (i % 2 ? 4.0 : 2.0));
    }
    return sum * (2.0 / n) / 3.0;
}

// How a pattern correlates two beams: the intensity correlation at a separation in x = k u units.
struct Aperture {
    const char* name;
    double (*weight)(double s);
};
double uniform_weight(double) {
    return 1.0;
}
double hann_weight(double s) {
    return 1.0 + std::cos(kPi * s);
}

double expected_correlation(const Aperture& a, double x) {
    const double rho = aperture_integral(a.weight, x, 2) / aperture_integral(a.weight, 0.0, 2);
    return rho * rho;
}
// The pattern constant k = x3 / sin(bw / 2) of an aperture (the plan's definition of the beamwidth).
double pattern_k(const Aperture& a, double beamwidth_rad) {
    const double norm = aperture_integral(a.weight, 0.0, 1);
    const double x3 = half_power_x(
        [&](double x) {
            const double amp = aperture_integral(a.weight, x, 1) / norm;
            return amp * amp;
        },
        0.0, 3.0);
    return x3 / std::sin(0.5 * beamwidth_rad);
}

// The mean correlation of beam pairs (j, j + lag), j from `from` on, `pairs` of them, against each pair's own
// expectation `expected(theta_1, theta_2)`.
struct LagCheck {
    double measured = 0, expected = 0;
};
template <class Expected>
LagCheck check_lag(const Plan& p, const std::vector<float>& draws, Expected&& expected, std::uint32_t from,
                   std::uint32_t lag, std::uint32_t pairs) {
    LagCheck out;
    for (std::uint32_t j = from; j < from + pairs; ++j) {
        out.measured += correlation(p, draws, j, j + lag) / pairs;
        out.expected += expected(p.beam_angle_rad[j], p.beam_angle_rad[j + lag]) / pairs;
    }
    return out;
}

} // namespace

TEST(Grain, NeighbouringBeamsCorrelateAsTheirAperturesOverlap) {
    const Aperture uniform{"unshaded", uniform_weight}, hann{"hann", hann_weight};
    const double bw = 1.0 * kDeg;
    const double k_sinc = pattern_k(uniform, bw), k_hann = pattern_k(hann, bw);
    // a line array's patterns are functions of the sines' difference, a planar fan's of the difference's sine
    const auto in_sine = [](const Aperture& a, double k) {
        return [&a, k](double t1, double t2) { return expected_correlation(a, k * (std::sin(t1) - std::sin(t2))); };
    };
    const auto planar = [](const Aperture& a, double k) {
        return [&a, k](double t1, double t2) { return expected_correlation(a, k * std::sin(t1 - t2)); };
    };
    // a gaussian power pattern exp(-k a^2) (-3 dB at bw / 2) filters with exp(-k a^2 / 2): the fields' correlation
    // exp(-k d^2 / 4), the intensities' its square
    const double k_gauss = std::log(2.0) / (0.25 * bw * bw);
    const auto gaussian = [k_gauss](double t1, double t2) { return std::exp(-0.5 * k_gauss * (t1 - t2) * (t1 - t2)); };
    struct Case {
        const char* name;
        BeamPattern pattern;
        BeamGeometry geometry;
        BeamSpacing spacing;
        double hfov_deg;
        std::uint32_t beams;
        std::function<double(double, double)> expected;
        double tolerance;
    };
    const Case cases[] = {
        {"line array, sinc (the default)", BeamPattern::sinc, BeamGeometry::line_array, BeamSpacing::equiangular, 130.0,
         512, in_sine(uniform, k_sinc), 0.05},
        {"line array, sinc, equal steps in sine", BeamPattern::sinc, BeamGeometry::line_array, BeamSpacing::equisine,
         130.0, 512, in_sine(uniform, k_sinc), 0.05},
        {"line array, hann", BeamPattern::hann, BeamGeometry::line_array, BeamSpacing::equiangular, 130.0, 512,
         in_sine(hann, k_hann), 0.01},
        {"planar, sinc", BeamPattern::sinc, BeamGeometry::planar, BeamSpacing::equiangular, 90.0, 256,
         planar(uniform, k_sinc), 0.05},
        {"planar, hann", BeamPattern::hann, BeamGeometry::planar, BeamSpacing::equiangular, 90.0, 256,
         planar(hann, k_hann), 0.01},
        {"planar, gaussian", BeamPattern::gaussian, BeamGeometry::planar, BeamSpacing::equiangular, 90.0, 256, gaussian,
         0.01},
    };
    for (const Case& kase : cases) {
        SCOPED_TRACE(kase.name);
        SonarConfig c = fan_config(kase.pattern, kase.geometry, kase.hfov_deg, bw / kDeg, kase.beams);
        c.beam_spacing = kase.spacing;
        const Plan p = grain_plan(c);
        ASSERT_GT(p.grain.taps, 0u) << p.grain.why;
        ASSERT_EQ(p.line_array, kase.geometry == BeamGeometry::line_array);
        const Draws d = draws_of(p);
        // near broadside, and (line array) near 55 deg, where a beam is 1.7 times wider in angle
        std::vector<std::uint32_t> starts{p.beams / 2 - 10};
        if (p.line_array) starts.push_back(std::uint32_t(p.beams * 0.08));
        for (const std::uint32_t from : starts) {
            for (const std::uint32_t lag : {1u, 2u, 4u, 8u}) {
                for (const std::vector<float>* field : {&d.speckle, &d.noise}) {
                    const LagCheck got = check_lag(p, *field, kase.expected, from, lag, 12);
                    EXPECT_NEAR(got.measured, got.expected, kase.tolerance)
                        << "beams from " << from << " (" << p.beam_angle_rad[from] / kDeg << " deg), lag " << lag
                        << (field == &d.speckle ? ", speckle" : ", noise");
                }
            }
        }
        // speckle and noise are drawn apart: uncorrelated, cell by cell
        double cross = 0;
        for (std::uint32_t j = p.beams / 2 - 10; j < p.beams / 2 + 10; ++j)
            cross += correlation(p, d.speckle, j, d.noise, j) / 20;
        EXPECT_NEAR(cross, 0.0, 0.01);
    }
}

TEST(Grain, NoneDrawsEveryCellOnItsOwn) {
    SonarConfig c = grain_config();
    c.beam_correlation = BeamCorrelation::none;
    const Plan p = grain_plan(c);
    EXPECT_EQ(p.grain.taps, 0u);
    EXPECT_NE(p.grain.why.find("beam_correlation none"), std::string::npos) << p.grain.why;
    const Draws d = draws_of(p);
    for (std::uint32_t j = p.beams / 2 - 10; j < p.beams / 2 + 10; ++j)
        EXPECT_NEAR(correlation(p, d.speckle, j, j + 1), 0.0, 0.03) << "beam " << j;
}

// Each beam's weights have unit sum of squares and its points are unit-power complex normals, so every cell is
// Exp(1): mean 1 and variance 1, P(> 3) = e^-3, at broadside and at the fan's edges (where a beam's taps reach
// past the others' and the normalization differs).
TEST(Grain, EachCellStaysExponential) {
    SonarConfig c = grain_config();
    const Plan p = grain_plan(c);
    ASSERT_GT(p.grain.taps, 0u) << p.grain.why;
    const Draws d = draws_of(p);
    for (const std::uint32_t j : {0u, 1u, p.beams / 2, p.beams - 1}) {
        for (const std::vector<float>* field : {&d.speckle, &d.noise}) {
            const std::size_t rows = field->size() / p.beams;
            double sum = 0, sum_squares = 0, above = 0;
            for (std::size_t r = 0; r < rows; ++r) {
                const double v = (*field)[r * p.beams + j];
                sum += v;
                sum_squares += v * v;
                above += v > 3.0 ? 1.0 : 0.0;
            }
            const double n = double(rows), mean = sum / n, var = sum_squares / n - mean * mean;
            // 5 standard errors (the rows are independent: bins and frames are drawn apart)
            EXPECT_NEAR(mean, 1.0, 5.0 / std::sqrt(n)) << "beam " << j;
            EXPECT_NEAR(var, 1.0, 5.0 * std::sqrt(8.0 / n))
                << "beam " << j; // the sample variance's SE: sqrt((mu4 - 1) / n), mu4 = 9 for Exp(1)
            const double tail = std::exp(-3.0);
            EXPECT_NEAR(above / n, tail, 5.0 * std::sqrt(tail * (1 - tail) / n)) << "beam " << j;
        }
    }
}

// Patterns that end abruptly: a box (amplitude 1 within its half width) and beams so wide that a planar fan's
// baffle cuts them at 90 deg. Their fields are integrals of white noise over the cut pattern, so two beams
// correlate as rho(d) = int a(v) a(v - d) dv / int a^2 over the support (Simpson in the test: for the box a
// triangle, 1 - |d| / (2 h)). Every neighbouring pair is checked, not a mean: a grid that ignored the cut
// gave identical draws to neighbours under a box and dips to 0.45 where a grid point crossed the baffle.
TEST(Grain, PatternsThatEndAbruptlyCorrelateSmoothly) {
    struct Case {
        const char* name;
        BeamPattern pattern;
        double hfov_deg, beamwidth_deg;
        std::uint32_t beams;
    };
    const Case cases[] = {
        {"planar, 3 deg box beams", BeamPattern::box, 130, 3, 512},
        {"circle, 120 deg sinc beams", BeamPattern::sinc, 360, 120, 128},
        {"circle, 170 deg sinc beams", BeamPattern::sinc, 360, 170, 128},
    };
    const Aperture uniform{"unshaded", uniform_weight};
    for (const Case& kase : cases) {
        SCOPED_TRACE(kase.name);
        const SonarConfig c =
            fan_config(kase.pattern, BeamGeometry::planar, kase.hfov_deg, kase.beamwidth_deg, kase.beams);
        const Plan p = grain_plan(c);
        ASSERT_GT(p.grain.taps, 0u) << p.grain.why;
        const double bw = kase.beamwidth_deg * kDeg;
        const double k = kase.pattern == BeamPattern::sinc ? pattern_k(uniform, bw) : 0.0;
        const double support = kase.pattern == BeamPattern::box ? 0.5 * bw : 0.5 * kPi;
        const auto amplitude = [&](double v) {
            if (std::abs(v) > support) return 0.0;
            if (kase.pattern == BeamPattern::box) return 1.0;
            const double x = k * std::sin(v);
            return x == 0.0 ? 1.0 : std::sin(x) / x;
        };
        const auto rho = [&](double d) { // Simpson over the support, 4000 panels
            constexpr int n = 4000;
            double overlap = 0, norm = 0;
            for (int i = 0; i <= n; ++i) {
                const double v = -support + 2.0 * support * i / n;
                const double weight = i == 0 || i == n ? 1.0 : (i % 2 ? 4.0 : 2.0);
                overlap += weight * amplitude(v) * amplitude(v - d);
                norm += weight * amplitude(v) * amplitude(v);
            }
            return overlap / norm;
        };
        const Draws d = draws_of(p);
        double worst = 0;
        std::uint32_t worst_beam = 0;
        for (std::uint32_t j = 0; j + 1 < p.beams; ++j) {
            const double r = rho(p.beam_angle_rad[j] - p.beam_angle_rad[j + 1]);
            const double error = std::abs(correlation(p, d.speckle, j, j + 1) - r * r);
            if (error > worst) worst = error, worst_beam = j;
        }
        // the cut cells' weights approximate the integral to a few per cent; sampling error 0.006 a pair
        EXPECT_LT(worst, 0.05) << "beams " << worst_beam << " and " << worst_beam + 1;
    }
}

// Every beam's draws have mean 1 whatever the pattern and the fan: the weights' unit sum of squares, with no
// point counted twice. Box, gaussian and chebyshev patterns, equal steps in sine, beams so narrow that the
// points fill several chunks, and full circles with beams so wide that a reach past the baffle would take a
// point into a beam twice (a 150 deg gaussian beam's draws had mean 1.2 that way).
TEST(Grain, EveryBeamsDrawsHaveMeanOne) {
    struct Case {
        const char* name;
        BeamPattern pattern;
        BeamGeometry geometry;
        double hfov_deg, beamwidth_deg, sidelobe_db;
        std::uint32_t beams;
        bool several_chunks;
    };
    const Case cases[] = {
        {"line array, chebyshev -10 dB", BeamPattern::chebyshev, BeamGeometry::line_array, 130, 1, -10, 512, true},
        {"line array, chebyshev -100 dB", BeamPattern::chebyshev, BeamGeometry::line_array, 130, 1, -100, 512, true},
        {"planar, box", BeamPattern::box, BeamGeometry::planar, 90, 1, -30, 256, false},
        {"planar, 0.05 deg sinc beams", BeamPattern::sinc, BeamGeometry::planar, 15, 0.05, -30, 300, true},
        {"circle, 150 deg gaussian beams", BeamPattern::gaussian, BeamGeometry::planar, 360, 150, -30, 64, false},
        {"circle, 170 deg box beams", BeamPattern::box, BeamGeometry::planar, 360, 170, -30, 64, false},
        {"circle, 40 deg sinc beams", BeamPattern::sinc, BeamGeometry::planar, 360, 40, -30, 128, false},
    };
    for (const Case& kase : cases) {
        SCOPED_TRACE(kase.name);
        SonarConfig c = fan_config(kase.pattern, kase.geometry, kase.hfov_deg, kase.beamwidth_deg, kase.beams);
        c.bins = 1024;
        c.horizontal_sidelobe_db = kase.sidelobe_db;
        const Plan p = grain_plan(c);
        ASSERT_GT(p.grain.taps, 0u) << p.grain.why;
        if (kase.several_chunks) {
            EXPECT_GT(p.grain.chunk.size(), 2u);
        }
        const Draws d = draws_of(p);
        const double n = double(d.speckle.size() / p.beams);
        for (const std::vector<float>* field : {&d.speckle, &d.noise}) {
            double worst = 0;
            std::uint32_t worst_beam = 0;
            for (std::uint32_t j = 0; j < p.beams; ++j) {
                double sum = 0;
                for (std::size_t r = 0; r < field->size() / p.beams; ++r)
                    sum += (*field)[r * p.beams + j];
                if (std::abs(sum / n - 1.0) > worst) worst = std::abs(sum / n - 1.0), worst_beam = j;
            }
            // Exp(1) over n samples: SE 1 / sqrt(n) = 0.008; 5 SE over the beams
            EXPECT_LT(worst, 5.0 / std::sqrt(n))
                << "beam " << worst_beam << (field == &d.speckle ? ", speckle" : ", noise");
        }
    }
}

// A full circle (planar, 360 deg): the first and the last beam are neighbours across the seam and correlate as
// any two neighbours do.
TEST(Grain, AFullCircleWrapsAtTheSeam) {
    const SonarConfig c = fan_config(BeamPattern::sinc, BeamGeometry::planar, 360.0, 1.5, 720);
    const Plan p = grain_plan(c);
    ASSERT_TRUE(p.circular);
    ASSERT_GT(p.grain.taps, 0u) << p.grain.why;
    const Draws d = draws_of(p);
    const double k = pattern_k({"unshaded", uniform_weight}, c.horizontal_beamwidth_deg * kDeg);
    const double expected = expected_correlation({"unshaded", uniform_weight}, k * std::sin(0.5 * kDeg));
    double seam = correlation(p, d.speckle, p.beams - 1, 0), inside = 0;
    for (std::uint32_t j = 300; j < 310; ++j)
        inside += correlation(p, d.speckle, j, j + 1) / 10;
    EXPECT_NEAR(inside, expected, 0.05);
    EXPECT_NEAR(seam, expected, 0.05);
    EXPECT_GT(expected, 0.5); // a half-degree step under a 1.5 deg beam: the check has something to find
}

// The renderer makes the draws ahead of the stage (noise_draws) or the stage makes its own: the same bytes with
// the grain, on one thread or three, with either draw alone, with gamma speckle of 2.5 looks (per cell) beside
// grained noise and with grained gamma speckle of 3 looks, on a full circle whose points fill several chunks.
TEST(Grain, DrawsMadeAheadEqualTheStagesOwn) {
    SonarConfig c = grain_config();
    c.bins = 200;
    c.hfov_deg = 360.0;
    c.beams = 1210; // chunks of 256 and a last one of 186 beams: a partial block of 16
    c.horizontal_beamwidth_deg = 0.2;
    const Plan planned = grain_plan(c);
    ASSERT_GT(planned.grain.taps, 0u) << planned.grain.why;
    ASSERT_GT(planned.grain.chunk.size(), 3u);
    struct Case {
        bool speckle, ambient_noise;
        SpeckleModel model;
        double looks;
    };
    for (const Case& kase : {Case{true, true, SpeckleModel::rayleigh, 1}, Case{false, true, SpeckleModel::rayleigh, 1},
                             Case{true, false, SpeckleModel::rayleigh, 1}, Case{true, true, SpeckleModel::gamma, 2.5},
                             Case{true, true, SpeckleModel::gamma, 3}, Case{true, false, SpeckleModel::gamma, 3}}) {
        SCOPED_TRACE(std::string("speckle ") + (kase.speckle ? "on" : "off") + ", noise " +
                     (kase.ambient_noise ? "on" : "off") +
                     (kase.model == SpeckleModel::gamma ? ", gamma " + std::to_string(kase.looks) : ""));
        Plan p = planned;
        p.effects.speckle = kase.speckle;
        p.effects.ambient_noise = kase.ambient_noise;
        p.config.speckle = kase.model;
        p.config.speckle_looks = kase.looks;
        ASSERT_TRUE(host::noise_draws_ahead(p));
        Frame here = vksonar::testing::host_stage_frame(p);
        const std::size_t cells = std::size_t(p.beams) * p.bins;
        here.clean.assign(cells, 1e-12f);
        Frame ahead = here;
        host::noise_and_gain(p, 3, 9, here);
        for (std::uint32_t threads : {1u, 3u}) {
            host::Workers workers(threads);
            std::vector<float> speckle(cells), noise(cells);
            const host::NoiseDraws draws{speckle.data(), noise.data()};
            host::noise_draws(p, 3, 9, draws, &workers);
            host::noise_and_gain(p, 3, 9, ahead, &workers, nullptr, &draws);
            EXPECT_EQ(std::memcmp(ahead.intensity.data(), here.intensity.data(), cells * sizeof(float)), 0) << threads;
        }
    }
}

// Gamma speckle of L looks (L a whole number, at most 16) is the mean of L independent grained fields' draws:
// Gamma(L, 1/L) in every cell (mean 1, variance 1 / L, P(> x) = e^(-L x) sum_{k < L} (L x)^k / k!), and two
// beams correlate as one look's do (the mean of L independent pairs keeps the pair's correlation): sinc^2 of
// the sines' difference for the default line array, the same closed form and tolerance as above. One look is
// Rayleigh speckle's draws exactly, and a look count the grain cannot average (2.5) is drawn per cell as with
// beam_correlation none, the same bytes.
TEST(Grain, GammaSpeckleAveragesWholeLooksOfTheGrain) {
    SonarConfig c = grain_config();
    c.speckle = SpeckleModel::gamma;
    c.speckle_looks = 3;
    const Plan p = grain_plan(c);
    ASSERT_GT(p.grain.taps, 0u) << p.grain.why;
    ASSERT_EQ(host::row_draws_of(p).speckle_looks, 3u);
    const Draws d = draws_of(p);
    const double looks = 3, x = 2.0;
    const double tail = std::exp(-looks * x) * (1.0 + looks * x + 0.5 * (looks * x) * (looks * x));
    const double mu4 = 3.0 * (looks + 2.0) / (looks * looks * looks); // Gamma(L, 1/L)'s fourth central moment
    for (const std::uint32_t j : {0u, p.beams / 2, p.beams - 1}) {
        const std::size_t rows = d.speckle.size() / p.beams;
        double sum = 0, sum_squares = 0, above = 0;
        for (std::size_t r = 0; r < rows; ++r) {
            const double v = d.speckle[r * p.beams + j];
            sum += v;
            sum_squares += v * v;
            above += v > x ? 1.0 : 0.0;
        }
        const double n = double(rows), mean = sum / n, var = sum_squares / n - mean * mean;
        EXPECT_NEAR(mean, 1.0, 5.0 * std::sqrt(1.0 / looks / n)) << "beam " << j;
        EXPECT_NEAR(var, 1.0 / looks, 5.0 * std::sqrt((mu4 - 1.0 / (looks * looks)) / n)) << "beam " << j;
        EXPECT_NEAR(above / n, tail, 5.0 * std::sqrt(tail * (1 - tail) / n)) << "beam " << j;
    }
    const Aperture uniform{"unshaded", uniform_weight};
    const double k = pattern_k(uniform, c.horizontal_beamwidth_deg * kDeg);
    const auto expected = [&](double t1, double t2) {
        return expected_correlation(uniform, k * (std::sin(t1) - std::sin(t2)));
    };
    for (const std::uint32_t lag : {1u, 2u, 4u}) {
        const LagCheck got = check_lag(p, d.speckle, expected, p.beams / 2 - 10, lag, 12);
        EXPECT_NEAR(got.measured, got.expected, 0.05) << "lag " << lag;
    }
    // the looks are drawn apart from the ambient noise's field: uncorrelated, cell by cell (a look drawn from
    // the noise's streams would correlate about 1 / sqrt(3) = 0.58 with it)
    double cross = 0;
    for (std::uint32_t j = p.beams / 2 - 10; j < p.beams / 2 + 10; ++j)
        cross += correlation(p, d.speckle, j, d.noise, j) / 20;
    EXPECT_NEAR(cross, 0.0, 0.01);

    // one look: Rayleigh speckle's grained draws, byte for byte
    SonarConfig one = c;
    one.speckle_looks = 1;
    SonarConfig rayleigh = c;
    rayleigh.speckle = SpeckleModel::rayleigh;
    const Draws one_look = draws_of(grain_plan(one)), rayleigh_draws = draws_of(grain_plan(rayleigh));
    EXPECT_EQ(std::memcmp(one_look.speckle.data(), rayleigh_draws.speckle.data(), one_look.speckle.size() * 4), 0);

    // 2.5 looks: per cell, whatever beam_correlation says (noise off, so the scans hold speckle alone)
    SonarConfig half = c;
    half.speckle_looks = 2.5;
    half.effects.ambient_noise = EffectMode::off;
    half.bins = 256;
    SonarConfig half_none = half;
    half_none.beam_correlation = BeamCorrelation::none;
    const Plan hp = grain_plan(half), hn = grain_plan(half_none);
    ASSERT_GT(hp.grain.taps, 0u);
    EXPECT_FALSE(host::row_draws_of(hp).speckle);
    Frame grained = vksonar::testing::host_stage_frame(hp), alone = vksonar::testing::host_stage_frame(hn);
    grained.clean.assign(grained.clean.size(), 1e-9f);
    alone.clean = grained.clean;
    host::noise_and_gain(hp, 5, 2, grained);
    host::noise_and_gain(hn, 5, 2, alone);
    EXPECT_EQ(std::memcmp(grained.intensity.data(), alone.intensity.data(), grained.intensity.size() * 4), 0);
    double spread = 0; // and the cells are speckled (not a constant)
    for (std::size_t i = 1; i < grained.intensity.size(); ++i)
        spread += std::abs(grained.intensity[i] - grained.intensity[0]);
    EXPECT_GT(spread, 0.0);
}

// meta.json's noise entry says what is grained, from what the noise stage draws in rows, and gives the grid
// only then.
TEST(Grain, MetaSaysWhatIsGrained) {
    SonarConfig c = grain_config();
    c.bins = 64;
    Plan p = grain_plan(c);
    ASSERT_GT(p.grain.taps, 0u) << p.grain.why;
    const auto text = [&] { return host::noise_json(p)["grain"].get<std::string>(); };
    EXPECT_EQ(text(), "speckle and ambient noise correlated across beams as the receive pattern overlaps them");
    EXPECT_EQ(host::noise_json(p)["grain_taps"].get<std::uint32_t>(), p.grain.taps);
    p.config.speckle = SpeckleModel::gamma; // one look: Rayleigh's draws
    EXPECT_EQ(text(), "speckle and ambient noise correlated across beams as the receive pattern overlaps them");
    p.config.speckle_looks = 3;
    EXPECT_EQ(text(), "gamma speckle (the mean of 3 grained looks) and ambient noise correlated across beams as the "
                      "receive pattern overlaps them");
    p.config.speckle_looks = 2.5;
    EXPECT_EQ(text(), "ambient noise correlated across beams as the receive pattern overlaps them (gamma speckle of "
                      "2.5 looks is drawn per cell: the grain averages a whole number of looks, at most 16)");
    p.config.speckle_looks = 17;
    EXPECT_NE(text().find("gamma speckle of 17.0 looks is drawn per cell"), std::string::npos) << text();
    p.config.speckle = SpeckleModel::gaussian;
    EXPECT_EQ(text(), "ambient noise correlated across beams as the receive pattern overlaps them (the gaussian "
                      "speckle model is drawn per cell)");
    p.effects.ambient_noise = false;
    EXPECT_EQ(text(), "nothing grained: the gaussian speckle model is drawn per cell, and ambient noise is off");
    EXPECT_EQ(host::noise_json(p)["grain_taps"].get<std::uint32_t>(), 0u);
    c.beam_correlation = BeamCorrelation::none;
    EXPECT_EQ(host::noise_json(grain_plan(c))["grain"].get<std::string>(),
              "beam_correlation none: every cell drawn alone");
}

// The stage's sums against the tables' meaning (Plan::grain, plan.h), evaluated here in double: each
// beam's field is the sum over its block's points of the point's weight for that beam's lane times the point's
// complex normal, drawn from the counter-based RNG as the noise stage documents it (power -log(u) from the
// 24-bit draw of stream 96, phase 2 pi i / 4096 from the top 12 bits of stream 97; docs/pipeline.md "Grain").
// A beam or lane mixed up in the stage, a point taken from the wrong chunk or a wrong wrap on a circle breaks
// it at once. The draws are O(1) (mean 1): a float field of at most a few dozen products of O(1) terms is off
// by a few 1e-7 at most (the phase table's floats, fast_logf's 1e-7, the sums' roundings), its power by
// about twice that times |z|: within 1e-5 of the double one, relative where it exceeds 1. A mixed-up beam
// is off by O(1).
TEST(Grain, TheStagesSumsAreTheTablesInDouble) {
    struct Case {
        const char* name;
        SonarConfig config;
    };
    SonarConfig line_array = grain_config();
    line_array.bins = 16;
    line_array.beams = 509; // odd: the last block is partial
    SonarConfig circle = fan_config(BeamPattern::sinc, BeamGeometry::planar, 360.0, 0.2, 1210);
    circle.bins = 16;
    SonarConfig box = fan_config(BeamPattern::box, BeamGeometry::planar, 130.0, 3.0, 333);
    box.bins = 16;
    for (const Case& kase : {Case{"line array, 509 beams", line_array}, Case{"circle, 1210 beams", circle},
                             Case{"planar box, 333 beams", box}}) {
        SCOPED_TRACE(kase.name);
        const Plan p = grain_plan(kase.config);
        ASSERT_GT(p.grain.taps, 0u) << p.grain.why;
        const std::size_t cells = std::size_t(p.beams) * p.bins;
        std::vector<float> speckle(cells), noise(cells);
        host::noise_draws(p, 21, 4, {speckle.data(), noise.data()}, nullptr);
        const host::rng::FrameKey key = host::rng::frame_key(21, 4);
        double worst = 0;
        for (std::uint32_t bin = 0; bin < p.bins; ++bin) {
            for (std::size_t c = 0; c + 1 < p.grain.chunk.size(); ++c) {
                const std::uint32_t b0 = p.grain.chunk[c], count = p.grain.chunk[c + 1] - b0;
                const auto point_value = [&](std::uint32_t i, double& re, double& im) {
                    const std::int64_t cells_around = p.grain.cells;
                    const auto m = static_cast<std::uint32_t>(
                        ((std::int64_t(p.grain.chunk_low[c]) + i) % cells_around + cells_around) % cells_around);
                    const double u =
                        (double(host::rng::hash_cell32(key, m, bin, 96) >> 8) + 0.5) / 16777216.0; // 24 bits
                    const double amplitude = std::sqrt(-std::log(u));
                    const double phase = 2.0 * kPi * double(host::rng::hash_cell32(key, m, bin, 97) >> 20) / 4096.0;
                    re = amplitude * std::cos(phase);
                    im = amplitude * std::sin(phase);
                };
                for (std::uint32_t b = p.grain.chunk_block[c]; b < p.grain.chunk_block[c + 1]; ++b) {
                    const std::uint32_t q0 = (b - p.grain.chunk_block[c]) * kGrainLanes;
                    const std::uint32_t begin = p.grain.block_points[2 * b], end = p.grain.block_points[2 * b + 1];
                    ASSERT_LE(end, p.grain.chunk_points[c]);
                    for (std::uint32_t l = 0; l < kGrainLanes && q0 + l < count; ++l) {
                        double field_re = 0, field_im = 0;
                        for (std::uint32_t i = begin; i < end; ++i) {
                            const double w = p.grain.weight[p.grain.block_weight[b] + (i - begin) * kGrainLanes + l];
                            double re, im;
                            point_value(i, re, im);
                            field_re += w * re;
                            field_im += w * im;
                        }
                        const double expected = field_re * field_re + field_im * field_im;
                        const double got = speckle[std::size_t(bin) * p.beams + b0 + q0 + l];
                        worst = std::max(worst, std::abs(got - expected) / std::max(expected, 1.0));
                    }
                }
            }
        }
        EXPECT_LT(worst, 1e-5);
    }
}
