// Hard cases (docs/hard_cases.md), energy: a very bright target beside a dark one, millions of pixels in one
// range bin, pixel solid angles converging as resolution doubles, energy in = energy out for a box
// vertical pattern, echo falling with range, and depth discontinuities (no Sobel spikes).
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "hard_cases/hard_support.h"

namespace vksonar::testing::hard {
namespace {

class EnergyCase : public HardCase {};

// ---- bright beside dark --------------------------------------------------------------------------

TEST_P(EnergyCase, BrightTargetBesideADarkOneAddsLinearlyWithBoundedSideLobes) {
    SonarConfig config = small_config();
    config.source_level_db = 260.0; // the loudest valid source, to look for overflow in the received intensity
    // The side lobes bounded by the kernel's reach (the far side lobes, which reach every beam, have
    // their own tests: tests/far_sidelobes_test.cpp).
    config.far_sidelobe_cell = 0.0;
    Scene bright, dark, both;
    const double dark_az = 14 * kDeg; // beyond the side-lobe reach (3 beamwidths = 6 deg) of the bright plate
    for (Scene* s : {&bright, &both})
        add_quad(*s, 10.0, 0.0, 0.0, 0.5, 0.5, 0.0, 0.0, AcousticMaterial::Model::constant); // brightest valid
    for (Scene* s : {&dark, &both})
        add_quad(*s, 10 * std::cos(dark_az), 10 * std::sin(dark_az), 0.0, 0.5, 0.5, -100.0, 14.0); // darkest valid
    auto b = render_checked(GetParam(), config, bright);
    auto d = render_checked(GetParam(), config, dark);
    auto s = render_checked(GetParam(), config, both);
    ASSERT_TRUE(b && d && s);
    const Plan& plan = renderer_plan(s->renderer);
    double peak_bright = 0, peak_dark = 0;
    for (std::size_t i = 0; i < s->frame.clean.size(); ++i) {
        peak_bright = std::max(peak_bright, double(b->frame.clean[i]));
        peak_dark = std::max(peak_dark, double(d->frame.clean[i]));
    }
    ASSERT_GT(peak_dark, 0.0);
    EXPECT_GT(peak_bright / peak_dark, 1e9) << "100 dB of contrast in the clean scan";
    // Superposition: the targets do not occlude each other and every stage is linear in the echo, so
    // both = bright + dark cell by cell, to float rounding of sums of a few hundred terms (1e-5 of
    // the cell, or of the dark peak for cells that are all bright side lobe).
    for (std::size_t i = 0; i < s->frame.clean.size(); ++i) {
        const double sum = double(b->frame.clean[i]) + d->frame.clean[i];
        ASSERT_NEAR(s->frame.clean[i], sum, 1e-5 * sum + 1e-6 * peak_dark) << "cell " << i;
    }
    // Side lobes are bounded by the kernel: beams farther than its reach from the bright plate's
    // beams get exactly nothing from it, so the dark target reads the same with or without it.
    const double reach = config.sidelobe_kernel_beamwidths * config.horizontal_beamwidth_deg * kDeg;
    const double half_extent = std::atan(0.25 / 10.0);
    const double spacing = plan.beam_angle_rad[0] - plan.beam_angle_rad[1];
    int dark_beams = 0;
    for (std::uint32_t j = 0; j < s->frame.beams; ++j) {
        if (std::abs(plan.beam_angle_rad[j]) <= half_extent + reach + 2 * spacing) continue;
        ASSERT_EQ(beam_energy(b->frame, j), 0.0) << "beam " << j;
        if (beam_energy(d->frame, j) > 0) {
            ++dark_beams;
            for (std::uint32_t k = 0; k < s->frame.bins; ++k)
                ASSERT_EQ(s->frame.clean[k * s->frame.beams + j], d->frame.clean[k * s->frame.beams + j]);
        }
    }
    EXPECT_GT(dark_beams, 1);
    // Inside the reach the bright plate does leak (the side-lobe kernel is active): some beam beside
    // the plate, but within the reach, holds bright energy.
    double leaked = 0;
    for (std::uint32_t j = 0; j < s->frame.beams; ++j) {
        const double off = std::abs(plan.beam_angle_rad[j]);
        if (off > half_extent + 2 * spacing && off < half_extent + reach) leaked += beam_energy(b->frame, j);
    }
    EXPECT_GT(leaked, 0.0);
    // And the received intensity at 260 dB SL stays finite (checked by render_checked) and exact:
    // I = 10^(SL/10) clean with noise off.
    const std::size_t at = std::max_element(s->frame.clean.begin(), s->frame.clean.end()) - s->frame.clean.begin();
    EXPECT_NEAR(s->frame.intensity[at] / (1e26 * s->frame.clean[at]), 1.0, 1e-6);
}

// ---- millions of pixels into one bin --------------------------------------------------------------

// Exact solid angle of a rectangular pyramid with half-angle tangents a and b: 4 asin(sin A sin B).
double frustum_solid_angle(double tan_a, double tan_b) {
    return 4 * std::asin(std::sin(std::atan(tan_a)) * std::sin(std::atan(tan_b)));
}

TEST_P(EnergyCase, TwoMillionPixelsInOneRangeBinAccumulateWithoutLoss) {
    // The sonar at the centre of a sphere of radius 10 m: every pixel of a 1920 x 1024 grid returns
    // from r = 10 m, which is the centre of bin 4 of [1, 19] m in 2 m bins, and a single beam takes
    // every column: ~2e6 pixels into one cell.
    SonarConfig config = small_config();
    config.hfov_deg = 120.0; // 2 slices of 60 deg
    config.beams = 1;
    config.horizontal_beamwidth_deg = 1.0;
    config.pixels_per_beam = 16.0; // 16 * 120 / 1 = 1920 columns
    config.rows_per_vfov = 512;    // 1024 rows over 40 deg
    config.bins = 9;
    config.range_min_m = 1.0;
    config.range_max_m = 19.0;
    config.effects.incidence = EffectMode::off; // constant model: every pixel counts the same
    config.effects.vertical_pattern = EffectMode::off;
    config.effects.absorption = EffectMode::off;
    const double mu_db = -20.0, radius = 10.0;
    Scene scene;
    add_sphere(scene, radius, 256, 128, mu_db);
    auto r = render_once(GetParam(), config, scene); // intermediates not kept: 2e6 pixels
    ASSERT_TRUE(r);
    expect_every_stage_finite(r->frame);
    const Plan& plan = renderer_plan(r->renderer);
    const Frame& f = r->frame;
    ASSERT_EQ(f.beams, 1u);
    const std::size_t pixels = std::size_t(plan.rows) * plan.columns;
    std::printf("[one bin] %zu pixels (%u x %u)\n", pixels, plan.columns, plan.rows);
    EXPECT_GT(pixels, 1900000u);
    // Closed form: mu / R^2 times the sum of pixel solid angles = the slices' frustum solid angle. The
    // midpoint rule on 1920 x 1024 pixels is exact to ~1e-7; the facets lie inside the sphere by up
    // to R (1 - cos(half-diagonal 1.0 deg)) = 1.5e-4 R: up to 3.0e-4 more energy; float sums of 1024
    // rows then 1920 columns: worst case (1024 + 1920) 2^-24 = 1.8e-4. Total 4.8e-4.
    const double expected = std::pow(10.0, mu_db / 10.0) / (radius * radius) * plan.slices *
                            frustum_solid_angle(plan.tan_half_h, plan.tan_half_v);
    const double got = total(f.clean);
    const double in_bin = f.clean[4];
    EXPECT_NEAR(got / expected, 1.0, 4.8e-4);
    EXPECT_GE(in_bin / got, 0.999) << "the footprint kernel spreads only the facet range spread (1.5 mm)";
    // Precision of the accumulation alone: the same scene through the CPU reference in double. Same
    // pixels (lavapipe and the CPU rasterizer agree on this mesh's interior), so only the float sums
    // differ: within the worst-case bound (1024 + 1920) 2^-24 = 1.8e-4.
    config.cpu_precision = Precision::f64;
    auto reference = render_once(Backend::cpu, config, scene);
    ASSERT_TRUE(reference);
    const double exact_sum = total(reference->frame.clean);
    std::printf("[one bin] bin 4 holds %.6f of the energy; total / closed form - 1 = %.2e; "
                "total / double-precision sum - 1 = %.2e\n",
                in_bin / got, got / expected - 1, got / exact_sum - 1);
    EXPECT_NEAR(got / exact_sum, 1.0, 1.8e-4);
}

// ---- convergence and energy conservation ----------------------------------------------------------

// Sonar inside a closed box (every pixel hit), constant model, no incidence/absorption:
// E_p = mu Omega_p b_v(psi_p) / r_p^2, so sum_p E_p r_p^2 / mu = sum_p Omega_p b_v(psi_p).
double weighted_solid_angle(const Frame& f, double mu) {
    double s = 0;
    for (std::size_t p = 0; p < f.echo.size() / 2; ++p) {
        const double r = f.echo[2 * p + 1];
        s += f.echo[2 * p] * r * r / mu;
    }
    return s;
}

SonarConfig box_room_config(std::uint32_t rows_per_vfov, double pixels_per_beam) {
    SonarConfig config = small_config();
    config.hfov_deg = 120.0;
    config.beams = 64;
    config.rows_per_vfov = rows_per_vfov;
    config.pixels_per_beam = pixels_per_beam;
    config.effects.incidence = EffectMode::off;
    config.effects.absorption = EffectMode::off;
    config.effects.horizontal_pattern = EffectMode::off;
    return config;
}

TEST_P(EnergyCase, DoublingResolutionConvergesToTheExactSolidAngle) {
    const double mu_db = -20.0, mu = std::pow(10.0, mu_db / 10.0);
    Scene scene;
    add_box(scene, {-5, -5, -5}, {5, 5, 5}, mu_db, AcousticMaterial::Model::constant);
    double previous_error = 0;
    for (int level = 0; level < 4; ++level) {
        SonarConfig config = box_room_config(2u << level, 0.25 * (1 << level)); // 4..32 rows, 16..128 columns
        config.effects.vertical_pattern = EffectMode::off;
        auto r = render_checked(GetParam(), config, scene);
        ASSERT_TRUE(r);
        const Plan& plan = renderer_plan(r->renderer);
        const double exact = plan.slices * frustum_solid_angle(plan.tan_half_h, plan.tan_half_v);
        const double error = std::abs(weighted_solid_angle(r->frame, mu) / exact - 1);
        std::printf("[convergence] %u x %u pixels: solid angle rel error %.3e\n", plan.columns, plan.rows, error);
        // The midpoint rule is second order: doubling both axes divides the error by ~4; require 3
        // (and stop once it reaches float rounding of the per-pixel values, 1e-6).
        if (level > 0 && previous_error > 1e-6) {
            EXPECT_LT(error, previous_error / 3) << "level " << level;
        }
        previous_error = error;
    }
    EXPECT_LT(previous_error, 1e-3);
}

TEST_P(EnergyCase, EnergyInEqualsEnergyOutForABoxVerticalPattern) {
    // With a box vertical pattern of width vfov the pixels inside |psi| <= vfov/2 collect the band's
    // solid angle hfov * 2 sin(vfov/2) (the band lies inside every slice's frustum), and beamforming
    // with the horizontal pattern off moves that energy into the scan without loss.
    const double mu_db = -20.0, mu = std::pow(10.0, mu_db / 10.0);
    Scene scene;
    add_box(scene, {-5, -5, -5}, {5, 5, 5}, mu_db, AcousticMaterial::Model::constant);
    SonarConfig config = box_room_config(64, 4.0);
    config.vertical_pattern = BeamPattern::box;
    config.effects.vertical_pattern = EffectMode::on;
    auto r = render_checked(GetParam(), config, scene);
    ASSERT_TRUE(r);
    const Plan& plan = renderer_plan(r->renderer);
    const double band = config.hfov_deg * kDeg * 2 * std::sin(0.5 * config.vfov_deg * kDeg);
    const double got = weighted_solid_angle(r->frame, mu);
    // Pixel centres decide in or out along the band's two edges: at most half a row each, 1 / 64 of
    // the band's 64 rows.
    const double bound = 1.0 / config.rows_per_vfov;
    std::printf("[box pattern] band solid angle rel error %.2e (bound %.2e)\n", got / band - 1, bound);
    EXPECT_NEAR(got / band, 1.0, bound);
    const double in = echo_total(r->frame), out = total(r->frame.clean);
    // Every range (5..8.7 m) is inside the window; tent resampling weights sum to 1 per column. Float
    // sums over 128 rows then ~30 columns: 1e-5.
    EXPECT_NEAR(out / in, 1.0, 1e-5);
    EXPECT_NEAR(total(r->frame.beam_profiles) / in, 1.0, 1e-5);
    (void)plan;
}

// ---- range ---------------------------------------------------------------------------------------

TEST_P(EnergyCase, EchoOfTheSameTargetFallsWithRange) {
    SonarConfig config = small_config();
    config.effects.vertical_pattern = EffectMode::off;
    config.effects.horizontal_pattern = EffectMode::off;
    config.absorption_db_per_m = 0.1;
    config.pixels_per_beam = 16.0; // 1024 columns: 0.059 deg
    config.rows_per_vfov = 128;    // 256 rows: 0.156 deg
    const double ranges[] = {2, 4, 8, 16, 32};
    const double mu = std::pow(10.0, -20.0 / 10.0);
    double previous = 0, previous_reference = 0;
    for (int i = 0; i < 5; ++i) {
        Scene scene;
        add_quad(scene, ranges[i], 0.0, 0.0, 2.0, 2.0);
        auto r = render_checked(GetParam(), config, scene);
        ASSERT_TRUE(r);
        const Plan& plan = renderer_plan(r->renderer);
        const double e = total(r->frame.clean);
        const double reference = plate_reference(0.0, 1.0, ranges[i], mu, config.absorption_db_per_m);
        ASSERT_GT(e, 0.0);
        if (i > 0) {
            EXPECT_LT(e, previous) << ranges[i] << " m";
        }
        // From 4 m on the plate lies inside the vertical coverage and the ratio follows the integrated
        // model (40 log 2 + 2 alpha dr for a small plate, exactly integrated here). Pixel quantization:
        // half a pixel per edge at each of the two ranges.
        const double extent = 2 * std::atan(1.0 / ranges[i]);
        const double q = 1.0 / (extent / (config.hfov_deg * kDeg / plan.columns)) +
                         1.0 / (extent / (2 * std::atan(plan.tan_half_v) / plan.rows));
        if (i > 1) {
            std::printf("[range] %g -> %g m: %.3f dB, model %.3f dB\n", ranges[i - 1], ranges[i], to_db(previous / e),
                        to_db(previous_reference / reference));
            EXPECT_NEAR(to_db(previous / e), to_db(previous_reference / reference), 2 * to_db(1 + q))
                << ranges[i] << " m";
        }
        previous = e;
        previous_reference = reference;
    }
}

// Absorption of 9 to 30 dB/m over the bundled scene's seabed: the echoes fall to 1e-30 and below, and the
// footprint kernel's density slope, a ratio of products of two echoes and two widths, took 0 / 0 where
// both products underflowed: a NaN that the slope's cap kept, 5120 to 7168 NaN cells of `clean` in float
// on the CPU (lavapipe flushes denormals, and saw no slope there). Every stage stays finite, the scan is
// not empty, and the seabed's far half underflows to 0 rather than to NaN.
TEST_P(EnergyCase, StrongAbsorptionUnderflowsToZeroNotNaN) {
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    for (const double absorption : {9.0, 20.0}) {
        SCOPED_TRACE(absorption);
        SonarConfig config = quiet_config();
        config.absorption_db_per_m = absorption;
        Pose pose;
        pose.pitch_deg = 10.0;
        auto r = render_checked(GetParam(), config, scene.value(), pose);
        ASSERT_TRUE(r);
        EXPECT_GT(total(r->frame.clean), 0.0);
    }
}

// ---- depth discontinuities -----------------------------------------------------------------------

TEST_P(EnergyCase, DepthDiscontinuityGivesNoSobelSpikes) {
    // A box whose front face (x = 5) faces the sonar, in front of a wall at 20 m turned 25 deg. Every
    // pixel, on either side of the silhouette, must get the incidence of its own surface: the
    // contract's one-sided differences never mix the two surfaces. Bound: |cos - exact| <= 1e-3 (the
    // plane tolerance of tests/stages/normals_test.cpp), so no echo spike exceeds its surface by > 0.1%.
    SonarConfig config = small_config();
    config.rows_per_vfov = 32;
    Scene scene;
    add_box(scene, {5.0, -0.6, -0.4}, {6.0, 0.6, 0.4}, -20.0);
    add_quad(scene, 20.0, 0.0, 0.0, 80.0, 80.0, -30.0, 25.0);
    auto r = render_checked(GetParam(), config, scene);
    ASSERT_TRUE(r);
    const Plan& plan = renderer_plan(r->renderer);
    const Frame& f = r->frame;
    const std::uint32_t box_material = 1; // material 0 is the scene's implicit default
    ASSERT_EQ(scene.materials()[box_material].backscatter_db, -20.0);
    double max_err = 0, max_err_edge = 0;
    int edge_pixels = 0, box_pixels = 0;
    for (std::uint32_t j = 0; j < plan.rows; ++j)
        for (std::uint32_t c = 0; c < plan.columns; ++c) {
            const std::size_t p = std::size_t(j) * plan.columns + c;
            ASSERT_GT(f.depth[p], 0.0f);
            const double u = (2.0 * (c % plan.slice_columns + 0.5) / plan.slice_columns - 1) * plan.tan_half_h;
            const double v = (2.0 * (j + 0.5) / plan.rows - 1) * plan.tan_half_v;
            const double phi = plan.slice_info[c / plan.slice_columns].center_azimuth_rad;
            const double D[3] = {std::cos(phi) + u * std::sin(phi), std::sin(phi) - u * std::cos(phi), -v};
            const double len = std::sqrt(D[0] * D[0] + D[1] * D[1] + D[2] * D[2]);
            const bool is_box = f.material[p] == box_material;
            const double n[3] = {is_box ? -1.0 : -std::cos(25 * kDeg), is_box ? 0.0 : -std::sin(25 * kDeg), 0.0};
            const double exact = -(n[0] * D[0] + n[1] * D[1] + n[2] * D[2]) / len;
            const double err = std::abs(f.normals[4 * p + 3] - exact);
            bool edge = false;
            for (int dj = -1; dj <= 1; ++dj)
                for (int dc = -1; dc <= 1; ++dc) {
                    const int jj = int(j) + dj, cc = int(c) + dc;
                    if (jj >= 0 && cc >= 0 && jj < int(plan.rows) && cc < int(plan.columns))
                        edge |= (f.material[std::size_t(jj) * plan.columns + cc] == box_material) != is_box;
                }
            edge_pixels += edge;
            box_pixels += is_box;
            max_err = std::max(max_err, err);
            if (edge) max_err_edge = std::max(max_err_edge, err);
            EXPECT_LE(err, 1e-3) << (is_box ? "box" : "wall") << (edge ? " edge" : "") << " pixel " << c << "," << j;
        }
    std::printf("[sobel edges] %d edge pixels, max |cos - exact| %.2e (edges %.2e), bound 1e-3\n", edge_pixels, max_err,
                max_err_edge);
    EXPECT_GT(box_pixels, 50);
    EXPECT_GT(edge_pixels, 20);
}

INSTANTIATE_TEST_SUITE_P(Backends, EnergyCase, ::testing::Values(Backend::vulkan, Backend::cpu), backend_name);

} // namespace
} // namespace vksonar::testing::hard
