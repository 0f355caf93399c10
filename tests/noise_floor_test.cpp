// The noise terms' "auto" values (SonarConfig::noise_terms) against references computed here: the
// directivity index as 4 pi over the receive pattern's whole solid angle, a double integral over the
// front half-space with this file's own sinc and its own half-power constant; the noise level from the
// thermal-noise law and the band's width.
#include <gtest/gtest.h>

#include <cmath>

#include "test_support.h" // sinc_half_power_x: the tests' own half-power constant
#include "vksonar/config.h"

namespace {

using namespace vksonar;
using vksonar::testing::sinc_half_power_x;

constexpr double kPi = 3.14159265358979323846;

double sinc2(double x) {
    if (std::abs(x) < 1e-9) return 1.0;
    const double s = std::sin(x) / x;
    return s * s;
}

// DI = 10 log10(4 pi / Omega), Omega = int int b_h^2 b_v^2 cos(psi) dphi dpsi over phi, psi in
// (-pi/2, pi/2): unshaded apertures (sinc^2 in the sine of the angle off the axis), -3 dB at +-bw/2. A
// line array's horizontal pattern takes the direction's cosine along the array, cos(psi) sin(phi); planar
// beams the azimuth's sine.
double directivity_by_double_integral(double h_deg, double v_deg, bool line_array) {
    const double x3 = sinc_half_power_x();
    const double kh = x3 / std::sin(0.5 * h_deg * kPi / 180.0), kv = x3 / std::sin(0.5 * v_deg * kPi / 180.0);
    const int n_phi = 12000, n_psi = 1500;
    const double d_phi = kPi / n_phi, d_psi = kPi / n_psi;
    double omega = 0.0;
    for (int i = 0; i < n_psi; ++i) {
        const double psi = -0.5 * kPi + (i + 0.5) * d_psi;
        double row = 0.0;
        for (int j = 0; j < n_phi; ++j) {
            const double phi = -0.5 * kPi + (j + 0.5) * d_phi;
            row += sinc2(kh * (line_array ? std::cos(psi) : 1.0) * std::sin(phi));
        }
        omega += row * d_phi * sinc2(kv * std::sin(psi)) * std::cos(psi) * d_psi;
    }
    return 10.0 * std::log10(4.0 * kPi / omega);
}

// The resolved DI of a sinc x sinc receiver against the double integral, both geometries: a 1 x 20 deg
// beam (the default sonar; the common rule 10 log10(41253 / (1 x 20)) = 33.1 dB is a box beam's), an
// ARIS-like 0.3 x 14, and wide 3 x 40 beams where separating the integral costs most. Tolerance 0.1 dB:
// the library separates the integral (exact for planar beams, to the narrow-beam limit for cones).
TEST(NoiseFloor, AutoDirectivityIndexIsTheReceivePatternsSolidAngle) {
    struct Case {
        double h, v;
        BeamGeometry geometry;
    };
    for (const Case& c : {Case{1.0, 20.0, BeamGeometry::line_array}, Case{1.0, 20.0, BeamGeometry::planar},
                          Case{0.3, 14.0, BeamGeometry::planar}, Case{3.0, 40.0, BeamGeometry::line_array}}) {
        SonarConfig config;
        config.horizontal_beamwidth_deg = c.h;
        config.vfov_deg = c.v;
        config.beam_geometry = c.geometry;
        ASSERT_TRUE(config.validate());
        const bool line = c.geometry == BeamGeometry::line_array;
        const double expect = directivity_by_double_integral(c.h, c.v, line);
        EXPECT_NEAR(config.noise_terms().directivity_index_db, expect, 0.1)
            << c.h << " x " << c.v << " deg, " << (line ? "line_array" : "planar");
    }
    // An explicit DI is taken as it is.
    SonarConfig fixed;
    fixed.directivity_index_db = 25.0;
    EXPECT_EQ(fixed.noise_terms().directivity_index_db, 25.0);
}

// Above about 100 kHz the sea's noise is the water's thermal noise, -15 + 20 log10(f / 1 kHz) dB re
// 1 uPa^2/Hz (Mellen 1952); over a receive band B the level is that times B, and a matched receiver's band
// is the range bins' c / 2 dr. Wind and shipping noise fall as f^-1.7 and faster: at 750 kHz they add
// less than 0.01 dB. Over a band as wide as 2 f, the f^2 law sums to B (f^2 + B^2 / 12) / f^2: 1.25 dB more.
TEST(NoiseFloor, AutoNoiseLevelIsThermalNoiseOverTheReceiveBand) {
    SonarConfig config; // 750 kHz, 512 bins over 0.5-40 m
    const double bin = (config.range_max_m - config.range_min_m) / config.bins;
    const double band = config.sound_speed_mps / (2.0 * bin);
    const double thermal = -15.0 + 20.0 * std::log10(750.0);
    const NoiseTerms t = config.noise_terms();
    EXPECT_NEAR(t.band_hz, band, 1e-6 * band);
    EXPECT_NEAR(t.noise_level_db, thermal + 10.0 * std::log10(band), 0.05);

    SonarConfig wide = config; // a chirp over the whole band: 1.5 MHz
    wide.bandwidth_hz = 2.0 * wide.frequency_hz;
    wide.range_max_m = 10.0;   // 19 000 bins of 0.5 mm
    wide.wind_speed_mps = 0.0; // down at a few kHz a 5 m/s wind's noise would add 0.2 dB to this band
    ASSERT_TRUE(wide.validate());
    EXPECT_NEAR(wide.noise_terms().noise_level_db,
                thermal + 10.0 * std::log10(wide.bandwidth_hz) + 10.0 * std::log10(4.0 / 3.0), 0.05);

    // At 10 kHz the wind's noise leads by far (sea state 2-3: 40-50 dB/Hz on the Wenz curves, against the
    // thermal 5 dB/Hz), and more wind raises it; an explicit level is kept.
    SonarConfig low = config;
    low.frequency_hz = 10e3;
    SonarConfig windy = low;
    windy.wind_speed_mps = 15.0;
    EXPECT_GT(low.noise_terms().noise_level_db, 5.0 + 10.0 * std::log10(band) + 30.0);
    EXPECT_GT(windy.noise_terms().noise_level_db, low.noise_terms().noise_level_db + 5.0);
    SonarConfig fixed = config;
    fixed.noise_level_db = 60.0;
    EXPECT_EQ(fixed.noise_terms().noise_level_db, 60.0);

    // Bins finer than a 1 kHz pulse can resolve (0.5-40 m in 512 bins: c / 2 dr = 9.7 kHz) ask for a band
    // below 0 Hz: the band is at most 0 .. 2 f, and the sum starts at f / 10, where the turbulence and
    // shipping terms stay finite (a review's: NaN noise, every cell FLT_MAX). Likewise a band of exactly 2 f.
    SonarConfig fine = config;
    fine.frequency_hz = 1000.0;
    ASSERT_TRUE(fine.validate());
    EXPECT_EQ(fine.noise_terms().band_hz, 2000.0);
    EXPECT_TRUE(std::isfinite(fine.noise_terms().noise_level_db));
    fine.bandwidth_hz = 2000.0;
    ASSERT_TRUE(fine.validate());
    EXPECT_TRUE(std::isfinite(fine.noise_terms().noise_level_db));
    EXPECT_LT(fine.noise_terms().noise_level_db, 120.0);
}

} // namespace
