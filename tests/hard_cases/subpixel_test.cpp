// Hard cases of issue 17 item 6, "small and thin things keep their energy": an object smaller than a pixel
// returns what its area and material say, not zero and not a pixel's worth (docs/pipeline.md "Sub-pixel
// objects"). At the default (`balanced`) quality on both backends, with every effect that is not part of
// the closed form off (noise, speckle, absorption, both beam patterns).
//
// Energies are relative to the source level: the clean polar scan holds E / 10^(SL/10) (echo_energy,
// shaders/sonar_math.h, leaves SL out; the host adds it in dB with the noise), so the closed forms
// below, 10^(SL/10) mu (...), are compared without their 10^(SL/10).
//
// A Lambert sphere of radius a at range R (a << R): each surface element dA at incidence theta returns
// mu cos^2(theta) dA / R^4 (one cos from Lambert's f, one from the projected solid angle), and over the
// visible half, dA = 2 pi a^2 sin(theta) dtheta, integral cos^2 sin dtheta over [0, pi/2] = 1/3:
//   E = mu 2 pi a^2 / (3 R^4).
// A Lambert cylinder of radius a whose axis makes angle psi with the ray: a strip of its surface at angle
// phi around the axis from the ray's side has cos(theta) = cos(phi) sin(psi), so per unit length
//   dE/dl = mu a sin^2(psi) / r^4 * integral cos^2(phi) dphi over [-pi/2, pi/2] = mu a (pi / 2) sin^2(psi) / r^4.
// For a cable along y at x = X, z = 0 (the sonar at the origin), a point at steering angle theta has
// y = X tan(theta), r = X / cos(theta), sin(psi) = cos(theta), dl = X dtheta / cos^2(theta): per radian
// of steering angle dE/dtheta = mu a (pi / 2) X cos^4(theta) / X^4 = mu a (pi / 2) cos^4(theta) / X^3.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>
#include <vector>

#include "core/renderer_access.h"
#include "core/subpixel.h"
#include "hard_support.h"

namespace vksonar::testing::hard {
namespace {

SonarConfig closed_form_config() {
    SonarConfig c = quiet_config(); // the default preset at the default (balanced) quality, noise off
    c.effects.horizontal_pattern = EffectMode::off;
    c.effects.vertical_pattern = EffectMode::off;
    c.effects.absorption = EffectMode::off;
    c.effects.incidence = EffectMode::on;
    c.effects.spreading = EffectMode::on;
    return c;
}

AcousticMaterial lambert(double backscatter_db) {
    AcousticMaterial m;
    m.name = "lambert";
    m.backscatter_db = backscatter_db;
    m.model = AcousticMaterial::Model::lambert;
    return m;
}

// A closed UV sphere (one vertex per pole, counter-clockwise seen from outside, or with inside_out from
// inside) of radius r centred at c. pole_quads: the pole rows written as quads, as many exporters write
// them: a pole vertex per segment (all at the pole) and each quad's second triangle collapsed to a line.
void add_closed_sphere(Scene& scene, double r, const std::array<double, 3>& c, std::uint32_t segments,
                       std::uint32_t rings, const AcousticMaterial& material, bool inside_out = false,
                       bool pole_quads = false) {
    std::vector<float> p{0.0f, 0.0f, static_cast<float>(r)}; // north pole: vertex 0
    for (std::uint32_t i = 1; i < rings; ++i) {
        const double theta = kPi * i / rings;
        for (std::uint32_t j = 0; j < segments; ++j) {
            const double phi = 2 * kPi * j / segments;
            p.push_back(static_cast<float>(r * std::sin(theta) * std::cos(phi)));
            p.push_back(static_cast<float>(r * std::sin(theta) * std::sin(phi)));
            p.push_back(static_cast<float>(r * std::cos(theta)));
        }
    }
    const auto south = static_cast<std::uint32_t>(p.size() / 3);
    p.insert(p.end(), {0.0f, 0.0f, static_cast<float>(-r)});
    auto ring = [&](std::uint32_t i, std::uint32_t j) { return 1 + (i - 1) * segments + j % segments; };
    const auto north_copies = static_cast<std::uint32_t>(p.size() / 3), south_copies = north_copies + segments;
    for (std::uint32_t j = 0; j < segments && pole_quads; ++j)
        p.insert(p.end(), {0.0f, 0.0f, static_cast<float>(r)});
    for (std::uint32_t j = 0; j < segments && pole_quads; ++j)
        p.insert(p.end(), {0.0f, 0.0f, static_cast<float>(-r)});
    std::vector<std::uint32_t> idx;
    for (std::uint32_t j = 0; j < segments; ++j) {
        const std::uint32_t n0 = north_copies + j, n1 = north_copies + (j + 1) % segments;
        const std::uint32_t s0 = south_copies + j, s1 = south_copies + (j + 1) % segments;
        if (pole_quads)
            idx.insert(idx.end(), {n0, ring(1, j), ring(1, j + 1), n0, ring(1, j + 1), n1});
        else
            idx.insert(idx.end(), {0, ring(1, j), ring(1, j + 1)});
        for (std::uint32_t i = 1; i + 1 < rings; ++i)
            idx.insert(idx.end(), {ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j), ring(i + 1, j + 1),
                                   ring(i, j + 1)});
        if (pole_quads)
            idx.insert(idx.end(), {ring(rings - 1, j), s0, s1, ring(rings - 1, j), s1, ring(rings - 1, j + 1)});
        else
            idx.insert(idx.end(), {ring(rings - 1, j), south, ring(rings - 1, j + 1)});
    }
    for (std::size_t t = 0; t + 3 <= idx.size() && inside_out; t += 3)
        std::swap(idx[t + 1], idx[t + 2]);
    add_mesh_draw(scene, p, idx, translation(c[0], c[1], c[2]), material);
}

// A cylinder (capped: closed; else an open tube) of radius r along y from -half to +half, centred at c, `sides` around
// and `segments` along.
void add_cable(Scene& scene, double r, double half, const std::array<double, 3>& c, std::uint32_t sides,
               std::uint32_t segments, const AcousticMaterial& material, bool capped = true,
               std::uint32_t instance = 0) {
    std::vector<float> p;
    for (std::uint32_t s = 0; s <= segments; ++s) {
        const double y = -half + 2 * half * s / segments;
        for (std::uint32_t k = 0; k < sides; ++k) {
            const double phi = 2 * kPi * k / sides;
            p.insert(p.end(), {static_cast<float>(r * std::cos(phi)), static_cast<float>(y),
                               static_cast<float>(r * std::sin(phi))});
        }
    }
    const auto cap0 = static_cast<std::uint32_t>(p.size() / 3);
    p.insert(p.end(), {0.0f, static_cast<float>(-half), 0.0f, 0.0f, static_cast<float>(half), 0.0f});
    auto at = [&](std::uint32_t s, std::uint32_t k) { return s * sides + k % sides; };
    std::vector<std::uint32_t> idx;
    for (std::uint32_t s = 0; s < segments; ++s)
        for (std::uint32_t k = 0; k < sides; ++k)
            idx.insert(idx.end(), {at(s, k), at(s + 1, k), at(s + 1, k + 1), at(s, k), at(s + 1, k + 1), at(s, k + 1)});
    for (std::uint32_t k = 0; k < sides && capped; ++k) {
        idx.insert(idx.end(), {cap0, at(0, k), at(0, k + 1)});
        idx.insert(idx.end(), {cap0 + 1, at(segments, k + 1), at(segments, k)});
    }
    add_mesh_draw(scene, p, idx, translation(c[0], c[1], c[2]), material, instance);
}

double db(double x) {
    return 10.0 * std::log10(x);
}

class Subpixel : public HardCase {};

// Lambert spheres of 2 to 40 cm diameter at 15 m: the scan's total energy within 1 dB of 2 pi a^2 mu /
// (3 R^4). Their size against the pixel grid: the default's pixels at balanced are 0.135 deg wide and 0.31
// deg tall (3.5 and 8.2 cm at 15 m), so the spheres span 0.25 to 5 rows: up to 6 cm they leave the
// raster, 10 and 20 cm are drawn silent, 40 cm is rasterized as before. Three places each: on the
// sonar's axis (the centre of a row boundary: the worst case of the raster, which saw nothing of the
// 2 to 6 cm spheres there and +1.2 dB at 20 cm) and two off it.
TEST_P(Subpixel, SpheresKeepTheEnergyOfTheirAreaAtEverySize) {
    const SonarConfig config = closed_form_config();
    const double mu = std::pow(10.0, -20.0 / 10.0);
    const std::array<std::array<double, 3>, 3> places{{{15.0, 0.0, 0.0}, {14.98, 0.7, 0.05}, {14.8, -2.3, -0.11}}};
    for (double diameter_cm : {2.0, 4.0, 6.0, 10.0, 20.0, 40.0}) {
        for (const auto& c : places) {
            SCOPED_TRACE(::testing::Message()
                         << diameter_cm << " cm at (" << c[0] << ", " << c[1] << ", " << c[2] << ")");
            const double a = 0.005 * diameter_cm, range = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
            Scene scene;
            add_closed_sphere(scene, a, c, 48, 24, lambert(-20.0));
            auto rendered = render_checked(GetParam(), config, scene);
            ASSERT_TRUE(rendered);
            const double got = total(rendered->frame.clean);
            const double expected = mu * 2 * kPi * a * a / (3 * std::pow(range, 4));
            const double error_db = got > 0 ? db(got / expected) : -999.0;
            std::printf("[subpixel] %s sphere %4.0f cm at (%g, %g, %g): %.4e vs %.4e, %+.2f dB\n",
                        GetParam() == Backend::vulkan ? "vulkan" : "cpu", diameter_cm, c[0], c[1], c[2], got, expected,
                        error_db);
            EXPECT_LT(std::abs(error_db), 1.0);
        }
    }
}

// A sphere whose pole rows are quads (a pole vertex per segment, every quad's second triangle collapsed to
// a line: as many exporters write a UV sphere) is the same closed sphere: its echo equals the one-pole
// sphere's. The collapsed triangles' edges used to make the pole edges four-sided, the mesh counted as
// open and was seen from both sides: +2.96 dB.
TEST_P(Subpixel, ASpheresCollapsedPoleTrianglesLeaveItClosed) {
    const SonarConfig config = closed_form_config();
    for (double diameter_cm : {6.0, 10.0}) {
        double got[2] = {};
        for (int quads = 0; quads < 2; ++quads) {
            Scene scene;
            add_closed_sphere(scene, 0.005 * diameter_cm, {14.98, 0.7, 0.05}, 48, 24, lambert(-20.0), false,
                              quads == 1);
            auto rendered = render_checked(GetParam(), config, scene);
            ASSERT_TRUE(rendered);
            got[quads] = total(rendered->frame.clean);
        }
        std::printf("[subpixel] %s sphere %4.0f cm, pole quads against one pole vertex: %+.4f dB\n",
                    GetParam() == Backend::vulkan ? "vulkan" : "cpu", diameter_cm, db(got[1] / got[0]));
        ASSERT_GT(got[0], 0.0);
        // the same surface drawn with other triangles: equal within the raster's and the list's rounding
        EXPECT_LT(std::abs(db(got[1] / got[0])), 0.05) << diameter_cm << " cm";
    }
}

// With the vertical pattern and absorption on, a small sphere's echo carries them as a pixel's does:
// the closed form times the sinc^2 pattern at its elevation (half power at +-vfov / 2) and
// 10^(-2 alpha r / 10) with the plan's alpha; 4 cm spheres at 15 m, 0 to 9 degrees up and down, and at
// -35 and +48 degrees, past the elevation gate, where the tier views hold them (the pattern's side lobes:
// docs/pipeline.md "Vertical side lobes").
TEST_P(Subpixel, SmallSpheresCarryTheVerticalPatternAndAbsorption) {
    SonarConfig config = closed_form_config();
    config.effects.vertical_pattern = EffectMode::on;
    config.effects.absorption = EffectMode::on;
    const double a = 0.02, range = 15.0, mu = 0.01;
    const double k_v = sinc_half_power_x() / std::sin(0.5 * config.vfov_deg * kDeg);
    for (double elevation_deg : {0.0, 3.0, -6.0, 9.0, -35.0, 48.0}) {
        SCOPED_TRACE(elevation_deg);
        const double e = elevation_deg * kDeg;
        Scene scene;
        add_closed_sphere(scene, a, {range * std::cos(e), 0.0, range * std::sin(e)}, 48, 24, lambert(-20.0));
        auto rendered = render_checked(GetParam(), config, scene);
        ASSERT_TRUE(rendered);
        const Plan& plan = renderer_plan(rendered->renderer);
        ASSERT_GT(plan.alpha_db_per_m, 0.0);
        const double x = k_v * std::sin(e);
        const double pattern = x == 0 ? 1.0 : std::pow(std::sin(x) / x, 2);
        const double expected = mu * 2 * kPi * a * a / (3 * std::pow(range, 4)) * pattern *
                                std::pow(10.0, -0.2 * plan.alpha_db_per_m * range);
        const double got = total(rendered->frame.clean);
        std::printf("[subpixel] %s 4 cm sphere at %+.0f deg, pattern and absorption: %+.3f dB\n",
                    GetParam() == Backend::vulkan ? "vulkan" : "cpu", elevation_deg, db(got / expected));
        EXPECT_LT(std::abs(db(got / expected)), 0.05);
    }
}

// Planar beams, the horizontal pattern on: a 1 cm sphere at 12 m (a third of a pixel column across) swept
// across beam 255 by turning the sonar, 0.025 deg a step out to +-0.7 deg. Its energy in that beam follows
// the beam's own sinc^2 in angle (half power at +-horizontal_beamwidth / 2) wherever the pattern is above
// -5 dB, within 0.15 dB of the response at the beam's centre. Its pixel column alone used to take each
// return: a staircase of 0.127 deg column steps, up to 0.6 dB off the pattern on the main lobe's skirt.
TEST_P(Subpixel, APlanarBeamHearsASmallTargetThroughItsPatternNotInColumnSteps) {
    SonarConfig config = closed_form_config();
    config.beam_geometry = BeamGeometry::planar;
    config.effects.horizontal_pattern = EffectMode::on;
    Scene scene;
    add_closed_sphere(scene, 0.005, {12.0, 0.0, 0.0}, 48, 24, lambert(-20.0));
    auto rendered = render_checked(GetParam(), config, scene);
    ASSERT_TRUE(rendered);
    const double half = 0.5 * config.hfov_deg * kDeg;
    const double x_half = sinc_half_power_x() / std::sin(0.5 * config.horizontal_beamwidth_deg * kDeg);
    const auto pattern = [&](double separation) {
        const double x = x_half * std::sin(separation);
        return x == 0.0 ? 1.0 : std::pow(std::sin(x) / x, 2);
    };
    // beam 255 near broadside, and beam 168 (22.22 deg), whose skirt lies on the seam of two 43.3-degree slices at
    // 21.67 deg (the neighbour slice's edge column takes the share there: 0.51 dB off without it)
    ASSERT_EQ(renderer_plan(rendered->renderer).slices, 3u);
    for (const std::uint32_t beam : {255u, 168u}) {
        const double centre = (1.0 - (2.0 * beam + 1.0) / config.beams) * half; // the equi-angular table
        const auto energy_at = [&](double azimuth) { // the sphere at this azimuth of the sonar's frame
            Pose pose;
            pose.yaw_deg = -azimuth / kDeg;
            Frame& f = rendered->frame;
            EXPECT_TRUE(rendered->renderer.render(pose, 0, f));
            return beam_energy(f, beam);
        };
        const double at_centre = energy_at(centre);
        ASSERT_GT(at_centre, 0.0);
        double worst = 0;
        int compared = 0;
        for (int step = -28; step <= 28; ++step) {
            const double offset = 0.025 * step * kDeg;
            if (!(pattern(offset) > std::pow(10.0, -0.5))) continue;
            const double error_db = db(energy_at(centre + offset) / at_centre / pattern(offset));
            worst = std::max(worst, std::abs(error_db));
            ++compared;
        }
        std::printf("[subpixel] %s planar beam %u across a 1 cm sphere: %d offsets, worst %.3f dB off the pattern\n",
                    GetParam() == Backend::vulkan ? "vulkan" : "cpu", beam, compared, worst);
        EXPECT_GE(compared, 40);
        EXPECT_LT(worst, 0.15) << "beam " << beam;
    }
}

// A 1 cm cable across the fan at 10 m (y from -5 to 5 m, 26.6 degrees either side): a continuous line,
// every beam it crosses at the level of mu a (pi / 2) cos^4(theta) / X^3 per radian of steering angle,
// times the beam's width in steering angle.
TEST_P(Subpixel, ThinCableGivesAContinuousLineAtItsLevel) {
    const SonarConfig config = closed_form_config();
    const double x = 10.0, half = 5.0, a = 0.005, mu = std::pow(10.0, -20.0 / 10.0);
    // capped, and an open tube (no caps: its ends are holes, small against its area, so it still has an
    // outside and its back half is not counted from within)
    for (bool capped : {true, false}) {
        SCOPED_TRACE(capped ? "capped" : "open tube");
        Scene scene;
        add_cable(scene, a, half, {x, 0.0, 0.0}, 12, 100, lambert(-20.0), capped);
        auto rendered = render_checked(GetParam(), config, scene);
        ASSERT_TRUE(rendered);
        const Frame& f = rendered->frame;
        const Plan& plan = renderer_plan(rendered->renderer);
        const double edge = std::atan(half / x);
        double worst = 0, got_total = 0, expected_total = 0;
        std::uint32_t compared = 0;
        for (std::uint32_t j = 1; j + 1 < f.beams; ++j) {
            const double theta = plan.beam_angle_rad[j];
            // Beams a degree and more inside the cable's ends: a beam's cone reaches a beam width either side.
            if (std::abs(theta) > edge - 1.0 * kDeg) continue;
            const double width = 0.5 * std::abs(plan.beam_angle_rad[j - 1] - plan.beam_angle_rad[j + 1]);
            const double expected = mu * a * 0.5 * kPi * std::pow(std::cos(theta), 4) / std::pow(x, 3) * width;
            const double got = beam_energy(f, j);
            got_total += got;
            expected_total += expected;
            const double error_db = got > 0 ? db(got / expected) : -999.0;
            worst = std::max(worst, std::abs(error_db));
            ++compared;
            EXPECT_GT(got, 0.0) << "beam " << j << " at " << theta / kDeg << " deg: a gap in the line";
        }
        std::printf("[subpixel] %s %s cable 1 cm at %.0f m: %u beams, worst beam %+.2f dB, total %+.2f dB\n",
                    GetParam() == Backend::vulkan ? "vulkan" : "cpu", capped ? "capped" : "open", x, compared, worst,
                    db(got_total / expected_total));
        EXPECT_GT(compared, 100u);
        EXPECT_LT(worst, 1.0);
        EXPECT_LT(std::abs(db(got_total / expected_total)), 0.5);
    }
}

// Labels (SaveFlags::labels) follow the cable's returns: before, a 1 cm cable lit a line of cells that no
// label named (its echo comes from its triangles, not from pixels). Every beam a degree inside its ends has
// a cell of it; every labelled cell is the cable's alone, within a bin and a half of its point's range, and
// its point lies on the cable (within its radius of the axis, 1 mm for the float centroid).
TEST_P(Subpixel, LabelsNameTheCableItsReturnsLight) {
    const SonarConfig config = closed_form_config();
    const double x = 10.0, half = 5.0, a = 0.005;
    constexpr std::uint32_t kCable = 9;
    Scene scene;
    add_cable(scene, a, half, {x, 0.0, 0.0}, 12, 100, lambert(-20.0), true, kCable);
    auto rendered = render_once(GetParam(), config, scene, Pose{}, SaveFlags::labels);
    ASSERT_TRUE(rendered);
    const Frame& f = rendered->frame;
    const Plan& plan = renderer_plan(rendered->renderer);
    ASSERT_EQ(f.instance.size(), std::size_t(f.bins) * f.beams);
    const double edge = std::atan(half / x);
    std::uint32_t labelled = 0, beams_inside = 0, beams_lit = 0;
    double worst_axis = 0, worst_bins = 0;
    for (std::uint32_t j = 0; j < f.beams; ++j) {
        const bool inside = std::abs(plan.beam_angle_rad[j]) < edge - 1.0 * kDeg;
        beams_inside += inside;
        bool lit = false;
        for (std::uint32_t k = 0; k < f.bins; ++k) {
            const std::size_t i = std::size_t(k) * f.beams + j;
            if (f.instance[i] == 0) continue;
            ++labelled;
            lit = true;
            EXPECT_EQ(f.instance[i], kCable) << "bin " << k << " beam " << j;
            EXPECT_FLOAT_EQ(f.instance_fraction[i], 1.0f);
            const double p[3] = {f.point[3 * i], f.point[3 * i + 1], f.point[3 * i + 2]};
            worst_axis = std::max(worst_axis, std::hypot(p[0] - x, p[2]));
            const double range = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
            worst_bins = std::max(worst_bins, std::abs((range - config.range_min_m) / plan.bin_width_m - (k + 0.5)));
        }
        beams_lit += inside && lit;
    }
    std::printf("[subpixel] %s cable labels: %u cells, %u of %u beams inside its ends lit, point off the axis <= %.4f "
                "m, <= %.2f bins off its cell\n",
                GetParam() == Backend::vulkan ? "vulkan" : "cpu", labelled, beams_lit, beams_inside, worst_axis,
                worst_bins);
    EXPECT_GT(beams_inside, 100u);
    EXPECT_EQ(beams_lit, beams_inside) << "a gap in the labelled line";
    EXPECT_LE(worst_axis, a + 1e-3);
    EXPECT_LE(worst_bins, 1.5);
    // Its visibility from its returns (it has no pixel of its own): seen whole, inside the window. Drawn
    // alone on the rasterizer it would count as hidden wherever a pixel centre caught it.
    const auto seen = std::find_if(f.visibility.begin(), f.visibility.end(),
                                   [&](const ObjectVisibility& v) { return v.instance == kCable; });
    ASSERT_NE(seen, f.visibility.end());
    EXPECT_GT(seen->pixels, 100u);
    EXPECT_EQ(seen->hidden, 0u);
    EXPECT_EQ(seen->outside, 0u);
}

// An open mesh has no outside: a 3 cm square plate at 15 m facing the sonar returns mu A / R^4 (cos
// theta = 1 to 1e-6 over it) whichever way its two triangles are wound; a closed mesh wound inside out
// (the sphere's triangles reversed) still shows its near half, 2 pi a^2 mu / (3 R^4).
// Render-ahead (Renderer::render with a NextFrame) builds the next frame's returns while this frame's
// labels read this frame's: each frame slot keeps its own list. Two poses that see the cable at
// different bearings, alternated, each announcing the other: the labels are a plain render's, with
// timestamps on Vulkan (one submission per frame, two frames on the device).
TEST_P(Subpixel, RenderAheadLabelsEachFrameFromItsOwnReturns) {
    const SonarConfig config = closed_form_config();
    constexpr std::uint32_t kCable = 9;
    Scene scene;
    add_cable(scene, 0.005, 5.0, {10.0, 0.0, 0.0}, 12, 100, lambert(-20.0), true, kCable);
    RendererOptions options;
    options.stage_timing = StageTiming::timestamps;
    Pose a, b;
    b.yaw_deg = 12.0;
    auto ahead = render_once(GetParam(), config, scene, a, SaveFlags::labels, 1, options);
    auto plain = render_once(GetParam(), config, scene, a, SaveFlags::labels, 1, options);
    ASSERT_TRUE(ahead && plain);
    std::vector<std::uint16_t> first;
    for (std::uint64_t i = 0; i < 4; ++i) {
        const Pose& pose = i % 2 ? b : a;
        ASSERT_TRUE(ahead->renderer.render(pose, i, ahead->frame, NextFrame{i % 2 ? a : b, i + 1}));
        ASSERT_TRUE(plain->renderer.render(pose, i, plain->frame));
        EXPECT_EQ(ahead->frame.instance, plain->frame.instance) << i;
        EXPECT_EQ(ahead->frame.clean, plain->frame.clean) << i;
        const auto cable_cells = std::count(plain->frame.instance.begin(), plain->frame.instance.end(), kCable);
        EXPECT_GT(cable_cells, 0) << i;
        if (i == 0) first = plain->frame.instance;
        if (i == 1) {
            EXPECT_NE(plain->frame.instance, first) << "the two poses see the cable in other cells";
        }
    }
}

TEST_P(Subpixel, AnOpenSheetIsSeenFromEitherSideAndAClosedMeshFromOutside) {
    const SonarConfig config = closed_form_config();
    const double mu = 0.01, half = 0.015, range = 15.0;
    for (bool towards : {true, false}) {
        SCOPED_TRACE(towards ? "wound towards the sonar" : "wound away");
        Scene scene;
        const std::vector<std::uint32_t> idx =
            towards ? std::vector<std::uint32_t>{0, 1, 2, 0, 2, 3} : std::vector<std::uint32_t>{0, 2, 1, 0, 3, 2};
        const auto h = static_cast<float>(half);
        add_mesh_draw(scene, {0, -h, -h, 0, h, -h, 0, h, h, 0, -h, h}, idx, translation(range, 0, 0), lambert(-20.0));
        auto rendered = render_checked(GetParam(), config, scene);
        ASSERT_TRUE(rendered);
        const double expected = mu * 4 * half * half / std::pow(range, 4);
        EXPECT_NEAR(total(rendered->frame.clean), expected, 2e-3 * expected);
    }
    Scene scene;
    const double a = 0.02;
    add_closed_sphere(scene, a, {range, 0.0, 0.0}, 48, 24, lambert(-20.0), /*inside_out=*/true);
    auto rendered = render_checked(GetParam(), config, scene);
    ASSERT_TRUE(rendered);
    const double expected = mu * 2 * kPi * a * a / (3 * std::pow(range, 4));
    EXPECT_LT(std::abs(db(total(rendered->frame.clean) / expected)), 0.05);
}

// A capped cylinder of radius r from p0 to p1 with its vertices in the world's coordinates (a cable path
// baked into the mesh, as exporters write it: the mesh's own axes say nothing about its direction).
void add_baked_cable(Scene& scene, double r, const std::array<double, 3>& p0, const std::array<double, 3>& p1,
                     std::uint32_t sides, std::uint32_t segments, const AcousticMaterial& material) {
    std::array<double, 3> u{p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
    const double length = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    for (double& x : u)
        x /= length;
    // v, w: perpendicular to u and to each other
    std::array<double, 3> v{-u[1], u[0], 0.0};
    const double lv = std::sqrt(v[0] * v[0] + v[1] * v[1]);
    for (double& x : v)
        x /= lv;
    const std::array<double, 3> w{u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    std::vector<float> p;
    for (std::uint32_t s = 0; s <= segments; ++s) {
        const double t = length * s / segments;
        for (std::uint32_t k = 0; k < sides; ++k) {
            const double phi = 2 * kPi * k / sides, c = r * std::cos(phi), sn = r * std::sin(phi);
            for (int i = 0; i < 3; ++i)
                p.push_back(static_cast<float>(p0[i] + t * u[i] + c * v[i] + sn * w[i]));
        }
    }
    const auto cap0 = static_cast<std::uint32_t>(p.size() / 3);
    for (int i = 0; i < 3; ++i)
        p.push_back(static_cast<float>(p0[i]));
    for (int i = 0; i < 3; ++i)
        p.push_back(static_cast<float>(p1[i]));
    auto at = [&](std::uint32_t s, std::uint32_t k) { return s * sides + k % sides; };
    std::vector<std::uint32_t> idx;
    for (std::uint32_t s = 0; s < segments; ++s)
        for (std::uint32_t k = 0; k < sides; ++k)
            idx.insert(idx.end(), {at(s, k), at(s, k + 1), at(s + 1, k + 1), at(s, k), at(s + 1, k + 1), at(s + 1, k)});
    for (std::uint32_t k = 0; k < sides; ++k) {
        idx.insert(idx.end(), {cap0, at(0, k + 1), at(0, k)});
        idx.insert(idx.end(), {cap0 + 1, at(segments, k), at(segments, k + 1)});
    }
    add_mesh_draw(scene, p, idx, translation(0, 0, 0), material);
}

// A 1 cm cable baked into its mesh diagonally, from (9, -4, -0.3) to (11, 4, 0.3) m: its runs' boxes are
// wide, their principal axes thin. The scan's total against the cable integrated along its length,
// mu a (pi / 2) sin^2(psi) / r^4 dl (psi between the ray and the cable), within 0.3 dB (the ends' caps and
// their 1 cm of rim: 1e-3 of it); every beam between its ends lit.
TEST_P(Subpixel, ADiagonalCableIsThinToo) {
    const SonarConfig config = closed_form_config();
    const double a = 0.005, mu = 0.01;
    const std::array<double, 3> p0{9.0, -4.0, -0.3}, p1{11.0, 4.0, 0.3};
    Scene scene;
    add_baked_cable(scene, a, p0, p1, 12, 100, lambert(-20.0));
    auto rendered = render_checked(GetParam(), config, scene);
    ASSERT_TRUE(rendered);
    const Frame& f = rendered->frame;
    const Plan& plan = renderer_plan(rendered->renderer);
    const std::array<double, 3> d{p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
    const double length = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    double expected = 0;
    const int steps = 20000;
    for (int i = 0; i < steps; ++i) {
        const double t = (i + 0.5) / steps;
        const std::array<double, 3> q{p0[0] + t * d[0], p0[1] + t * d[1], p0[2] + t * d[2]};
        const double r = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
        const double cos_psi = (q[0] * d[0] + q[1] * d[1] + q[2] * d[2]) / (r * length);
        expected += mu * a * 0.5 * kPi * (1 - cos_psi * cos_psi) / std::pow(r, 4) * length / steps;
    }
    const double got = total(f.clean);
    std::printf("[subpixel] %s diagonal cable: %+.3f dB\n", GetParam() == Backend::vulkan ? "vulkan" : "cpu",
                db(got / expected));
    EXPECT_LT(std::abs(db(got / expected)), 0.3);
    // every beam whose steering angle lies between the ends' (a degree inside them)
    const double lo = std::asin(p0[1] / std::sqrt(p0[0] * p0[0] + p0[1] * p0[1] + p0[2] * p0[2]));
    const double hi = std::asin(p1[1] / std::sqrt(p1[0] * p1[0] + p1[1] * p1[1] + p1[2] * p1[2]));
    std::uint32_t lit = 0, inside = 0;
    for (std::uint32_t j = 0; j < f.beams; ++j) {
        const double theta = plan.beam_angle_rad[j];
        if (theta < lo + kDeg || theta > hi - kDeg) continue;
        ++inside;
        lit += beam_energy(f, j) > 0;
    }
    EXPECT_GT(inside, 100u);
    EXPECT_EQ(lit, inside);
}

// A wall (a 12 m square facing the sonar, Lambert) at distance `x`.
void add_wall(Scene& scene, double x, double backscatter_db) {
    add_mesh_draw(scene, {0, -6, -6, 0, 6, -6, 0, 6, 6, 0, -6, 6}, {0, 1, 2, 0, 2, 3}, translation(x, 0, 0),
                  lambert(backscatter_db));
}

// The clean scan's energy in the bins within `half` metres of range r.
double energy_near(const Frame& f, const Plan& plan, double r, double half) {
    double e = 0;
    for (std::uint32_t k = 0; k < f.bins; ++k)
        if (std::abs(plan.bin_range_m[k] - r) <= half)
            for (std::uint32_t j = 0; j < f.beams; ++j)
                e += f.clean[std::size_t(k) * f.beams + j];
    return e;
}

// The occlusion test against the depth image: a 4 cm sphere (not rasterized) behind a wall returns
// nothing; in front of it, its whole echo, the wall's too. A 20 cm sphere (rasterized silent, its echo
// from its returns) in front of the wall still hides the wall behind it: the wall loses the echo of
// the patch in the sphere's shadow, the sphere's disc of pi a^2 at the wall's distance seen at the
// sphere's distance (a^2 pi (x_wall / x_sphere)^2 of wall, mu cos^2 / r^4 each, the wall head on).
TEST_P(Subpixel, ReturnsHideBehindSurfacesAndSilentObjectsCastShadows) {
    const SonarConfig config = closed_form_config();
    const double mu = 0.01;
    {
        SCOPED_TRACE("4 cm sphere at 15 m behind a wall at 10 m");
        Scene scene;
        add_closed_sphere(scene, 0.02, {15.0, 0.0, 0.0}, 48, 24, lambert(-20.0));
        add_wall(scene, 10.0, -40.0);
        auto rendered = render_checked(GetParam(), config, scene);
        ASSERT_TRUE(rendered);
        const Plan& plan = renderer_plan(rendered->renderer);
        EXPECT_EQ(energy_near(rendered->frame, plan, 15.0, 0.3), 0.0);
    }
    {
        SCOPED_TRACE("4 cm sphere at 15 m in front of a wall at 20 m");
        Scene scene;
        add_closed_sphere(scene, 0.02, {15.0, 0.0, 0.0}, 48, 24, lambert(-20.0));
        add_wall(scene, 20.0, -40.0);
        auto rendered = render_checked(GetParam(), config, scene);
        ASSERT_TRUE(rendered);
        const Plan& plan = renderer_plan(rendered->renderer);
        const double expected = mu * 2 * kPi * 0.02 * 0.02 / (3 * std::pow(15.0, 4));
        EXPECT_NEAR(energy_near(rendered->frame, plan, 15.0, 0.3), expected, 0.05 * expected);
    }
    double wall_alone = 0, wall_shadowed = 0;
    for (bool sphere : {false, true}) {
        Scene scene;
        add_wall(scene, 20.0, -20.0);
        if (sphere) add_closed_sphere(scene, 0.1, {15.0, 0.0, 0.0}, 48, 24, lambert(-20.0));
        auto rendered = render_checked(GetParam(), config, scene);
        ASSERT_TRUE(rendered);
        const Plan& plan = renderer_plan(rendered->renderer);
        (sphere ? wall_shadowed : wall_alone) = energy_near(rendered->frame, plan, 20.0, 0.5);
        if (sphere) {
            const double expected = mu * 2 * kPi * 0.01 / (3 * std::pow(15.0, 4));
            const double got = energy_near(rendered->frame, plan, 15.0, 0.5);
            EXPECT_LT(std::abs(db(got / expected)), 0.5) << "the silent sphere's own echo";
        }
    }
    // The shadow: a disc of radius 0.1 x 20 / 15 m on the wall, head on at 20 m. Its pixels are whole
    // pixels of the depth image (about 120 of them): 20 % for the pixels along its rim.
    const double shadow = mu * kPi * std::pow(0.1 * 20.0 / 15.0, 2) / std::pow(20.0, 4);
    std::printf("[subpixel] %s shadow of a 20 cm sphere on a wall: %.4e vs %.4e\n",
                GetParam() == Backend::vulkan ? "vulkan" : "cpu", wall_alone - wall_shadowed, shadow);
    EXPECT_NEAR(wall_alone - wall_shadowed, shadow, 0.2 * shadow);
}

// More small objects than the list holds (kMaxSubpixelReturns, 2^18 returns; 260 spheres of 2 cm at 15 m
// listing about 2000 each, on the sonar's horizontal plane where the raster sees none of them): the
// objects past it go to the depth pass as before, whole (the list takes an object whole or not at all).
// So the scan holds the listed spheres' echo, about half of them (measured 0.45 of the closed form), and
// no sphere twice.
TEST_P(Subpixel, ObjectsPastTheListsCapacityGoToTheDepthPass) {
    const SonarConfig config = closed_form_config();
    const double a = 0.01, mu = 0.01;
    Scene scene;
    double expected = 0;
    for (int i = 0; i < 260; ++i) {
        const double r = 15.0, az = (-60.0 + 0.46 * i) * kDeg;
        add_closed_sphere(scene, a, {r * std::cos(az), r * std::sin(az), 0.0}, 48, 24, lambert(-20.0));
        expected += mu * 2 * kPi * a * a / (3 * std::pow(r, 4));
    }
    auto rendered = render_checked(GetParam(), config, scene);
    ASSERT_TRUE(rendered);
    EXPECT_EQ(renderer_plan(rendered->renderer).subpixel_capacity, kMaxSubpixelReturns);
    const double got = total(rendered->frame.clean);
    std::printf("[subpixel] %s 260 spheres past the list's capacity: %.4f of the closed form\n",
                GetParam() == Backend::vulkan ? "vulkan" : "cpu", got / expected);
    EXPECT_GT(got, 0.3 * expected);
    EXPECT_LT(got, 0.9 * expected);
}

// Both backends add the same returns: spheres of 2 to 10 cm across the fan from 5 to 35 m and the cable,
// nothing rasterized. The list is the host's, the same for both; each backend adds a column's returns
// in list order after its pixels, in float (the CPU's float path) with the same tent shares
// (range_spread, `precise` on the GPU): the scans agree to float rounding.
TEST(SubpixelBackends, BothBackendsAddTheSameReturns) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard validation;
    SonarConfig config = closed_form_config();
    config.effects.horizontal_pattern = EffectMode::on;
    config.effects.vertical_pattern = EffectMode::on;
    config.effects.absorption = EffectMode::on;
    Scene scene;
    for (int i = 0; i < 7; ++i) {
        const double r = 5.0 + 5.0 * i, az = (-50.0 + 16.0 * i) * kDeg;
        add_closed_sphere(scene, 0.01 + 0.008 * (i % 4), {r * std::cos(az), r * std::sin(az), -0.3 + 0.1 * i}, 24, 12,
                          lambert(-20.0 - i));
    }
    add_cable(scene, 0.005, 5.0, {10.0, 0.0, -0.5}, 12, 100, lambert(-25.0));
    auto cpu = render_once(Backend::cpu, config, scene, {}, kSaveAll);
    auto gpu = render_once(Backend::vulkan, config, scene, {}, kSaveAll);
    ASSERT_TRUE(cpu && gpu);
    const std::vector<float>& a = cpu->frame.clean;
    const std::vector<float>& b = gpu->frame.clean;
    ASSERT_EQ(a.size(), b.size());
    double peak = 0, worst = 0;
    for (float v : a)
        peak = std::max(peak, double(v));
    for (std::size_t i = 0; i < a.size(); ++i)
        worst = std::max(worst, std::abs(double(a[i]) - double(b[i])) / peak);
    std::printf("[subpixel] cpu vs vulkan: worst cell %.3g of the peak, totals %.6e / %.6e\n", worst, total(a),
                total(b));
    EXPECT_GT(peak, 0.0);
    EXPECT_LT(worst, 1e-6);
    EXPECT_NEAR(total(a), total(b), 1e-6 * total(a));
    // A GPU's profile layout (32 invocations a column, tests/stages/beamform_test.cpp) adds the
    // returns to the same cells in the same order.
    RendererOptions lanes;
    lanes.layout = WorkLayout::gpu;
    auto gpu_lanes = render_once(Backend::vulkan, config, scene, {}, kSaveAll, 1, lanes);
    ASSERT_TRUE(gpu_lanes);
    EXPECT_EQ(gpu_lanes->frame.clean, b);
}

INSTANTIATE_TEST_SUITE_P(Backends, Subpixel, ::testing::Values(Backend::cpu, Backend::vulkan), backend_name);

} // namespace
} // namespace vksonar::testing::hard
