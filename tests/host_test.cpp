// Host stages 5/6: counter-based RNG and samplers, noise + gain, colormaps, images and output files.
// Statistical bounds are 5 standard errors of the estimator for the sample size used (a false
// failure has probability < 1e-6 per check, and the RNG is deterministic, so a pass stays a pass).
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include <sched.h>
#include <unistd.h>

#include "host/host_stages.h"
#include "host/rng.h"
#include "host/table_interval.h"
#include "host/workers.h"
#include "test_support.h"

#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wsign-compare"
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wunused-parameter"
#pragma GCC diagnostic ignored "-Wimplicit-fallthrough"
#endif
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_STATIC // the test's own decoder, independent of the writer under test
#define STBI_ONLY_PNG
#include <stb_image.h>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

namespace vksonar {
namespace {

namespace fs = std::filesystem;
constexpr double kPi = 3.14159265358979323846;

// A plan built by hand (no make_plan): equiangular or equisine beams, uniform bins.
Plan test_plan(std::uint32_t beams, std::uint32_t bins, double hfov_deg, double rmin, double rmax,
               bool equisine = false) {
    Plan p;
    p.config.hfov_deg = hfov_deg;
    p.config.beams = beams;
    p.config.bins = bins;
    p.config.range_min_m = rmin;
    p.config.range_max_m = rmax;
    p.config.fan_width_px = 400;
    p.beams = beams;
    p.bins = bins;
    const double half = 0.5 * hfov_deg * kPi / 180.0;
    for (std::uint32_t j = 0; j < beams; ++j) {
        const double u = 1.0 - 2.0 * (j + 0.5) / beams; // +1 (port) .. -1 (starboard)
        p.beam_angle_rad.push_back(equisine ? std::asin(std::sin(half) * u) : half * u);
    }
    p.bin_width_m = (rmax - rmin) / bins;
    for (std::uint32_t k = 0; k < bins; ++k)
        p.bin_range_m.push_back(rmin + (k + 0.5) * p.bin_width_m);
    p.effects.speckle = false;
    p.effects.ambient_noise = false;
    p.effects.tvg = false;
    p.effects.states = {{"speckle", false, "test"}, {"ambient_noise", true, "test"}};
    return p;
}

struct Moments {
    double mean = 0, var = 0;
};
template <class F> Moments moments(std::size_t n, F&& draw) {
    // Two passes over a stored sample: exact enough (1e6 doubles) and free of cancellation.
    std::vector<double> x(n);
    for (std::size_t i = 0; i < n; ++i)
        x[i] = draw(i);
    Moments m;
    for (double v : x)
        m.mean += v;
    m.mean /= n;
    for (double v : x)
        m.var += (v - m.mean) * (v - m.mean);
    m.var /= (n - 1);
    return m;
}
// Key of sample i: spread over beams and bins like a frame does.
inline std::uint32_t beam_of(std::size_t i) {
    return static_cast<std::uint32_t>(i % 1024);
}
inline std::uint32_t bin_of(std::size_t i) {
    return static_cast<std::uint32_t>(i / 1024);
}

std::string temp_dir() {
    const fs::path d = fs::temp_directory_path() / ("vksonar_host_test_" + std::to_string(::getpid()));
    fs::create_directories(d);
    return d.string();
}

std::string slurp(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// ---------------------------------------------------------------------------------------------- RNG

TEST(HostRng, SameKeySameValueAndEveryComponentMatters) {
    const double base = host::uniform01(42, 7, 3, 9, 0);
    EXPECT_EQ(base, host::uniform01(42, 7, 3, 9, 0));
    EXPECT_NE(base, host::uniform01(43, 7, 3, 9, 0));
    EXPECT_NE(base, host::uniform01(42, 8, 3, 9, 0));
    EXPECT_NE(base, host::uniform01(42, 7, 4, 9, 0));
    EXPECT_NE(base, host::uniform01(42, 7, 3, 10, 0));
    EXPECT_NE(base, host::uniform01(42, 7, 3, 9, 1));
    // Swapping beam and bin is a different key too.
    EXPECT_NE(host::uniform01(42, 7, 3, 9, 0), host::uniform01(42, 7, 9, 3, 0));
    // All-zero and all-ones keys are ordinary values.
    const double z = host::uniform01(0, 0, 0, 0, 0);
    EXPECT_GT(z, 0.0);
    EXPECT_LT(z, 1.0);
    EXPECT_NE(z, host::uniform01(0, 0, 0, 0, 1));
    const double o = host::uniform01(~0ull, ~0ull, ~0u, ~0u, ~0u);
    EXPECT_GT(o, 0.0);
    EXPECT_LT(o, 1.0);
}

TEST(HostRng, UniformMeanAndVariance) {
    constexpr std::size_t n = 1000000;
    double lo = 1.0, hi = 0.0;
    const Moments m = moments(n, [&](std::size_t i) {
        const double u = host::uniform01(1234, 5, beam_of(i), bin_of(i), 0);
        lo = std::min(lo, u);
        hi = std::max(hi, u);
        return u;
    });
    EXPECT_GT(lo, 0.0);
    EXPECT_LT(hi, 1.0);
    // Mean: sd 1/sqrt(12) -> SE = 0.2887/sqrt(n) = 2.9e-4, 5 SE = 1.44e-3.
    EXPECT_NEAR(m.mean, 0.5, 5.0 * std::sqrt(1.0 / 12.0 / n));
    // Variance: Var((U - 1/2)^2) = 1/80 - 1/144 = 1/180 -> SE = sqrt(1/180/n) = 7.5e-5.
    EXPECT_NEAR(m.var, 1.0 / 12.0, 5.0 * std::sqrt(1.0 / 180.0 / n));
    // Neighbouring cells and streams are uncorrelated: lag-1 correlation along beams, SE = 1/sqrt(n).
    double c = 0;
    for (std::size_t i = 0; i < n; ++i)
        c += (host::uniform01(1234, 5, beam_of(i), bin_of(i), 0) - 0.5) *
             (host::uniform01(1234, 5, beam_of(i), bin_of(i), 1) - 0.5);
    EXPECT_NEAR(c / n * 12.0, 0.0, 5.0 / std::sqrt(static_cast<double>(n)));
}

TEST(HostRng, Exp1MeanAndVariance) {
    constexpr std::size_t n = 1000000;
    const Moments m = moments(n, [](std::size_t i) { return host::sample_exp1(99, 0, beam_of(i), bin_of(i), 0); });
    // Exp(1): mean 1, variance 1 -> SE(mean) = 1/sqrt(n) = 1e-3; the 4th central moment is 9, so
    // Var((X - 1)^2) = 9 - 1 = 8 and SE(variance) = sqrt(8/n) = 2.8e-3.
    EXPECT_NEAR(m.mean, 1.0, 5.0 / std::sqrt(static_cast<double>(n)));
    EXPECT_NEAR(m.var, 1.0, 5.0 * std::sqrt(8.0 / n));
}

TEST(HostRng, NormalMeanAndVariance) {
    constexpr std::size_t n = 1000000;
    const Moments m = moments(n, [](std::size_t i) { return host::sample_normal01(5, 1, beam_of(i), bin_of(i), 0); });
    // N(0,1): SE(mean) = 1/sqrt(n); Var(X^2) = 3 - 1 = 2 -> SE(variance) = sqrt(2/n).
    EXPECT_NEAR(m.mean, 0.0, 5.0 / std::sqrt(static_cast<double>(n)));
    EXPECT_NEAR(m.var, 1.0, 5.0 * std::sqrt(2.0 / n));
}

TEST(HostRng, GammaUnitMeanVarianceOneOverLooks) {
    constexpr std::size_t n = 200000;
    for (double looks : {0.5, 1.0, 2.0, 4.0, 16.0}) {
        SCOPED_TRACE("looks " + std::to_string(looks));
        const Moments m = moments(
            n, [looks](std::size_t i) { return host::sample_gamma_unit_mean(looks, 7, 3, beam_of(i), bin_of(i), 0); });
        // Gamma(L, 1/L): mean 1, variance 1/L, 4th central moment 3(L+2)/L^3, so
        // Var((X - 1)^2) = (2L + 6)/L^3. Bounds: 5 SE of each estimator.
        const double var = 1.0 / looks;
        EXPECT_NEAR(m.mean, 1.0, 5.0 * std::sqrt(var / n));
        EXPECT_NEAR(m.var, var, 5.0 * std::sqrt((2.0 * looks + 6.0) / (looks * looks * looks) / n));
    }
    // Deterministic: the same key gives the same draw.
    EXPECT_EQ(host::sample_gamma_unit_mean(3.0, 1, 2, 3, 4, 0), host::sample_gamma_unit_mean(3.0, 1, 2, 3, 4, 0));
}

// ------------------------------------------------------------------------------------ noise + gain

TEST(HostNoise, AmbientFloorMeanIsNoiseLevel) {
    Plan p = test_plan(256, 256, 130, 0.5, 40);
    p.effects.ambient_noise = true;
    p.effects.speckle = true;
    p.config.noise_level_db = 70;
    p.config.directivity_index_db = 20;
    resolve_noise_floor(p);
    Frame f = vksonar::testing::host_stage_frame(p); // clean = 0 everywhere
    host::noise_and_gain(p, 11, 3, f);
    const double noise = std::pow(10.0, (70.0 - 20.0) / 10.0);
    double sum = 0;
    for (float v : f.intensity) {
        ASSERT_TRUE(std::isfinite(v));
        ASSERT_GT(v, 0.0f);
        sum += v;
    }
    const double n = static_cast<double>(f.intensity.size());
    // N * Exp(1): relative SE of the mean = 1/sqrt(n) = 1/256.
    EXPECT_NEAR(sum / n / noise, 1.0, 5.0 / std::sqrt(n));

    // Rerun with the same key: identical; another frame index: different.
    Frame g = vksonar::testing::host_stage_frame(p);
    host::noise_and_gain(p, 11, 3, g);
    EXPECT_EQ(f.intensity, g.intensity);
    host::noise_and_gain(p, 11, 4, g);
    EXPECT_NE(f.intensity, g.intensity);
}

// A line array's beam steered to theta is a cone whose width in sine space is the broadside beam's: in
// angle it is 1 / cos(theta) wider, its solid angle too, so it hears that much more isotropic noise:
// DI(theta) = DI + 10 log10(cos theta). Each beam's mean over its bins, against that.
TEST(HostNoise, ALineArraysSteeredBeamsHearMoreOfTheSea) {
    Plan p = test_plan(64, 4096, 130, 0.5, 40);
    p.line_array = true;
    p.effects.ambient_noise = true;
    p.config.noise_level_db = 70;
    p.config.directivity_index_db = 20;
    resolve_noise_floor(p);
    Frame f = vksonar::testing::host_stage_frame(p);
    host::noise_and_gain(p, 11, 3, f);
    for (std::uint32_t j = 0; j < p.beams; ++j) {
        const double theta = p.beam_angle_rad[j];
        const double expect = std::pow(10.0, (70.0 - (20.0 + 10.0 * std::log10(std::cos(theta)))) / 10.0);
        double sum = 0;
        for (std::uint32_t k = 0; k < p.bins; ++k)
            sum += f.intensity[std::size_t(k) * p.beams + j];
        // Exp(1) over 4096 bins: relative SE 1/64; 5 SE. At the fan's edge (64.5 deg) the floor is 3.6 dB up.
        EXPECT_NEAR(sum / p.bins / expect, 1.0, 5.0 / 64.0) << "beam " << j << " at " << theta << " rad";
    }
}

// The default noise (Rayleigh speckle + ambient noise) runs a float, vectorized loop; every cell must
// equal the model evaluated in double from the same draws, to the float path's four roundings
// (source * clean, * speckle, + noise * draw, * gain: <= 4 x 2^-24 relative, 3e-7 allowed), with
// NaN/negative echo as no echo and +inf as FLT_MAX.
TEST(HostNoise, DefaultFloatPathEqualsTheModelInDouble) {
    Plan p = test_plan(300, 64, 130, 0.5, 40); // 300 beams: two row chunks, the second partial
    p.effects.speckle = true;
    p.effects.ambient_noise = true;
    p.effects.tvg = true;
    p.config.speckle = SpeckleModel::rayleigh;
    p.config.source_level_db = 210;
    p.config.noise_level_db = 60;
    p.config.directivity_index_db = 20;
    p.config.tvg_db_per_decade = 40;
    resolve_noise_floor(p);
    Frame f = vksonar::testing::host_stage_frame(p);
    for (std::size_t i = 0; i < f.clean.size(); ++i)
        f.clean[i] = i % 3 == 0 ? 0.0f : std::pow(10.0f, -22.0f + float(i % 17)); // 1e-22 .. 1e-6
    f.clean[7] = std::nanf("");
    f.clean[8] = -1.0f;
    f.clean[9] = std::numeric_limits<float>::infinity();
    const std::uint64_t seed = 5, frame = 2;
    host::noise_and_gain(p, seed, frame, f);

    const host::rng::FrameKey key = host::rng::frame_key(seed, frame);
    const double source = std::pow(10.0, 210.0 / 10.0), noise = std::pow(10.0, (60.0 - 20.0) / 10.0);
    for (std::uint32_t k = 0; k < p.bins; ++k) {
        const double r = p.bin_range_m[k];
        const double gain = std::pow(10.0, 40.0 * std::log10(r) / 10.0); // alpha = 0 in this plan
        for (std::uint32_t j = 0; j < p.beams; ++j) {
            const std::size_t i = std::size_t(k) * p.beams + j;
            const double clean = f.clean[i] > 0.0f ? double(f.clean[i]) : 0.0; // NaN, < 0: no echo
            const double expect = (source * clean * host::rng::exp1_cell32(key, j, k, 0) +
                                   noise * host::rng::exp1_cell32(key, j, k, 64)) *
                                  gain;
            if (std::isinf(expect)) {
                ASSERT_EQ(f.intensity[i], std::numeric_limits<float>::max()) << "cell " << i;
                continue;
            }
            ASSERT_NEAR(f.intensity[i] / expect, 1.0, 3e-7) << "cell " << i;
        }
    }
}

// The renderer makes a frame's draws while the GPU renders (host::noise_draws) and the noise stage then
// reads them, copying the clean scan in from the backend's buffer as it goes: the same bytes as the stage
// making its own draws from frame.clean, on one thread or three, with the defaults and with either
// draw alone (speckle off, ambient noise off, or a speckle model whose draws are not made in rows).
TEST(HostNoise, DrawsMadeAheadAndTheCopiedScanGiveTheSameBytes) {
    struct Case {
        bool speckle, ambient_noise;
        SpeckleModel model;
    };
    for (const Case& c : {Case{true, true, SpeckleModel::rayleigh}, Case{false, true, SpeckleModel::rayleigh},
                          Case{true, false, SpeckleModel::rayleigh}, Case{true, true, SpeckleModel::gamma}}) {
        SCOPED_TRACE(std::string("speckle ") + (c.speckle ? "on" : "off") + ", noise " +
                     (c.ambient_noise ? "on" : "off") + (c.model == SpeckleModel::gamma ? ", gamma" : ""));
        Plan p = test_plan(300, 64, 130, 0.5, 40);
        p.effects.speckle = c.speckle;
        p.effects.ambient_noise = c.ambient_noise;
        p.effects.tvg = true;
        p.config.speckle = c.model;
        p.config.noise_level_db = 60;
        resolve_noise_floor(p);
        ASSERT_TRUE(host::noise_draws_ahead(p));
        Frame made_here = vksonar::testing::host_stage_frame(p);
        for (std::size_t i = 0; i < made_here.clean.size(); ++i)
            made_here.clean[i] = i % 3 == 0 ? 0.0f : std::pow(10.0f, -22.0f + float(i % 17));
        const std::vector<float> source = made_here.clean;
        const std::uint64_t seed = 5, frame = 2;
        host::noise_and_gain(p, seed, frame, made_here);
        for (std::uint32_t threads : {1u, 3u}) {
            host::Workers workers(threads);
            std::vector<float> speckle(source.size()), noise(source.size());
            const host::NoiseDraws draws{speckle.data(), noise.data()};
            host::noise_draws(p, seed, frame, draws, &workers);
            Frame ahead = vksonar::testing::host_stage_frame(p); // clean all zero: the stage copies it from `source`
            host::noise_and_gain(p, seed, frame, ahead, &workers, source.data(), &draws);
            EXPECT_EQ(ahead.clean, source) << threads << " threads";
            EXPECT_EQ(std::memcmp(ahead.intensity.data(), made_here.intensity.data(), source.size() * sizeof(float)), 0)
                << threads << " threads";
            EXPECT_EQ(std::memcmp(ahead.display.data(), made_here.display.data(), source.size() * sizeof(float)), 0)
                << threads << " threads";
        }
    }
    Plan quiet = test_plan(300, 64, 130, 0.5, 40); // no draws at all: nothing to make ahead
    quiet.effects.speckle = false;
    quiet.effects.ambient_noise = false;
    EXPECT_FALSE(host::noise_draws_ahead(quiet));
}

TEST(HostNoise, RayleighSpeckleHasUnitMeanAndVariance) {
    Plan p = test_plan(512, 512, 130, 0.5, 40);
    p.effects.speckle = true;
    p.config.speckle = SpeckleModel::rayleigh;
    p.config.source_level_db = 0; // 10^(SL/10) = 1: intensity = clean * S
    Frame f = vksonar::testing::host_stage_frame(p);
    std::fill(f.clean.begin(), f.clean.end(), 1.0f);
    host::noise_and_gain(p, 1, 0, f);
    const Moments m = moments(f.intensity.size(), [&](std::size_t i) { return double(f.intensity[i]); });
    const double n = static_cast<double>(f.intensity.size());
    EXPECT_NEAR(m.mean, 1.0, 5.0 / std::sqrt(n)); // see HostRng.Exp1MeanAndVariance
    EXPECT_NEAR(m.var, 1.0, 5.0 * std::sqrt(8.0 / n));
}

TEST(HostNoise, GammaAndGaussianSpeckleModels) {
    Plan p = test_plan(512, 256, 130, 0.5, 40);
    p.effects.speckle = true;
    p.config.source_level_db = 0;
    Frame f = vksonar::testing::host_stage_frame(p);
    std::fill(f.clean.begin(), f.clean.end(), 1.0f);
    const double n = static_cast<double>(f.clean.size());

    p.config.speckle = SpeckleModel::gamma;
    p.config.speckle_looks = 4;
    host::noise_and_gain(p, 2, 0, f);
    Moments m = moments(f.intensity.size(), [&](std::size_t i) { return double(f.intensity[i]); });
    EXPECT_NEAR(m.mean, 1.0, 5.0 * std::sqrt(0.25 / n));
    EXPECT_NEAR(m.var, 0.25, 5.0 * std::sqrt(14.0 / 64.0 / n)); // (2L + 6)/L^3 = 14/64

    p.config.speckle = SpeckleModel::gaussian;
    p.config.speckle_gaussian_sigma = 0.1;
    host::noise_and_gain(p, 2, 0, f);
    m = moments(f.intensity.size(), [&](std::size_t i) { return double(f.intensity[i]); });
    // |N(1, 0.1)|: folding at 0 is 10 sigma away, so mean 1, variance 0.01; Var((X-1)^2) = 2 sigma^4.
    EXPECT_NEAR(m.mean, 1.0, 5.0 * 0.1 / std::sqrt(n));
    EXPECT_NEAR(m.var, 0.01, 5.0 * std::sqrt(2e-4 / n));
    for (float v : f.intensity)
        ASSERT_GE(v, 0.0f);
}

TEST(HostNoise, DbOfZeroIsTheFloorNeverNaN) {
    Plan p = test_plan(16, 16, 90, 1, 10);
    p.effects.speckle = true; // no ambient noise: zero echo stays exactly zero
    Frame f = vksonar::testing::host_stage_frame(p);
    f.clean[3] = std::nanf("");
    f.clean[4] = -1.0f;
    f.clean[5] = std::numeric_limits<float>::infinity();
    host::noise_and_gain(p, 1, 1, f);
    for (std::size_t i = 0; i < f.clean.size(); ++i) {
        ASSERT_TRUE(std::isfinite(f.intensity[i])) << i;
        ASSERT_TRUE(std::isfinite(f.display[i])) << i;
        ASSERT_GE(f.display[i], 0.0f);
        ASSERT_LE(f.display[i], 1.0f);
        if (i != 5) {
            EXPECT_EQ(f.intensity[i], 0.0f) << i;
            EXPECT_EQ(f.display[i], 0.0f) << i;
        }
    }
    EXPECT_EQ(f.display[5], 1.0f); // infinite echo saturates
}

TEST(HostNoise, DisplayWindowMapsDbMinToZeroAndDbMaxToOne) {
    Plan p = test_plan(5, 1, 90, 1, 10);
    p.config.source_level_db = 100;
    p.config.db_min = 60;
    p.config.db_max = 140;
    Frame f = vksonar::testing::host_stage_frame(p);
    // Received levels (dB re 1 uPa) = 100 + 10 log10(clean).
    const double levels[5] = {40, 60, 100, 140, 180};
    for (int j = 0; j < 5; ++j)
        f.clean[j] = static_cast<float>(std::pow(10.0, (levels[j] - 100.0) / 10.0));
    host::noise_and_gain(p, 0, 0, f);
    // Tolerance: clean is float (relative 6e-8 -> 2.6e-7 dB -> 3e-9 in display); 1e-6 covers it.
    EXPECT_EQ(f.display[0], 0.0f);
    EXPECT_NEAR(f.display[1], 0.0, 1e-6);
    EXPECT_NEAR(f.display[2], 0.5, 1e-6);
    EXPECT_NEAR(f.display[3], 1.0, 1e-6);
    EXPECT_EQ(f.display[4], 1.0f);
    EXPECT_NEAR(f.intensity[2], 1e10, 1e10 * 1e-6);
}

TEST(HostNoise, TvgGainFollowsLogRangePlusAbsorption) {
    Plan p = test_plan(2, 8, 90, 1, 100);
    p.effects.tvg = true;
    p.config.tvg_db_per_decade = 20;
    p.alpha_db_per_m = 0.05;
    p.config.source_level_db = 0;
    Frame f = vksonar::testing::host_stage_frame(p);
    std::fill(f.clean.begin(), f.clean.end(), 1.0f);
    host::noise_and_gain(p, 0, 0, f);
    for (std::uint32_t k = 0; k < p.bins; ++k) {
        const double r = p.bin_range_m[k];
        const double expect = std::pow(10.0, (20.0 * std::log10(r) + 2.0 * 0.05 * r) / 10.0);
        // Float storage: relative 1e-6 is a few float ulps.
        EXPECT_NEAR(f.intensity[k * 2] / expect, 1.0, 1e-6) << "bin " << k;
    }
}

// --------------------------------------------------------------------------------------- colormaps

TEST(HostColormap, Endpoints) {
    auto eq = [](host::Rgb8 c, int r, int g, int b, int tol) {
        return std::abs(c.r - r) <= tol && std::abs(c.g - g) <= tol && std::abs(c.b - b) <= tol;
    };
    EXPECT_TRUE(eq(host::colormap(Colormap::gray, 0.0f), 0, 0, 0, 0));
    EXPECT_TRUE(eq(host::colormap(Colormap::gray, 1.0f), 255, 255, 255, 0));
    EXPECT_TRUE(eq(host::colormap(Colormap::gray, 0.5f), 128, 128, 128, 1));
    // matplotlib viridis: #440154 and #fde725; the middle is #21918c (interpolated table: +-2 levels).
    EXPECT_TRUE(eq(host::colormap(Colormap::viridis, 0.0f), 68, 1, 84, 1));
    EXPECT_TRUE(eq(host::colormap(Colormap::viridis, 1.0f), 253, 231, 37, 1));
    EXPECT_TRUE(eq(host::colormap(Colormap::viridis, 0.5f), 33, 145, 140, 2));
    // MATLAB jet: (0, 0, 0.5) -> (0.5, 0, 0), green at 0.5.
    EXPECT_TRUE(eq(host::colormap(Colormap::jet, 0.0f), 0, 0, 128, 1));
    EXPECT_TRUE(eq(host::colormap(Colormap::jet, 1.0f), 128, 0, 0, 1));
    EXPECT_TRUE(eq(host::colormap(Colormap::jet, 0.5f), 128, 255, 128, 1));
    // Sonar: black to a pale yellow.
    EXPECT_TRUE(eq(host::colormap(Colormap::sonar, 0.0f), 0, 0, 0, 0));
    const host::Rgb8 top = host::colormap(Colormap::sonar, 1.0f);
    EXPECT_GE(top.r, 240);
    EXPECT_GE(top.g, 230);
    EXPECT_GE(top.b, 180);
    // Out of range and NaN clamp.
    for (Colormap map : {Colormap::gray, Colormap::viridis, Colormap::sonar, Colormap::jet}) {
        const host::Rgb8 a = host::colormap(map, 0.0f), b = host::colormap(map, std::nanf(""));
        const host::Rgb8 c = host::colormap(map, -3.0f), d = host::colormap(map, 1.0f), e = host::colormap(map, 7.0f);
        EXPECT_TRUE(a.r == b.r && a.g == b.g && a.b == b.b);
        EXPECT_TRUE(a.r == c.r && a.g == c.g && a.b == c.b);
        EXPECT_TRUE(d.r == e.r && d.g == e.g && d.b == e.b);
    }
}

TEST(HostColormap, GraySonarViridisGetBrighterMonotonically) {
    for (Colormap map : {Colormap::gray, Colormap::sonar, Colormap::viridis}) {
        double prev = -1;
        for (int i = 0; i <= 255; ++i) {
            const host::Rgb8 c = host::colormap(map, i / 255.0f);
            const double luma = 0.2126 * c.r + 0.7152 * c.g + 0.0722 * c.b;
            EXPECT_GE(luma, prev - 0.5) << "map " << int(map) << " at " << i; // 0.5: rounding of 8-bit channels
            prev = luma;
        }
    }
}

// ------------------------------------------------------------------------------------------ images

TEST(HostImages, PolarImageFarRangeOnTopPortOnLeft) {
    Plan p = test_plan(8, 6, 90, 1, 10);
    p.config.colormap = Colormap::gray;
    Frame f = vksonar::testing::host_stage_frame(p);
    f.display[5 * 8 + 1] = 1.0f; // far bin, port-side beam 1
    host::Image img;
    host::polar_image(p, f, img);
    ASSERT_EQ(img.width, 8u);
    ASSERT_EQ(img.height, 6u);
    ASSERT_EQ(img.rgb.size(), 8u * 6u * 3u);
    for (std::uint32_t y = 0; y < 6; ++y)
        for (std::uint32_t x = 0; x < 8; ++x)
            EXPECT_EQ(img.rgb[(y * 8 + x) * 3], (y == 0 && x == 1) ? 255 : 0) << x << "," << y;
}

struct Lit {
    double x, y;
};
std::vector<Lit> pixels_where(const host::Image& img, bool (*pred)(const std::uint8_t*)) {
    std::vector<Lit> out;
    for (std::uint32_t y = 0; y < img.height; ++y)
        for (std::uint32_t x = 0; x < img.width; ++x)
            if (pred(&img.rgb[(static_cast<std::size_t>(y) * img.width + x) * 3])) out.push_back({x + 0.5, y + 0.5});
    return out;
}
bool not_background(const std::uint8_t* c) {
    return c[0] > 40 || c[1] > 40 || c[2] > 40;
}

TEST(HostImages, FanSingleBrightCellLightsTheRightRadiusAndSide) {
    // Non-uniform (equisine) beam table, so the lookup must use the table, not a uniform spacing.
    Plan p = test_plan(64, 100, 120, 0.01, 40, /*equisine=*/true);
    p.config.colormap = Colormap::sonar;
    const host::FanRenderer fan(p);
    ASSERT_EQ(fan.width(), 400u);
    ASSERT_GT(fan.height(), 100u);

    // Geometry from the image itself: the full fan's top (range_max at azimuth 0) and its apex.
    Frame full = vksonar::testing::host_stage_frame(p);
    std::fill(full.display.begin(), full.display.end(), 1.0f);
    host::Image img;
    fan.render(full, img);
    ASSERT_EQ(img.width, fan.width());
    ASSERT_EQ(img.height, fan.height());
    const auto fan_px = pixels_where(img, not_background);
    ASSERT_FALSE(fan_px.empty());
    double top = 1e9, bottom = -1e9, left = 1e9, right = -1e9;
    for (const Lit& l : fan_px) {
        top = std::min(top, l.y);
        bottom = std::max(bottom, l.y);
        left = std::min(left, l.x);
        right = std::max(right, l.x);
    }
    const double cx = 0.5 * img.width, cy = bottom; // apex: bottom centre (range_min is ~0)
    const double scale = (cy - top) / 40.0;         // pixels per metre
    // The fan is symmetric and +-60 deg wide: half-width R sin 60 (2 px: line width and rounding).
    EXPECT_NEAR(cx - left, 40.0 * std::sin(kPi / 3) * scale, 2.0);
    EXPECT_NEAR(right - cx, 40.0 * std::sin(kPi / 3) * scale, 2.0);

    // A single bright cell changes exactly the pixels whose bilinear support contains it: within one
    // bin and one beam step of the cell centre.
    Frame zero = vksonar::testing::host_stage_frame(p);
    host::Image img0;
    fan.render(zero, img0);
    const std::uint32_t bin = 60;
    for (std::uint32_t beam : {6u, 57u}) { // port, starboard
        SCOPED_TRACE("beam " + std::to_string(beam));
        Frame f = vksonar::testing::host_stage_frame(p);
        f.display[bin * p.beams + beam] = 1.0f;
        const std::uint8_t* before = img.rgb.data();
        fan.render(f, img);
        EXPECT_EQ(before, img.rgb.data()); // render reuses the image
        std::vector<Lit> lit;
        double brightest = 0;
        Lit peak{0, 0};
        for (std::uint32_t y = 0; y < img.height; ++y)
            for (std::uint32_t x = 0; x < img.width; ++x) {
                const std::size_t i = (static_cast<std::size_t>(y) * img.width + x) * 3;
                if (std::memcmp(&img.rgb[i], &img0.rgb[i], 3) == 0) continue;
                lit.push_back({x + 0.5, y + 0.5});
                if (img.rgb[i] + img.rgb[i + 1] > brightest) {
                    brightest = img.rgb[i] + img.rgb[i + 1];
                    peak = lit.back();
                }
            }
        ASSERT_GT(lit.size(), 4u);
        const double r_cell = p.bin_range_m[bin], az_cell = p.beam_angle_rad[beam];
        const double az_step =
            std::max(std::abs(p.beam_angle_rad[beam - 1] - az_cell), std::abs(p.beam_angle_rad[beam + 1] - az_cell));
        // 2 px: the apex/scale estimate from the image and the pixel size.
        const double r_tol = p.bin_width_m + 2.0 / scale, az_tol = az_step + 2.0 / (scale * r_cell);
        for (const Lit& l : lit) {
            const double x_fwd = (cy - l.y) / scale, y_port = (cx - l.x) / scale;
            EXPECT_NEAR(std::hypot(x_fwd, y_port), r_cell, r_tol);
            EXPECT_NEAR(std::atan2(y_port, x_fwd), az_cell, az_tol);
            if (beam < 32)
                EXPECT_LT(l.x, cx); // port on the left
            else
                EXPECT_GT(l.x, cx);
        }
        // The brightest pixel sits at the cell centre (half a bin / half a beam step + 2 px).
        const double x_fwd = (cy - peak.y) / scale, y_port = (cx - peak.x) / scale;
        EXPECT_NEAR(std::hypot(x_fwd, y_port), r_cell, 0.5 * p.bin_width_m + 2.0 / scale);
        EXPECT_NEAR(std::atan2(y_port, x_fwd), az_cell, 0.5 * az_step + 2.0 / (scale * r_cell));
    }
}

TEST(HostImages, FanWiderThan180IsSquareAndCentred) {
    Plan p = test_plan(90, 50, 360, 0.5, 20);
    const host::FanRenderer fan(p);
    EXPECT_EQ(fan.width(), fan.height());
    Frame f = vksonar::testing::host_stage_frame(p);
    host::Image img0, img;
    fan.render(f, img0);
    // A ring across all beams at one bin: lit all around the centre, including behind the sonar.
    for (std::uint32_t j = 0; j < p.beams; ++j)
        f.display[25 * p.beams + j] = 1.0f;
    fan.render(f, img);
    const double c = 0.5 * img.width;
    int ahead = 0, behind = 0, port = 0, starboard = 0;
    for (std::uint32_t y = 0; y < img.height; ++y)
        for (std::uint32_t x = 0; x < img.width; ++x) {
            const std::size_t i = (static_cast<std::size_t>(y) * img.width + x) * 3;
            if (std::memcmp(&img.rgb[i], &img0.rgb[i], 3) == 0) continue;
            ahead += y + 0.5 < c - 10;
            behind += y + 0.5 > c + 10;
            port += x + 0.5 < c - 10;
            starboard += x + 0.5 > c + 10;
        }
    EXPECT_GT(ahead, 0);
    EXPECT_GT(behind, 0);
    EXPECT_GT(port, 0);
    EXPECT_GT(starboard, 0);
}

#if defined(__linux__)
// The default thread count follows the CPUs the process may run on (a Slurm task's, taskset's), not the
// machine's: a Workers made by a thread confined to one CPU has one thread. (Affinity is per thread on
// Linux; this thread's mask is put back afterwards.)
TEST(HostWorkers, DefaultCountFollowsTheAffinityMask) {
    cpu_set_t all;
    ASSERT_EQ(sched_getaffinity(0, sizeof all, &all), 0);
    EXPECT_EQ(host::usable_cpus(), static_cast<std::uint32_t>(CPU_COUNT(&all)));
    int first = 0;
    while (!CPU_ISSET(first, &all))
        ++first;
    cpu_set_t one;
    CPU_ZERO(&one);
    CPU_SET(first, &one);
    ASSERT_EQ(sched_setaffinity(0, sizeof one, &one), 0);
    const std::uint32_t confined = host::usable_cpus();
    const std::uint32_t threads = host::Workers().count();
    ASSERT_EQ(sched_setaffinity(0, sizeof all, &all), 0);
    EXPECT_EQ(confined, 1u);
    EXPECT_EQ(threads, 1u);
}
#endif

// The fan image in bands of rows on 3 threads (the CLI's writer on a machine with 6+ cores): the same
// bytes as on one, for every colormap (each has its own loop) and a scan with NaN and out-of-range cells.
// The fan lookup's search (locate_in_table) walks from a hint: whatever the hint, it must find the interval a
// plain scan finds, the last entry "before" x (below it, or above it for a decreasing table), and the same
// fraction, for monotonic tables with equal neighbours, two entries, values on the entries and beyond the
// ends. A walk that stopped one entry short fails at once (the hint only shortens the walk).
TEST(HostImages, FanLookupSearchFindsThePlainScansInterval) {
    std::uint32_t state = 2024;
    const auto next = [&state] {
        state = state * 1664525u + 1013904223u;
        return state >> 8;
    };
    std::size_t checked = 0;
    for (int table_index = 0; table_index < 400; ++table_index) {
        const std::size_t n = 1 + next() % 40;
        const bool decreasing = next() % 2 == 0;
        std::vector<double> table(n);
        double v = -5.0 + 0.01 * (next() % 1000);
        for (std::size_t i = 0; i < n; ++i) {
            table[i] = v;
            const double step = next() % 5 == 0 ? 0.0 : 0.001 * (1 + next() % 900); // some equal neighbours
            v += decreasing ? -step : step;
        }
        std::int32_t hint = static_cast<std::int32_t>(next() % 60) - 10; // also negative and past the end
        for (int q = 0; q < 60; ++q) {
            const double x =
                next() % 4 == 0 ? table[next() % n]
                                : table.front() + (table.back() - table.front()) * (-0.2 + 1.4e-6 * (next() % 1000000));
            const auto before = [decreasing](double a, double b) { return decreasing ? a > b : a < b; };
            std::int32_t want_i0 = 0;
            float want_t = 0.0f;
            if (n > 1 && before(table[0], x) && before(x, table[n - 1])) {
                std::size_t lo = 0;
                for (std::size_t i = 0; i < n; ++i)
                    if (before(table[i], x)) lo = i;
                want_i0 = static_cast<std::int32_t>(lo);
                const double span = table[lo + 1] - table[lo];
                want_t = span != 0.0 ? static_cast<float>(std::clamp((x - table[lo]) / span, 0.0, 1.0)) : 0.0f;
            } else if (n > 1 && !before(x, table[n - 1]) && before(table[0], x)) {
                want_i0 = static_cast<std::int32_t>(n - 1);
            }
            std::int32_t i0 = -7;
            float t = -1.0f;
            host::locate_in_table(table, n, x, decreasing, i0, t, hint);
            ASSERT_EQ(i0, want_i0) << "table " << table_index << ", n " << n << ", x " << x;
            ASSERT_EQ(t, want_t) << "table " << table_index << ", x " << x;
            ++checked;
        }
    }
    EXPECT_EQ(checked, 400u * 60u);
}

TEST(HostImages, FanOnSeveralThreadsGivesTheSameBytes) {
    // a full circle's lookup (across the seam) and its nearest cells, built alone and on threads
    {
        host::Workers two(2);
        Plan circle = test_plan(90, 50, 360, 0.5, 30, /*equisine=*/false);
        circle.config.fan_width_px = 300;
        const host::FanRenderer alone(circle), shared(circle, &two);
        std::vector<std::uint16_t> cells(std::size_t(circle.beams) * circle.bins), a, b;
        for (std::size_t i = 0; i < cells.size(); ++i)
            cells[i] = static_cast<std::uint16_t>(1 + i % 65000);
        alone.nearest_cell(cells, a);
        shared.nearest_cell(cells, b);
        EXPECT_EQ(a, b);
        EXPECT_GT(std::count_if(a.begin(), a.end(), [](std::uint16_t id) { return id != 0; }), 1000);
    }
    host::Workers three(3);
    for (Colormap map : {Colormap::gray, Colormap::viridis, Colormap::sonar, Colormap::jet}) {
        Plan p = test_plan(64, 100, 120, 0.01, 40, /*equisine=*/true);
        p.config.colormap = map;
        const host::FanRenderer fan(p);
        Frame f = vksonar::testing::host_stage_frame(p);
        for (std::size_t i = 0; i < f.display.size(); ++i)
            f.display[i] = static_cast<float>((i * 37) % 101) / 80.0f - 0.1f; // [-0.1, 1.15]
        f.display[5] = std::numeric_limits<float>::quiet_NaN();
        host::Image alone, shared, built_shared;
        fan.render(f, alone);
        fan.render(f, shared, &three);
        ASSERT_EQ(alone.width, shared.width);
        EXPECT_EQ(alone.rgb, shared.rgb) << int(map);
        // the lookup built on the threads, band by band: the same tables
        const host::FanRenderer fan_built_shared(p, &three);
        fan_built_shared.render(f, built_shared);
        EXPECT_EQ(alone.rgb, built_shared.rgb) << int(map);
        const std::size_t middle = (std::size_t(alone.height / 2) * alone.width + alone.width / 2) * 3;
        EXPECT_FALSE(std::equal(alone.rgb.begin(), alone.rgb.begin() + 3, alone.rgb.begin() + middle))
            << "corner (background) and fan centre differ";
    }
}

// instance_fan.png's colours (label_image) depend on the id alone: black for 0, each channel in
// [64, 255] for the others, the same colour for an id wherever it is, whatever its neighbours (runs of
// one id, an id coming back after another, single pixels), and different colours for the ids used here.
TEST(HostImages, LabelColoursDependOnTheIdAlone) {
    const std::uint32_t width = 29, height = 7;
    std::vector<std::uint16_t> ids(std::size_t(width) * height);
    std::uint32_t state = 12345;
    for (std::size_t p = 0; p < ids.size();) {
        state = state * 1664525u + 1013904223u;
        const std::uint16_t id = static_cast<std::uint16_t>((state >> 24) % 5 == 0 ? 0 : 1 + (state >> 16) % 9);
        for (std::uint32_t n = 1 + (state >> 8) % 6; n > 0 && p < ids.size(); --n, ++p)
            ids[p] = id;
    }
    host::Image image, one;
    host::label_image(ids, width, height, image);
    std::vector<std::vector<std::uint8_t>> colour_of(10);
    for (std::uint16_t id = 0; id < 10; ++id) {
        host::label_image({id}, 1, 1, one);
        colour_of[id] = one.rgb;
        for (std::uint8_t channel : one.rgb)
            EXPECT_TRUE(id == 0 ? channel == 0 : channel >= 64) << id;
        for (std::uint16_t other = 1; other < id; ++other)
            EXPECT_NE(colour_of[other], colour_of[id]) << other << " and " << id;
    }
    for (std::size_t p = 0; p < ids.size(); ++p) {
        const std::vector<std::uint8_t> pixel(image.rgb.begin() + 3 * p, image.rgb.begin() + 3 * p + 3);
        EXPECT_EQ(pixel, colour_of[ids[p]]) << "pixel " << p << ", id " << ids[p];
    }
}

// ------------------------------------------------------------------------------------------- files

TEST(HostFiles, NpyHeaderShapeAndSize) {
    const std::string dir = temp_dir();
    std::vector<float> data(3 * 5 * 2);
    for (std::size_t i = 0; i < data.size(); ++i)
        data[i] = static_cast<float>(i) * 0.5f;
    for (std::uint32_t channels : {1u, 2u}) {
        const std::string path = dir + "/a" + std::to_string(channels) + ".npy";
        ASSERT_TRUE(host::write_npy_f32(path, data.data(), 3, 5, channels).ok());
        const std::string s = slurp(path);
        ASSERT_GE(s.size(), 10u);
        EXPECT_EQ(s.substr(0, 6), std::string("\x93NUMPY", 6));
        EXPECT_EQ(s[6], 1);
        EXPECT_EQ(s[7], 0);
        const std::size_t hl = static_cast<unsigned char>(s[8]) | (static_cast<unsigned char>(s[9]) << 8);
        EXPECT_EQ((10 + hl) % 64, 0u); // data aligned as numpy writes it
        const std::string dict = s.substr(10, hl);
        EXPECT_NE(dict.find("'descr': '<f4'"), std::string::npos) << dict;
        EXPECT_NE(dict.find("'fortran_order': False"), std::string::npos) << dict;
        EXPECT_NE(dict.find(channels == 1 ? "'shape': (3, 5)" : "'shape': (3, 5, 2)"), std::string::npos) << dict;
        EXPECT_EQ(dict.back(), '\n');
        const std::size_t n = 15u * channels;
        ASSERT_EQ(s.size(), 10 + hl + 4 * n);
        std::vector<float> back(n);
        std::memcpy(back.data(), s.data() + 10 + hl, 4 * n);
        EXPECT_TRUE(std::equal(back.begin(), back.end(), data.begin()));
    }
    std::vector<std::uint16_t> q(4 * 7, 513);
    const std::string path = dir + "/q.npy";
    ASSERT_TRUE(host::write_npy_u16(path, q.data(), 4, 7).ok());
    const std::string s = slurp(path);
    const std::size_t hl = static_cast<unsigned char>(s[8]) | (static_cast<unsigned char>(s[9]) << 8);
    EXPECT_NE(s.find("'descr': '<u2'"), std::string::npos);
    EXPECT_NE(s.find("'shape': (4, 7)"), std::string::npos);
    EXPECT_EQ(s.size(), 10 + hl + 2 * q.size());
    EXPECT_EQ(static_cast<unsigned char>(s[10 + hl]), 1u); // 513 = 0x0201, little-endian
    EXPECT_EQ(static_cast<unsigned char>(s[11 + hl]), 2u);
    fs::remove_all(dir);
}

TEST(HostFiles, PlyHeaderAndSize) {
    const std::string dir = temp_dir();
    Plan p = test_plan(4, 3, 90, 1, 4);
    Frame f = vksonar::testing::host_stage_frame(p);
    f.display[1 * 4 + 0] = 0.5f; // bin 1 (r = 2.5), beam 0 (port, +33.75 deg)
    f.intensity[1 * 4 + 0] = 123.0f;
    f.display[2 * 4 + 3] = 1.0f;
    f.intensity[2 * 4 + 3] = 7.0f;
    const std::string path = dir + "/c.ply";
    ASSERT_TRUE(host::write_cloud_ply(path, p, f).ok());
    const std::string s = slurp(path);
    const std::string end = "end_header\n";
    const std::size_t hdr = s.find(end);
    ASSERT_NE(hdr, std::string::npos);
    const std::string header = s.substr(0, hdr + end.size());
    EXPECT_EQ(header.rfind("ply\nformat binary_little_endian 1.0\n", 0), 0u);
    EXPECT_NE(header.find("element vertex 2\n"), std::string::npos);
    const std::size_t px = header.find("property float x\n"), py = header.find("property float y\n"),
                      pz = header.find("property float z\n"), pi = header.find("property float intensity\n");
    ASSERT_TRUE(px != std::string::npos && py != std::string::npos && pz != std::string::npos &&
                pi != std::string::npos);
    EXPECT_TRUE(px < py && py < pz && pz < pi);
    ASSERT_EQ(s.size(), header.size() + 2 * 16);
    float v[8];
    std::memcpy(v, s.data() + header.size(), sizeof v);
    const double a = p.beam_angle_rad[0];
    const double r = p.bin_range_m[1];
    EXPECT_NEAR(v[0], r * std::cos(a), 1e-5); // float storage of values ~2
    EXPECT_NEAR(v[1], r * std::sin(a), 1e-5);
    EXPECT_GT(v[1], 0.0f); // port = +y
    EXPECT_EQ(v[2], 0.0f);
    EXPECT_EQ(v[3], 123.0f);
    EXPECT_LT(v[5], 0.0f); // starboard beam
    EXPECT_EQ(v[7], 7.0f);
    fs::remove_all(dir);
}

TEST(HostFiles, MetaJsonFields) {
    const std::string dir = temp_dir();
    Plan p = test_plan(3, 4, 90, 1, 5);
    Frame f = vksonar::testing::host_stage_frame(p);
    f.seed = 77;
    f.frame_index = 5;
    f.times = {{"depth", 1.5}, {"noise", 0.25}};
    f.stages_run = {"depth", "noise"};
    const std::string path = dir + "/meta.json";
    ASSERT_TRUE(host::write_meta_json(path, p, f, R"({"config": {"name": "test"}})").ok());
    const auto m = nlohmann::json::parse(slurp(path));
    EXPECT_EQ(m["format"], "vksonar-frame-1");
    EXPECT_EQ(m["beams"], 3);
    EXPECT_EQ(m["bins"], 4);
    EXPECT_EQ(m["seed"], 77);
    EXPECT_EQ(m["frame_index"], 5);
    ASSERT_EQ(m["beam_angles_rad"].size(), 3u);
    ASSERT_EQ(m["ranges_m"].size(), 4u);
    EXPECT_DOUBLE_EQ(m["ranges_m"][0].get<double>(), 1.5);
    // Port beam 0 (+30 deg) in the ROS frame (Z forward, X up, Y right) points to -Y.
    EXPECT_NEAR(m["beam_directions"][0]["y"].get<double>(), -0.5, 1e-12);
    EXPECT_NEAR(m["beam_directions"][0]["z"].get<double>(), std::cos(kPi / 6), 1e-12);
    EXPECT_EQ(m["beam_directions"][0]["x"].get<double>(), 0.0);
    EXPECT_EQ(m["tx_beamwidths_rad"].size(), 3u);
    EXPECT_EQ(m["rx_beamwidths_rad"].size(), 3u);
    EXPECT_EQ(m["effects"]["speckle"]["on"], false);
    EXPECT_EQ(m["effects"]["ambient_noise"]["why"], "test");
    EXPECT_DOUBLE_EQ(m["timings_ms"]["depth"].get<double>(), 1.5);
    EXPECT_EQ(m["stages_run"].size(), 2u);
    EXPECT_EQ(m["config"]["name"], "test");
    EXPECT_TRUE(m.contains("frame_convention"));
    EXPECT_TRUE(m.contains("polar_layout"));
    EXPECT_TRUE(m.contains("intensity_unit"));
    EXPECT_FALSE(host::write_meta_json(dir + "/bad.json", p, f, "[1, 2").ok());
    fs::remove_all(dir);
}

TEST(HostFiles, PngRoundTripSizeAndErrorsNameThePath) {
    const std::string dir = temp_dir();
    host::Image img;
    img.width = 7;
    img.height = 3;
    img.rgb.assign(7 * 3 * 3, 200);
    const std::string path = dir + "/x.png";
    ASSERT_TRUE(host::write_png(path, img).ok());
    const std::string s = slurp(path);
    ASSERT_GT(s.size(), 24u);
    EXPECT_EQ(s.substr(1, 3), "PNG");
    EXPECT_EQ(static_cast<unsigned char>(s[19]), 7u); // IHDR width (big-endian)
    EXPECT_EQ(static_cast<unsigned char>(s[23]), 3u); // IHDR height

    const std::string bad = dir + "/no/such/dir/fan.png";
    const auto r = host::write_png(bad, img);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find(bad), std::string::npos) << r.error().message;
    EXPECT_NE(r.error().message.find("No such file"), std::string::npos) << r.error().message;
    const float one = 1.0f;
    const auto r2 = host::write_npy_f32(dir + "/no/a.npy", &one, 1, 1);
    ASSERT_FALSE(r2.ok());
    EXPECT_NE(r2.error().message.find(dir + "/no/a.npy"), std::string::npos);
    fs::remove_all(dir);
}

// write_png's file decodes, by stb_image (a decoder independent of the encoder), to the pixels written;
// its chunks are IHDR first (the size, 8-bit RGB), IDAT, IEND last, each with the CRC-32 of its type and
// data (computed here bit by bit, as the PNG specification defines it). The image mixes speckle-like
// noise with a flat area and an odd width (no row is a multiple of anything).
TEST(HostFiles, PngDecodesToThePixelsWrittenAndEveryChunkChecksOut) {
    const std::string dir = temp_dir();
    host::Image img;
    img.width = 301;
    img.height = 173;
    img.rgb.resize(std::size_t(img.width) * img.height * 3);
    std::uint32_t state = 12345u;
    for (std::size_t i = 0; i < img.rgb.size(); ++i) {
        state = state * 1664525u + 1013904223u;
        const bool flat = i / (img.width * 3) >= 100;
        img.rgb[i] = flat ? static_cast<unsigned char>(40 + i % 3) : static_cast<unsigned char>(state >> 24);
    }
    const std::string path = dir + "/noise.png";
    ASSERT_TRUE(host::write_png(path, img).ok());
    const std::string s = slurp(path);
    const std::string signature("\x89PNG\r\n\x1a\n", 8);
    ASSERT_GT(s.size(), 8u);
    ASSERT_EQ(s.substr(0, 8), signature);
    auto be32 = [&](std::size_t at) {
        std::uint32_t v = 0;
        for (std::size_t i = 0; i < 4; ++i)
            v = (v << 8) | static_cast<unsigned char>(s[at + i]);
        return v;
    };
    auto crc32 = [](const std::string& bytes) {
        std::uint32_t crc = 0xffffffffu;
        for (unsigned char b : bytes) {
            crc ^= b;
            for (int k = 0; k < 8; ++k)
                crc = (crc & 1u) ? (crc >> 1) ^ 0xedb88320u : crc >> 1;
        }
        return crc ^ 0xffffffffu;
    };
    std::vector<std::string> types;
    std::size_t at = 8;
    while (at + 12 <= s.size()) {
        const std::uint32_t length = be32(at);
        ASSERT_LE(at + 12 + length, s.size()) << "chunk " << types.size() << " runs past the file";
        const std::string type_and_data = s.substr(at + 4, 4 + length);
        types.push_back(type_and_data.substr(0, 4));
        EXPECT_EQ(crc32(type_and_data), be32(at + 8 + length)) << "CRC of chunk " << types.back();
        if (types.back() == "IHDR") {
            ASSERT_EQ(length, 13u);
            EXPECT_EQ(be32(at + 8), img.width);
            EXPECT_EQ(be32(at + 12), img.height);
            EXPECT_EQ(static_cast<unsigned char>(s[at + 16]), 8u); // bit depth
            EXPECT_EQ(static_cast<unsigned char>(s[at + 17]), 2u); // RGB
        }
        at += 12 + length;
    }
    EXPECT_EQ(at, s.size());
    ASSERT_GE(types.size(), 3u);
    EXPECT_EQ(types.front(), "IHDR");
    EXPECT_EQ(types.back(), "IEND");
    EXPECT_NE(std::find(types.begin(), types.end(), "IDAT"), types.end());

    int w = 0, h = 0, channels = 0;
    unsigned char* pixels = stbi_load_from_memory(reinterpret_cast<const unsigned char*>(s.data()),
                                                  static_cast<int>(s.size()), &w, &h, &channels, 3);
    ASSERT_NE(pixels, nullptr) << stbi_failure_reason();
    EXPECT_EQ(w, 301);
    EXPECT_EQ(h, 173);
    EXPECT_EQ(channels, 3);
    EXPECT_EQ(std::memcmp(pixels, img.rgb.data(), img.rgb.size()), 0);
    stbi_image_free(pixels);
    fs::remove_all(dir);
}

} // namespace
} // namespace vksonar
