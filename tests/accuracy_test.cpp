// Analytic checks of the model at `--quality accurate` (issue 6): each expected value is a closed form
// or a quadrature computed here, independently of the pipeline's code.
//   - flat plane at known range and tilt: first-return range and the Lambert incidence curve;
//   - sphere at known range: first return and total echo;
//   - horizontal pattern of a point-like target against sinc^2;
//   - the error against a fine reference shrinks with every doubling of horizontal oversampling.
// The CPU backend runs them (the same math as the shaders; tests/gpu_cpu_test.cpp ties the two), the
// plane also on Vulkan.
#include <algorithm>
#include <cmath>
#include <vector>

#include "test_support.h"

namespace vksonar::testing {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

// Clean model, accurate knobs; the terms a case does not test are switched off so the closed form
// stays short: no vertical pattern, no absorption, and (unless asked) no side lobes.
SonarConfig analytic_config(bool side_lobes = false) {
    auto accurate = apply_quality(quiet_config(), "accurate");
    EXPECT_TRUE(accurate.ok());
    SonarConfig config = accurate.value();
    config.effects.vertical_pattern = EffectMode::off;
    config.effects.absorption = EffectMode::off;
    config.effects.horizontal_pattern = side_lobes ? EffectMode::on : EffectMode::off;
    return config;
}

double total(const Frame& frame) {
    double s = 0;
    for (float x : frame.clean)
        s += x;
    return s;
}

// First bin whose energy exceeds `fraction` of the strongest bin (energy summed over beams).
int first_bin_above(const Frame& frame, double fraction) {
    std::vector<double> per_bin(frame.bins, 0.0);
    for (std::uint32_t k = 0; k < frame.bins; ++k)
        for (std::uint32_t j = 0; j < frame.beams; ++j)
            per_bin[k] += frame.clean[std::size_t(k) * frame.beams + j];
    const double peak = *std::max_element(per_bin.begin(), per_bin.end());
    for (std::uint32_t k = 0; k < frame.bins; ++k)
        if (per_bin[k] > fraction * peak) return static_cast<int>(k);
    return -1;
}

int bin_of_range(const Frame& frame, double range_m, const SonarConfig& config) {
    const double width = (config.range_max_m - config.range_min_m) / frame.bins;
    return static_cast<int>(std::floor((range_m - config.range_min_m) / width));
}

// Scattering strength s(cos theta) per unit area, plus spreading, integrated over a flat square (side a,
// centre at distance d on the x axis, turned by `tilt` about z): E = sum s(theta_i) / r^4 dA (per
// pixel the model takes 10^(mu/10) f(theta) Omega / r^2 with Omega = cos(theta) dA / r^2 and
// f = s / (10^(mu/10) cos)). Midpoint rule, n x n cells.
template <class Strength>
double plane_integral(Strength strength, double a, double d, double tilt, int n = 600, double* nearest = nullptr) {
    const double nx = -std::cos(tilt), ny = -std::sin(tilt); // faces the sonar
    const double tx = -std::sin(tilt), ty = std::cos(tilt);  // in-plane horizontal direction
    double e = 0, r_min = 1e30;
    const double da = (a / n) * (a / n);
    for (int i = 0; i < n; ++i) {
        const double s = (i + 0.5) / n * a - a / 2;
        for (int j = 0; j < n; ++j) {
            const double z = (j + 0.5) / n * a - a / 2;
            const double x = d + s * tx, y = s * ty;
            const double r2 = x * x + y * y + z * z, r = std::sqrt(r2);
            const double cos_i = std::abs(nx * x + ny * y) / r;
            e += strength(cos_i) / (r2 * r2) * da;
            r_min = std::min(r_min, r);
        }
    }
    if (nearest) *nearest = r_min;
    return e;
}

// Lambert: s = mu cos^2(theta).
double plane_echo(double mu, double a, double d, double tilt, int n = 600, double* nearest = nullptr) {
    return plane_integral([mu](double cos_i) { return mu * cos_i * cos_i; }, a, d, tilt, n, nearest);
}

class PlaneCase : public ::testing::TestWithParam<Backend> {
protected:
    void SetUp() override {
        if (GetParam() == Backend::vulkan) VKSONAR_REQUIRE_VULKAN();
    }
    ValidationGuard validation_;
};

TEST_P(PlaneCase, FirstReturnAndLambertCurveMatchTheClosedForm) {
    const SonarConfig config = analytic_config();
    const double d = 10.0, side = 1.0, mu_db = -20.0;
    double previous = 1e30;
    for (double tilt_deg : {0.0, 15.0, 30.0, 45.0, 60.0, 70.0}) {
        Scene scene;
        add_quad(scene, d, 0.0, 0.0, side, side, mu_db, tilt_deg);
        auto r = render_once(GetParam(), config, scene);
        ASSERT_TRUE(r);
        double nearest = 0;
        const double expected = plane_echo(std::pow(10.0, mu_db / 10.0), side, d, tilt_deg * kDeg, 600, &nearest);
        const double got = total(r->frame);
        const double error_db = 10.0 * std::log10(got / expected);
        std::printf("[plane] tilt %4.0f deg: echo %.4e vs closed form %.4e (%+.3f dB), first bin %d vs %d\n", tilt_deg,
                    got, expected, error_db, first_bin_above(r->frame, 1e-3), bin_of_range(r->frame, nearest, config));
        // 0.25 dB: at accurate a 1 m plate at 10 m covers ~90 x 40 pixels; the partly covered pixels
        // along its outline (a few % of them, half covered on average) and the r^-4 variation inside
        // a pixel (< 0.1 %) are the only discretization error, and they are unbiased to first order.
        EXPECT_NEAR(error_db, 0.0, 0.25) << "tilt " << tilt_deg;
        // The first return is the plate's nearest point, +-1 bin (a bin is 7.7 cm; the footprint kernel
        // spreads a pixel over its own range extent, < 1 bin here).
        EXPECT_NEAR(first_bin_above(r->frame, 1e-3), bin_of_range(r->frame, nearest, config), 1) << tilt_deg;
        EXPECT_LT(got, previous) << "echo must fall monotonically with incidence angle";
        previous = got;
    }
}

// The rough model on a plate: Lambert plus the Kirchhoff facet term of Gaussian slopes (rms m),
// s = mu cos^2 + R^2 exp(-tan^2(theta) / (2 m^2)) / (8 pi m^2 cos^4(theta)), written here from theta.
// The lobe (m = 0.1: ~6 deg) is resolved by ~90 pixel columns per degree at `accurate`.
TEST_P(PlaneCase, RoughPlateFollowsTheFacetModel) {
    const SonarConfig config = analytic_config();
    const double d = 10.0, side = 1.0;
    AcousticMaterial material;
    material.name = "rough plate";
    material.backscatter_db = -20.0;
    material.model = AcousticMaterial::Model::rough;
    material.rms_slope = 0.1;
    material.reflection_db = -6.0;
    const double mu = std::pow(10.0, material.backscatter_db / 10.0);
    const double reflection = std::pow(10.0, material.reflection_db / 10.0);
    const double m = material.rms_slope;
    const auto rough = [&](double cos_i) {
        const double theta = std::acos(std::min(cos_i, 1.0));
        const double facet =
            reflection * std::exp(-std::pow(std::tan(theta), 2) / (2 * m * m)) / (8 * kPi * m * m * std::pow(cos_i, 4));
        return mu * cos_i * cos_i + facet;
    };
    double previous = 1e30;
    for (double tilt_deg : {0.0, 3.0, 6.0, 10.0, 20.0, 40.0}) {
        Scene scene;
        add_quad(scene, d, 0.0, 0.0, side, side, material, tilt_deg);
        auto r = render_once(GetParam(), config, scene);
        ASSERT_TRUE(r);
        const double tilt = tilt_deg * kDeg;
        double nearest = 0;
        const double expected = plane_integral(rough, side, d, tilt, 600, &nearest);
        const double lambert = plane_echo(mu, side, d, tilt);
        const double got = total(r->frame);
        const double error_db = 10.0 * std::log10(got / expected);
        std::printf("[rough plane] tilt %4.0f deg: echo %.4e vs closed form %.4e (%+.3f dB; Lambert alone %+.2f dB)\n",
                    tilt_deg, got, expected, error_db, 10.0 * std::log10(lambert / expected));
        // 0.25 dB as for the Lambert plate: outline pixels and the variation inside a pixel; the facet
        // term changes by < 2 % across one pixel's 0.064 deg even on the lobe's flank.
        EXPECT_NEAR(error_db, 0.0, 0.25) << "tilt " << tilt_deg;
        EXPECT_NEAR(first_bin_above(r->frame, 1e-3), bin_of_range(r->frame, nearest, config), 1) << tilt_deg;
        EXPECT_LT(got, previous) << "the echo falls monotonically with incidence (m < 0.447)";
        previous = got;
        // The test tells the models apart: near normal incidence the facet term dominates (closed form:
        // +19.7 dB over Lambert at 0 deg), at 40 deg it is gone (exp(-35)).
        if (tilt_deg == 0.0) {
            EXPECT_GT(10.0 * std::log10(expected / lambert), 10.0);
        }
        if (tilt_deg == 40.0) {
            EXPECT_NEAR(10.0 * std::log10(got / lambert), 0.0, 0.25);
        }
    }
}

INSTANTIATE_TEST_SUITE_P(Backends, PlaneCase, ::testing::Values(Backend::cpu, Backend::vulkan),
                         [](const ::testing::TestParamInfo<Backend>& param_info) {
                             return param_info.param == Backend::cpu ? std::string("cpu") : std::string("vulkan");
                         });

// The same integral over the visible cap of a sphere (centre at distance d, radius rs), in spherical
// coordinates about the centre: dA = rs^2 sin(t) dt dp.
double sphere_echo(double mu, double rs, double d, int n = 1000) {
    double e = 0;
    for (int i = 0; i < n; ++i) {
        const double t = (i + 0.5) / n * kPi;
        for (int j = 0; j < 2 * n; ++j) {
            const double p = (j + 0.5) / (2 * n) * 2 * kPi;
            const double nx = std::sin(t) * std::cos(p), ny = std::sin(t) * std::sin(p), nz = std::cos(t);
            const double x = d + rs * nx, y = rs * ny, z = rs * nz;
            const double r2 = x * x + y * y + z * z, r = std::sqrt(r2);
            const double cos_i = -(nx * x + ny * y + nz * z) / r;
            if (cos_i <= 0) continue; // faces away: not seen
            e += mu * cos_i * cos_i / (r2 * r2) * rs * rs * std::sin(t) * (kPi / n) * (kPi / n);
        }
    }
    return e;
}

TEST(SphereCase, FirstReturnAndTotalEchoMatchTheClosedForm) {
    const SonarConfig config = analytic_config();
    const double d = 12.0, rs = 1.0, mu_db = -20.0;
    Scene scene;
    add_sphere(scene, d, 0, 0, rs, 96, mu_db);
    auto r = render_once(Backend::cpu, config, scene);
    ASSERT_TRUE(r);
    const double expected = sphere_echo(std::pow(10.0, mu_db / 10.0), rs, d);
    const double error_db = 10.0 * std::log10(total(r->frame) / expected);
    std::printf("[sphere] echo %+.3f dB vs closed form, first bin %d vs %d\n", error_db,
                first_bin_above(r->frame, 1e-3), bin_of_range(r->frame, d - rs, config));
    // 0.5 dB: the mesh has 96 x 48 facets (3.75 deg each). Flat facets inside the smooth sphere lose
    // up to 1 - cos(1.9 deg) of the radius and their Sobel normals follow the facets, which tilts the
    // Lambert cos^2 by up to ~2 deg near the rim; plus the outline pixels as for the plane.
    EXPECT_NEAR(error_db, 0.0, 0.5);
    EXPECT_NEAR(first_bin_above(r->frame, 1e-3), bin_of_range(r->frame, d - rs, config), 1);
}

// sinc^2(k sin a) with k such that the power is 1/2 at +-beamwidth/2: solved here by bisection on
// sin(x)/x = 1/sqrt(2), not taken from the library.
double sinc2_pattern(double a, double beamwidth_rad) {
    double lo = 0.1, hi = 3.0;
    for (int i = 0; i < 100; ++i) {
        const double mid = 0.5 * (lo + hi);
        (std::sin(mid) / mid > 1.0 / std::sqrt(2.0) ? lo : hi) = mid;
    }
    const double k = lo / std::sin(beamwidth_rad / 2);
    const double x = k * std::sin(a);
    if (std::abs(x) < 1e-9) return 1.0;
    const double s = std::sin(x) / x;
    return s * s;
}

// The per-beam response of a 2 cm target on the centre of the middle beam, in dB re that beam, against
// `expected_power(a)` at each beam's angle a off the target, over the crests: cells more than
// `crest_db` below the axis are near nulls, where the pattern falls tens of dB per degree and the
// target's own width fills it; inside the first null (|a| < first_null_rad) only cells down to
// `main_lobe_db` are compared (a steep main-lobe flank). Returns the number of beams compared.
template <class Pattern>
int trace_point_target(const SonarConfig& config, Pattern expected_power, double crest_db, double main_lobe_db = 0,
                       double first_null_rad = 0) {
    // Find the beam table first, then put the target exactly on the centre of the middle beam.
    Scene probe;
    add_quad(probe, 10.0, 0.0, 0.0, 1.0, 1.0);
    auto table = render_once(Backend::cpu, config, probe);
    EXPECT_TRUE(table);
    if (!table) return 0;
    const std::uint32_t j0 = table->frame.beams / 2;
    // The crests and nulls come from the kernel's exact taps; the far side lobes carry the pattern's mean
    // level beyond them (tests/far_sidelobes_test.cpp), so the callers trace the taps alone.
    EXPECT_EQ(config.far_sidelobe_cell, 0.0);
    const double phi0 = table->frame.beam_angles_rad[j0];
    Scene scene;
    add_quad(scene, 10.0 * std::cos(phi0), 10.0 * std::sin(phi0), 0.0, 0.02, 0.5, -10.0, phi0 / kDeg);
    auto r = render_once(Backend::cpu, config, scene);
    EXPECT_TRUE(r);
    if (!r) return 0;
    const Frame& f = r->frame;
    std::vector<double> per_beam(f.beams, 0.0);
    for (std::uint32_t k = 0; k < f.bins; ++k)
        for (std::uint32_t j = 0; j < f.beams; ++j)
            per_beam[j] += f.clean[std::size_t(k) * f.beams + j];
    EXPECT_GT(per_beam[j0], 0.0);
    const double bw = config.horizontal_beamwidth_deg * kDeg;
    const double reach = config.sidelobe_kernel_beamwidths * bw; // the kernel is truncated there
    int compared = 0;
    double worst = 0;
    for (std::uint32_t j = 0; j < f.beams; ++j) {
        const double a = f.beam_angles_rad[j] - phi0;
        if (std::abs(a) > reach - 0.5 * bw) continue;
        const double expected = expected_power(a);
        if (10.0 * std::log10(expected) < crest_db) continue;
        if (std::abs(a) < first_null_rad && 10.0 * std::log10(expected) < main_lobe_db) continue;
        const double got_db = 10.0 * std::log10(per_beam[j] / per_beam[j0]);
        const double expected_db = 10.0 * std::log10(expected);
        worst = std::max(worst, std::abs(got_db - expected_db));
        ++compared;
        // 1 dB: the target is 0.11 deg wide and its pixel columns are split between the two nearest
        // beams (0.25 deg apart) before the convolution; on the main-lobe flank (~25 dB/deg at -10 dB)
        // that smearing moves a sample by up to ~1 dB, far less near the peak and on the side lobes.
        EXPECT_NEAR(got_db, expected_db, 1.0) << "beam " << j << " at " << a / kDeg << " deg";
    }
    std::printf("[pattern] %d beams compared, worst %.2f dB from the pattern\n", compared, worst);
    return compared;
}

TEST(HorizontalPattern, PointLikeTargetTracesSincSquared) {
    SonarConfig config = analytic_config(true);
    config.far_sidelobe_cell = 0.0;
    const double bw = config.horizontal_beamwidth_deg * kDeg;
    // sinc^2 side lobes peak at -13.3 dB: compare down to -16 dB.
    const int compared = trace_point_target(
        config, [bw](double a) { return sinc2_pattern(a, bw); }, -16.0);
    EXPECT_GE(compared, 10); // main lobe and the first side lobes on both sides
}

// Dolph-Chebyshev (large-array limit) at -25 dB: every side lobe at -25 dB. The pattern is written here
// from its definition, with k found by bisection on the half-power condition, not from the library.
TEST(HorizontalPattern, PointLikeTargetTracesTheChebyshevPattern) {
    SonarConfig config = analytic_config(true);
    config.far_sidelobe_cell = 0.0;
    config.horizontal_pattern = BeamPattern::chebyshev;
    config.horizontal_sidelobe_db = -25.0;
    const double bw = config.horizontal_beamwidth_deg * kDeg;
    const double big_a = std::acosh(std::pow(10.0, 25.0 / 20.0));
    const auto amplitude = [big_a](double x) {
        const double d = big_a * big_a - x * x;
        return (d >= 0 ? std::cosh(std::sqrt(d)) : std::cos(std::sqrt(-d))) / std::cosh(big_a);
    };
    double lo = 0.0, hi = big_a; // the half-power point lies inside the main lobe, x < A
    for (int i = 0; i < 100; ++i) {
        const double mid = 0.5 * (lo + hi);
        (amplitude(mid) > 1.0 / std::sqrt(2.0) ? lo : hi) = mid;
    }
    const double k = lo / std::sin(bw / 2);
    const double first_null = std::asin(std::sqrt(big_a * big_a + kPi * kPi / 4) / k);
    // The side-lobe crests at -25 dB and the main lobe down to -10 dB: its flank is steeper than
    // sinc^2's (the price of lower side lobes), so the target's width smears the samples below that.
    const int compared = trace_point_target(
        config,
        [&](double a) {
            const double amp = amplitude(k * std::sin(a));
            return amp * amp;
        },
        -28.0, -10.0, first_null);
    EXPECT_GE(compared, 10);
}

TEST(Oversampling, ErrorShrinksWithEveryDoubling) {
    // Per-beam echo of a sphere against a fine reference (CPU, double, 16 columns per beam), at equal
    // rows: only the horizontal sampling differs, so the error must fall at every doubling.
    SonarConfig config = analytic_config();
    Scene scene;
    add_sphere(scene, 12.0, 0, 0, 1.0, 96, -20.0);
    auto per_beam = [&](double ppb, Precision precision) {
        SonarConfig c = config;
        c.pixels_per_beam = ppb;
        c.cpu_precision = precision;
        auto r = render_once(Backend::cpu, c, scene);
        std::vector<double> out;
        if (!r) return out;
        out.assign(r->frame.beams, 0.0);
        for (std::uint32_t k = 0; k < r->frame.bins; ++k)
            for (std::uint32_t j = 0; j < r->frame.beams; ++j)
                out[j] += r->frame.clean[std::size_t(k) * r->frame.beams + j];
        return out;
    };
    const std::vector<double> reference = per_beam(16, Precision::f64);
    ASSERT_FALSE(reference.empty());
    const double peak = *std::max_element(reference.begin(), reference.end());
    double previous = 1e30;
    for (double ppb : {1.0, 2.0, 4.0, 8.0}) {
        const std::vector<double> got = per_beam(ppb, Precision::f64);
        ASSERT_EQ(got.size(), reference.size());
        double sq = 0;
        int n = 0;
        for (std::size_t j = 0; j < got.size(); ++j) {
            if (reference[j] < 1e-3 * peak) continue;
            const double e = 10.0 * std::log10(std::max(got[j], 1e-30) / reference[j]);
            sq += e * e;
            ++n;
        }
        ASSERT_GT(n, 0);
        const double rmse = std::sqrt(sq / n);
        std::printf("[oversampling] %g px/beam: RMSE %.4f dB over %d beams\n", ppb, rmse, n);
        EXPECT_LT(rmse, previous) << ppb << " px/beam";
        previous = rmse;
    }
}

} // namespace
} // namespace vksonar::testing
