// Ground-truth labels (SaveFlags::labels, docs/labels.md) against geometry computed here: where an
// object's cells must lie (its visible surface's range and beam extent under each beam geometry), the
// elevation and 3-D point of a sphere, occlusion, the class table of a glTF scene, labels off vs on,
// and the two backends against each other. Nothing below reads the plan's beam or bin tables: beams
// come from the config's equi-angular table (beam centre j at (1 - (2 j + 1) / N) hfov / 2) and bins
// from the window (bin k covers [range_min + k w, range_min + (k + 1) w)).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "core/plan.h"
#include "core/renderer_access.h"
#include "core/tier_extent.h"
#include "stages/cpu_simd.h"
#include "stages/labels.h"
#include "stages/pixel_spread.h"
#include "test_support.h"

namespace vksonar::testing {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;
constexpr std::uint32_t kSphereId = 7, kQuadId = 9;

struct Point3 {
    double x, y, z;
};

// The extent, in fractional bin and beam coordinates, of a set of surface points seen by the config.
struct Extent {
    double bin_lo = 1e30, bin_hi = -1e30, beam_lo = 1e30, beam_hi = -1e30;
};

double beam_angle_of(BeamGeometry geometry, const Point3& p) {
    const double r = std::sqrt(p.x * p.x + p.y * p.y + p.z * p.z);
    // line array along y: the direction cosine along the axis is the sine of the steering angle
    return geometry == BeamGeometry::line_array ? std::asin(p.y / r) : std::atan2(p.y, p.x);
}

Extent extent_of(const SonarConfig& c, const std::vector<Point3>& points) {
    const double bin_width = (c.range_max_m - c.range_min_m) / c.bins;
    const double half = 0.5 * c.hfov_deg * kDeg, spacing = c.hfov_deg * kDeg / c.beams;
    Extent e;
    for (const Point3& p : points) {
        const double r = std::sqrt(p.x * p.x + p.y * p.y + p.z * p.z);
        const double bin = (r - c.range_min_m) / bin_width;
        const double beam = (half - beam_angle_of(c.beam_geometry, p)) / spacing - 0.5;
        e.bin_lo = std::min(e.bin_lo, bin);
        e.bin_hi = std::max(e.bin_hi, bin);
        e.beam_lo = std::min(e.beam_lo, beam);
        e.beam_hi = std::max(e.beam_hi, beam);
    }
    return e;
}

// Points on the half of a sphere (centre c, radius a) that faces a sonar at the origin.
std::vector<Point3> sphere_front(const Point3& c, double a) {
    std::vector<Point3> out;
    for (int i = 0; i <= 90; ++i) {
        const double theta = kPi * i / 90;
        for (int j = 0; j < 180; ++j) {
            const double phi = 2 * kPi * j / 180;
            const Point3 n{std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
            const Point3 p{c.x + a * n.x, c.y + a * n.y, c.z + a * n.z};
            if (n.x * p.x + n.y * p.y + n.z * p.z < 0) out.push_back(p); // faces the origin
        }
    }
    return out;
}

// Points of a width x height rectangle centred at c, facing the origin (normal along -c, vertical sides).
std::vector<Point3> quad_points(const Point3& c, double width, double height) {
    const double yaw = std::atan2(c.y, c.x);
    std::vector<Point3> out;
    for (int i = 0; i <= 60; ++i)
        for (int j = 0; j <= 20; ++j) {
            const double s = width * (double(i) / 60 - 0.5), t = height * (double(j) / 20 - 0.5);
            out.push_back({c.x - s * std::sin(yaw), c.y + s * std::cos(yaw), c.z + t});
        }
    return out;
}

Point3 at(double range, double azimuth_deg, double elevation_deg) {
    const double a = azimuth_deg * kDeg, e = elevation_deg * kDeg;
    return {range * std::cos(e) * std::cos(a), range * std::cos(e) * std::sin(a), range * std::sin(e)};
}

SonarConfig labels_config(BeamGeometry geometry) {
    SonarConfig c = quiet_config(); // the default sonar: 130 x 20 deg, 512 beams x 512 bins, 40 m
    c.beam_geometry = geometry;
    return c;
}

struct TwoObjects {
    Point3 sphere = at(15.0, 20.0, -4.0);
    double radius = 0.4;
    Point3 quad = at(10.0, -25.0, 0.0);
    double quad_width = 3.0, quad_height = 1.0;
    Scene scene;
    TwoObjects() {
        add_sphere(scene, sphere.x, sphere.y, sphere.z, radius, 64, -10.0, kSphereId);
        AcousticMaterial m;
        m.backscatter_db = -15.0;
        add_quad(scene, quad.x, quad.y, quad.z, quad_width, quad_height, m, std::atan2(quad.y, quad.x) / kDeg, kQuadId);
    }
};

struct LabelTest : public ::testing::TestWithParam<std::tuple<Backend, BeamGeometry>> {
    void SetUp() override {
        if (std::get<0>(GetParam()) == Backend::vulkan) VKSONAR_REQUIRE_VULKAN();
    }
    ValidationGuard validation_;
};

// Every cell of an object lies within one bin and one beam of the extent of its visible surface, and
// every beam strictly inside that extent has a cell of it; the rest of the image has no label.
TEST_P(LabelTest, ObjectsSitWhereTheGeometryPutsThem) {
    const auto [backend, geometry] = GetParam();
    const SonarConfig config = labels_config(geometry);
    TwoObjects objects;
    auto r = render_once(backend, config, objects.scene, {}, SaveFlags::labels);
    ASSERT_TRUE(r);
    const Frame& f = r->frame;
    ASSERT_EQ(f.instance.size(), std::size_t(f.bins) * f.beams);
    ASSERT_EQ(f.point.size(), std::size_t(f.bins) * f.beams * 3);

    const Extent sphere = extent_of(config, sphere_front(objects.sphere, objects.radius));
    const Extent quad = extent_of(config, quad_points(objects.quad, objects.quad_width, objects.quad_height));
    for (const auto& [id, e, name] : {std::tuple{kSphereId, sphere, "sphere"}, std::tuple{kQuadId, quad, "quad"}}) {
        std::size_t cells = 0, outside = 0;
        std::vector<bool> beam_has(f.beams, false);
        for (std::uint32_t k = 0; k < f.bins; ++k)
            for (std::uint32_t j = 0; j < f.beams; ++j) {
                if (f.instance[std::size_t(k) * f.beams + j] != id) continue;
                ++cells;
                beam_has[j] = true;
                const bool in_bins = k + 1 >= std::floor(e.bin_lo) && k <= std::floor(e.bin_hi) + 1;
                const bool in_beams = j + 1 >= std::floor(e.beam_lo) && j <= std::ceil(e.beam_hi) + 1;
                if (!in_bins || !in_beams) {
                    if (outside < 5)
                        ADD_FAILURE() << name << " cell bin " << k << " beam " << j << " outside bins [" << e.bin_lo
                                      << ", " << e.bin_hi << "] beams [" << e.beam_lo << ", " << e.beam_hi << "]";
                    ++outside;
                }
            }
        std::size_t missing = 0;
        for (int j = static_cast<int>(std::ceil(e.beam_lo)) + 1; j < static_cast<int>(std::floor(e.beam_hi)); ++j)
            missing += !beam_has[j];
        std::printf("[labels] %s: %zu cells, beams %.1f-%.1f, bins %.1f-%.1f\n", name, cells, e.beam_lo, e.beam_hi,
                    e.bin_lo, e.bin_hi);
        EXPECT_GT(cells, 0u) << name;
        EXPECT_EQ(outside, 0u) << name;
        EXPECT_EQ(missing, 0u) << name << ": beams inside its extent without a cell of it";
    }
    // Nothing else in the scene: every cell with energy belongs to one of the two, and they do not meet,
    // so each labelled cell is one object's alone.
    for (std::size_t i = 0; i < f.instance.size(); ++i) {
        if (f.instance[i] == 0) {
            ASSERT_EQ(f.instance_fraction[i], 0.0f);
            ASSERT_TRUE(std::isnan(f.elevation[i]) && std::isnan(f.point[3 * i]));
            continue;
        }
        ASSERT_TRUE(f.instance[i] == kSphereId || f.instance[i] == kQuadId) << f.instance[i];
        ASSERT_NEAR(f.instance_fraction[i], 1.0f, 1e-6f);
        ASSERT_EQ(f.object_class[i], 0u); // a hand-built scene has no class table
    }
}

// The sphere's strongest cell looks at its centre's elevation (within one vertical pixel), and the
// points of its cells lie on its surface (within a bin width).
TEST_P(LabelTest, SphereElevationAndPoints) {
    const auto [backend, geometry] = GetParam();
    const SonarConfig config = labels_config(geometry);
    TwoObjects objects;
    auto r = render_once(backend, config, objects.scene, {}, SaveFlags::labels);
    ASSERT_TRUE(r);
    const Frame& f = r->frame;
    const Plan& plan = renderer_plan(r->renderer);
    const double pixel_rad = plan.vertical_coverage_rad / plan.rows; // a tolerance only
    const double true_elevation = std::asin(objects.sphere.z / 15.0);
    std::size_t best = 0;
    for (std::size_t i = 0; i < f.clean.size(); ++i)
        if (f.instance[i] == kSphereId && (f.instance[best] != kSphereId || f.clean[i] > f.clean[best])) best = i;
    ASSERT_EQ(f.instance[best], kSphereId);
    std::printf("[labels] sphere elevation %.3f deg, true %.3f, pixel %.3f deg, spread %.3f deg\n",
                f.elevation[best] / kDeg, true_elevation / kDeg, pixel_rad / kDeg, f.elevation_spread[best] / kDeg);
    EXPECT_NEAR(f.elevation[best], true_elevation, pixel_rad);
    // All of the sphere lies within its angular radius of its centre's direction.
    EXPECT_LT(f.elevation_spread[best], std::asin(objects.radius / 15.0));

    const double bin_width = (config.range_max_m - config.range_min_m) / config.bins;
    // On its pixel's ray, at the range of that pixel's footprint inside the bin: off the surface by at
    // most the part of a bin the footprint's range does not follow.
    const double tolerance = bin_width;
    std::size_t cells = 0, off = 0;
    double worst = 0;
    for (std::size_t i = 0; i < f.instance.size(); ++i) {
        if (f.instance[i] != kSphereId) continue;
        ++cells;
        const double dx = f.point[3 * i] - objects.sphere.x, dy = f.point[3 * i + 1] - objects.sphere.y,
                     dz = f.point[3 * i + 2] - objects.sphere.z;
        const double miss = std::abs(std::sqrt(dx * dx + dy * dy + dz * dz) - objects.radius);

        worst = std::max(worst, miss);
        off += miss > tolerance;
    }
    std::printf("[labels] sphere points: %zu cells, worst %.3f m off the surface (tolerance %.3f)\n", cells, worst,
                tolerance);
    EXPECT_EQ(off, 0u);
}

INSTANTIATE_TEST_SUITE_P(Labels, LabelTest,
                         ::testing::Combine(::testing::Values(Backend::vulkan, Backend::cpu),
                                            ::testing::Values(BeamGeometry::line_array, BeamGeometry::planar)));

class LabelBackendTest : public BackendTest {};

// A wall in front of the sphere hides it: no cell is the sphere's (and without the wall some are).
TEST_P(LabelBackendTest, OccludedObjectGetsNoCells) {
    const SonarConfig config = labels_config(BeamGeometry::line_array);
    for (const bool wall : {false, true}) {
        Scene scene;
        add_sphere(scene, 14.0, 0.0, 0.0, 0.4, 48, -10.0, kSphereId);
        if (wall) { // 8 m away, 4 x 4 m: +-14 deg in azimuth and elevation, the sphere subtends +-1.6 deg
            AcousticMaterial m;
            m.backscatter_db = -20.0;
            add_quad(scene, 8.0, 0.0, 0.0, 4.0, 4.0, m, 0.0, kQuadId);
        }
        auto r = render_once(GetParam(), config, scene, {}, SaveFlags::labels);
        ASSERT_TRUE(r);
        const auto sphere_cells = std::count(r->frame.instance.begin(), r->frame.instance.end(), kSphereId);
        const auto wall_cells = std::count(r->frame.instance.begin(), r->frame.instance.end(), kQuadId);
        if (wall) {
            EXPECT_EQ(sphere_cells, 0);
            EXPECT_GT(wall_cells, 0);
        } else {
            EXPECT_GT(sphere_cells, 0);
        }
    }
}

// The bundled scene: labels off and on give bit-identical intensities and material image; every
// labelled cell names an object of the scene's table with that object's class.
TEST_P(LabelBackendTest, BundledSceneTableAndNoChangeToIntensities) {
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    SonarConfig config = quiet_config();
    config.effects.speckle = EffectMode::on;
    config.effects.ambient_noise = EffectMode::on;
    Pose pose;
    pose.pitch_deg = 10.0;
    auto off = render_once(GetParam(), config, scene.value(), pose, SaveFlags::depth);
    auto on = render_once(GetParam(), config, scene.value(), pose, SaveFlags::depth | SaveFlags::labels);
    ASSERT_TRUE(off && on);
    const Frame &a = off->frame, &b = on->frame;
    ASSERT_EQ(a.intensity.size(), b.intensity.size());
    EXPECT_EQ(std::memcmp(a.clean.data(), b.clean.data(), a.clean.size() * sizeof(float)), 0);
    EXPECT_EQ(std::memcmp(a.intensity.data(), b.intensity.data(), a.intensity.size() * sizeof(float)), 0);
    EXPECT_EQ(a.material, b.material);
    EXPECT_TRUE(a.instance.empty()) << "labels not asked for, yet filled";

    std::vector<std::uint32_t> class_of(65536, 0);
    std::vector<bool> known(65536, false);
    for (const SceneInstance& o : scene.value().instances()) {
        class_of[o.id] = o.class_id;
        known[o.id] = true;
    }
    std::size_t labelled = 0;
    std::vector<std::size_t> per_id(65536, 0);
    for (std::size_t i = 0; i < b.instance.size(); ++i) {
        const std::uint16_t id = b.instance[i];
        if (id == 0) continue;
        ++labelled;
        ++per_id[id];
        ASSERT_TRUE(known[id]) << "instance " << id << " is not in the scene's table";
        ASSERT_EQ(b.object_class[i], class_of[id]);
        ASSERT_GT(b.instance_fraction[i], 0.0f);
        ASSERT_LE(b.instance_fraction[i], 1.0f + 1e-6f);
        ASSERT_TRUE(std::isfinite(b.elevation[i]) && std::isfinite(b.point[3 * i]));
    }
    std::size_t objects_seen = 0;
    for (std::size_t n : per_id)
        objects_seen += n > 0;
    std::printf("[labels] default scene: %zu labelled cells, %zu objects\n", labelled, objects_seen);
    EXPECT_GT(labelled, b.instance.size() / 10);
    EXPECT_GE(objects_seen, 5u); // seabed, pilings, pipe, crate, sphere in the default view
}

// GPU vs CPU on the bundled scene: the labels are one host stage on each backend's depth and echo,
// so they differ only where the two backends' echoes do: float order, and the pixels on a triangle's
// edge that one rasterizer covers and the other does not (lavapipe follows the CPU rasterizer's rule;
// a real GPU does not, kDepthEdgePixelBudget). Elsewhere a cell whose top instance holds at least
// 50.1 % of its energy on the CPU cannot lose it to a 1e-5 relative change (the echo's GPU-vs-CPU
// tolerance, tests/tolerances.h, is far below the 0.2 % margin); one edge pixel more or less can move
// it. Measured: 0 clear cells differ on lavapipe (required there), 4 of 202832 on an H200; a GPU may
// differ in 1e-4 of them.
// Elevations: a cell's is the energy-weighted mean over its pixels, so it moves past 1e-3 rad where its
// pixels' shares differ by more than float rounding. Two causes:
// - narrow footprints (a face towards the sonar, range steps of millimetres between rows) whose place
//   in the bins moves with the depth's float rounding (kDepthInteriorRelTol): with no edge pixel at all,
//   lavapipe has 8 cells over, their clean values 1-8 % apart between the backends, and an NVIDIA H100
//   24 (its depth rounds differently from lavapipe's). Budget: 1e-4 of the cells on lavapipe (19.6
//   here), 5e-4 on a GPU (98, four times the H100's);
// - edge pixels (hit on one backend only, or by another object) and the pixels whose footprint reads
//   one (two rows up and down, one column either side): each reaches the bins of its footprint in the
//   2 cone columns it feeds (a tier view's pixel: the cells its cone extent meets), each resampled into at
//   most 2 beams. Budget: 2 cells per cone column and footprint bin of those pixels, counted here on both
//   backends' echoes.
// The H100's 24 failed the first budget when it was 1e-4 on every device.
// Labels hold ids in 16 bits: a draw whose object id passes 65535 is refused when labels are asked for
// (one line naming the draw and the id), and rendered as before without them.
TEST(LabelIds, IdsPastSixteenBitsAreRefusedOnlyWithLabels) {
    Scene scene;
    AcousticMaterial m;
    add_quad(scene, 10.0, 0.0, 0.0, 2.0, 2.0, m, 0.0, 70000);
    RendererOptions options;
    options.backend = Backend::cpu;
    options.save_mask = SaveFlags::labels;
    auto refused = Renderer::create(cpu_context(), quiet_config(), scene, options);
    ASSERT_FALSE(refused);
    EXPECT_EQ(refused.error().code, ErrorCode::invalid_argument);
    EXPECT_EQ(refused.error().message, "labels: draw 0 has instance id 70000; labels hold ids up to 65535");
    options.save_mask = SaveFlags::none;
    EXPECT_TRUE(Renderer::create(cpu_context(), quiet_config(), scene, options));
}

// A frame from a renderer without labels has the same bins x beams as a labels renderer's but no label
// arrays: render must refuse it (naming the first array of the wrong size) instead of the labels stage
// writing instance ... point past their ends. The labels renderer's own frame still renders.
TEST(LabelFrames, AFrameWithoutTheLabelArraysIsRefused) {
    Scene scene;
    AcousticMaterial m;
    add_quad(scene, 10.0, 0.0, 0.0, 2.0, 2.0, m, 0.0, 3);
    RendererOptions options;
    options.backend = Backend::cpu;
    options.host_threads = 1;
    auto plain = Renderer::create(cpu_context(), quiet_config(), scene, options);
    options.save_mask = SaveFlags::labels;
    auto labelled = Renderer::create(cpu_context(), quiet_config(), scene, options);
    ASSERT_TRUE(plain.ok() && labelled.ok());
    Frame foreign = plain->make_frame();
    ASSERT_EQ(foreign.clean.size(), labelled->make_frame().clean.size());
    auto refused = labelled->render(Pose{}, 0, foreign);
    ASSERT_FALSE(refused.ok());
    EXPECT_EQ(refused.error().code, ErrorCode::invalid_argument);
    EXPECT_EQ(refused.error().message.rfind("render: frame was not made by this renderer's make_frame() (Frame::depth "
                                            "has 0 elements, this renderer's ",
                                            0),
              0u)
        << refused.error().message;
    // Depth and echo sized by hand (as a labels frame's), the label arrays still missing: refused at instance.
    Frame own = labelled->make_frame();
    foreign.depth = own.depth;
    foreign.material = own.material;
    foreign.echo = own.echo;
    refused = labelled->render(Pose{}, 0, foreign);
    ASSERT_FALSE(refused.ok());
    EXPECT_NE(refused.error().message.find("(Frame::instance has 0 elements"), std::string::npos)
        << refused.error().message;
    EXPECT_TRUE(labelled->render(Pose{}, 0, own).ok());
}

TEST(LabelGpuCpu, BundledSceneLabelsAgree) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard validation;
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    const SonarConfig config = quiet_config();
    Pose pose;
    pose.pitch_deg = 10.0;
    const SaveFlags saves = SaveFlags::labels | SaveFlags::depth | SaveFlags::echo;
    auto gpu = render_once(Backend::vulkan, config, scene.value(), pose, saves);
    auto cpu = render_once(Backend::cpu, config, scene.value(), pose, saves);
    ASSERT_TRUE(gpu && cpu);
    const Frame &g = gpu->frame, &c = cpu->frame;
    ASSERT_EQ(g.depth.size(), c.depth.size());
    // The edge pixels, the pixels whose footprint reads one (reached), and their footprints' bins.
    const Plan& plan = renderer_plan(cpu->renderer);
    const std::uint32_t rows = plan.rows, columns = plan.columns;
    std::size_t edge_pixels = 0;
    std::vector<bool> reached(c.depth.size(), false);
    for (std::uint32_t j = 0; j < rows; ++j)
        for (std::uint32_t x = 0; x < columns; ++x) {
            const std::size_t p = std::size_t(j) * columns + x;
            if ((g.depth[p] > 0.0f) == (c.depth[p] > 0.0f) && g.material[p] == c.material[p]) continue;
            ++edge_pixels;
            for (int d = -2; d <= 2; ++d)
                if (int(j) + d >= 0 && int(j) + d < int(rows)) reached[p + std::ptrdiff_t(d) * columns] = true;
            if (x > 0) reached[p - 1] = true;
            if (x + 1 < columns) reached[p + 1] = true;
        }
    std::size_t footprint_bins = 0, footprint_cells = 0;
    for (std::uint32_t j = 0; j < rows; ++j)
        for (std::uint32_t x = 0; x < columns; ++x) {
            const std::size_t p = std::size_t(j) * columns + x;
            if (!reached[p]) continue;
            // the cone columns it feeds: 2, or a tier view's pixel's cells (sonar_kernels.h cone_extent_share)
            int cones = 2;
            if (plan.line_array && view_of_column(plan, x) >= plan.slices) {
                const std::uint32_t view = view_of_column(plan, x), first = view_first_column(plan, view);
                const float* row_x = plan.pixel_cone_coord.data() + std::size_t(j) * columns;
                const ConeExtent e = tier_cone_extent(row_x, x, first, first + view_columns(plan, view));
                cones = std::max(2, int(std::floor(e.hi + 0.5f)) - int(std::floor(e.lo + 0.5f)) + 1);
            }
            int bins = 0;
            for (const Frame* f : {&g, &c}) {
                if (!(f->echo[2 * p] > 0.0f)) continue;
                const auto s = cpu::pixel_spread<float>(plan, f->echo.data(), j, x, f->echo[2 * p],
                                                        plan.params.range_min_m, plan.params.inv_bin_width_m);
                bins = std::max(bins, s.k_last - s.k_first + 1);
            }
            footprint_bins += std::size_t(bins);
            footprint_cells += std::size_t(bins) * 2 * std::size_t(cones);
        }
    std::size_t labelled = 0, clear = 0, differ_clear = 0, differ_any = 0;
    double worst_elevation = 0;
    std::size_t elevation_off = 0;
    for (std::size_t i = 0; i < c.instance.size(); ++i) {
        labelled += c.instance[i] != 0;
        const bool is_clear = c.instance_fraction[i] >= 0.501f;
        clear += is_clear;
        differ_any += g.instance[i] != c.instance[i];
        if (is_clear && g.instance[i] != c.instance[i]) ++differ_clear;
        if (is_clear && g.instance[i] == c.instance[i]) {
            EXPECT_EQ(g.object_class[i], c.object_class[i]);
            const double d = std::abs(g.elevation[i] - c.elevation[i]);
            worst_elevation = std::max(worst_elevation, d);
            elevation_off += d > 1e-3;
        }
    }
    std::printf("[labels] gpu vs cpu: %zu labelled, %zu clear, %zu differ (%zu of them clear), elevation worst "
                "%.2e rad, %zu cells over 1e-3, %zu edge pixels (their reach: %zu footprint bins)\n",
                labelled, clear, differ_any, differ_clear, worst_elevation, elevation_off, edge_pixels, footprint_bins);
    EXPECT_GT(clear, labelled / 2);
    EXPECT_LE(double(differ_clear), vulkan_device_is_cpu() ? 0.0 : 1e-4 * double(clear));
    // The two budgets above.
    const double narrow_footprints = (vulkan_device_is_cpu() ? 1e-4 : 5e-4) * double(clear);
    EXPECT_LE(double(elevation_off), narrow_footprints + double(footprint_cells));
}

// The labels follow each pixel's energy over the same bins as the image: on the CPU backend their spreads
// and shares are the profile loop's own (float) or its kernel's in double (cpu.precision = double), so a
// cell has a label exactly where the main lobe put energy (beam_profiles, before the side lobes, > 0),
// cell for cell, in either precision, with either beam geometry and each range kernel. (In float with the
// spreads in double, as the labels had them before, one cell of the six float renders had a label but no
// main-lobe energy: line array, tent kernel.)
TEST(LabelCpu, LabelledCellsAreTheCellsTheMainLobeFills) {
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    Pose pose;
    pose.pitch_deg = 10.0;
    for (Precision precision : {Precision::f32, Precision::f64})
        for (BeamGeometry geometry : {BeamGeometry::line_array, BeamGeometry::planar})
            for (RangeKernel kernel : {RangeKernel::footprint, RangeKernel::tent, RangeKernel::nearest}) {
                SonarConfig config = quiet_config();
                config.cpu_precision = precision;
                config.beam_geometry = geometry;
                config.range_kernel = kernel;
                auto r =
                    render_once(Backend::cpu, config, scene.value(), pose, SaveFlags::labels | SaveFlags::profiles);
                ASSERT_TRUE(r);
                const Frame& f = r->frame;
                ASSERT_EQ(f.beam_profiles.size(), f.instance.size());
                std::size_t labelled = 0, label_only = 0, lobe_only = 0;
                for (std::size_t i = 0; i < f.instance.size(); ++i) {
                    const bool label = f.instance[i] != 0, lobe = f.beam_profiles[i] > 0.0f;
                    labelled += label;
                    label_only += label && !lobe;
                    lobe_only += lobe && !label;
                }
                const std::string what = std::string(precision == Precision::f64 ? "double, " : "float, ") +
                                         (geometry == BeamGeometry::planar ? "planar" : "line array") +
                                         ", range kernel " + std::to_string(int(kernel));
                EXPECT_GT(labelled, f.instance.size() / 8) << what;
                EXPECT_EQ(label_only, 0u) << what;
                EXPECT_EQ(lobe_only, 0u) << what;
            }
}

// A labelled frame at `from` (frame 0), the frame at `to` (frame 1) and the flow between them; `rendered` is
// null where a render or the flow failed.
struct FlowRun {
    std::unique_ptr<Rendered> rendered; // the frame at `from` and its renderer
    Frame next;                         // the frame at `to`
    std::vector<float> flow;
};
FlowRun flow_between(Backend backend, const SonarConfig& config, const Scene& scene, const Pose& from, const Pose& to) {
    FlowRun run;
    run.rendered = render_once(backend, config, scene, from, SaveFlags::labels);
    if (!run.rendered) return run;
    run.next = run.rendered->renderer.make_frame();
    if (!run.rendered->renderer.render(to, 1, run.next) ||
        !run.rendered->renderer.label_flow(run.rendered->frame, from, run.next, to, run.flow))
        run.rendered.reset();
    return run;
}

// Flow, sonar moving forward by d = 0.5 m in a static scene: each labelled point P of frame 0 moves to
// P - (d, 0, 0) in the sonar frame, so its range bin changes by (|P - d x| - |P|) / w and its beam by the
// change of its steering angle on the equi-angular table, computed here from P alone.
TEST_P(LabelBackendTest, FlowOfAForwardMove) {
    const SonarConfig config = labels_config(BeamGeometry::line_array);
    TwoObjects objects;
    Pose start, ahead;
    ahead.x_m = 0.5;
    const FlowRun run = flow_between(GetParam(), config, objects.scene, start, ahead);
    ASSERT_TRUE(run.rendered);
    const std::vector<float>& flow = run.flow;
    const Frame& f = run.rendered->frame;
    ASSERT_EQ(flow.size(), std::size_t(f.bins) * f.beams * 2);
    const double bin_width = (config.range_max_m - config.range_min_m) / config.bins;
    const double spacing = config.hfov_deg * kDeg / config.beams;
    std::size_t labelled = 0, finite = 0;
    double worst_bin = 0, worst_beam = 0;
    for (std::size_t i = 0; i < f.instance.size(); ++i) {
        if (f.instance[i] == 0) {
            ASSERT_TRUE(std::isnan(flow[2 * i]) && std::isnan(flow[2 * i + 1]));
            continue;
        }
        ++labelled;
        const Point3 p{f.point[3 * i], f.point[3 * i + 1], f.point[3 * i + 2]};
        if (std::isnan(flow[2 * i])) {
            // Hidden in the next frame: only the sphere's limb may be. Closer, the sonar sees less of the
            // sphere, so points within a few degrees of grazing from where it arrives turn away (or behind
            // the nearer surface within a pixel): the cosine between the sphere's normal there and the
            // direction to the sonar's new position is near 0 (measured: -0.09 .. 0.27).
            const bool sphere = f.instance[i] == kSphereId;
            EXPECT_TRUE(sphere) << "a cell of the quad lost from the next frame: bin " << i / f.beams;
            if (sphere) {
                const double n[3] = {p.x - objects.sphere.x, p.y - objects.sphere.y, p.z - objects.sphere.z};
                const double s[3] = {ahead.x_m - p.x, -p.y, -p.z};
                const double facing =
                    (n[0] * s[0] + n[1] * s[1] + n[2] * s[2]) /
                    std::sqrt((n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) * (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]));
                EXPECT_LT(facing, 0.35) << "bin " << i / f.beams << " beam " << i % f.beams << ": not at the limb";
            }
            continue;
        }
        ++finite;
        if (f.instance[i] == kSphereId) {
            // In view from the new pose, or so near its limb that a limb pixel's range footprint there reaches
            // it (the footprint's far end counts: see below): at most a few degrees past grazing (measured:
            // cosine -0.098 at the worst).
            const double n[3] = {p.x - objects.sphere.x, p.y - objects.sphere.y, p.z - objects.sphere.z};
            const double s[3] = {ahead.x_m - p.x, -p.y, -p.z};
            const double facing =
                (n[0] * s[0] + n[1] * s[1] + n[2] * s[2]) /
                std::sqrt((n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) * (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]));
            EXPECT_GT(facing, -0.15) << "bin " << i / f.beams << " beam " << i % f.beams << ": turned away";
        }
        const Point3 q{p.x - ahead.x_m, p.y, p.z};
        const double r0 = std::sqrt(p.x * p.x + p.y * p.y + p.z * p.z),
                     r1 = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z);
        const double d_bin = (r1 - r0) / bin_width;
        const double d_beam = (std::asin(p.y / r0) - std::asin(q.y / r1)) / spacing; // beams count to starboard
        worst_bin = std::max(worst_bin, std::abs(flow[2 * i] - d_bin));
        worst_beam = std::max(worst_beam, std::abs(flow[2 * i + 1] - d_beam));
    }
    std::printf("[labels] flow: %zu labelled cells, %zu with flow, worst error %.2e bins, %.2e beams\n", labelled,
                finite, worst_bin, worst_beam);
    // Nothing else hides anything here; the sphere's limb is a few of its cells (161 of 166 have a flow; 149
    // when only the pixels' own ranges counted, not their footprints' far ends).
    EXPECT_GT(finite, labelled * 4 / 5);
    EXPECT_LT(worst_bin, 1e-3);
    EXPECT_LT(worst_beam, 1e-3);
}

// Flow on a full circle (360 deg, 720 beams 0.5 deg apart), turning 4 deg to port: a sphere behind the sonar
// at azimuth 179 deg moves to 183 deg, across the seam between the last beam and the first. d_beam is the
// short way round, -8 beams here, not the +712 of the beam coordinates' plain difference; computed here as
// the change of each point's azimuth under the turn, wrapped into (-180, 180].
TEST_P(LabelBackendTest, FlowTakesTheShortWayRoundAFullCircle) {
    SonarConfig config = labels_config(BeamGeometry::planar);
    config.hfov_deg = 360.0;
    config.beams = 720;
    Scene scene;
    const Point3 centre = at(10.0, 179.0, 0.0);
    add_sphere(scene, centre.x, centre.y, centre.z, 0.3, 64, -10.0, kSphereId);
    Pose start, turned;
    turned.yaw_deg = -4.0; // a world point's azimuth in the sonar frame grows by 4 deg
    const FlowRun run = flow_between(GetParam(), config, scene, start, turned);
    ASSERT_TRUE(run.rendered);
    const std::vector<float>& flow = run.flow;
    const Frame& f = run.rendered->frame;
    const double spacing = 360.0 / config.beams; // deg
    std::size_t finite = 0, crossing = 0;
    double worst_beam = 0, worst_bin = 0;
    for (std::size_t i = 0; i < f.instance.size(); ++i) {
        if (f.instance[i] == 0 || std::isnan(flow[2 * i + 1])) continue;
        ++finite;
        const double azimuth = std::atan2(f.point[3 * i + 1], f.point[3 * i]) / kDeg;
        const double moved = std::remainder(azimuth + 4.0, 360.0); // (-180, 180]
        crossing += azimuth > 0 && moved < 0;
        const double d_beam = -std::remainder(moved - azimuth, 360.0) / spacing; // beams count to starboard
        worst_beam = std::max(worst_beam, std::abs(flow[2 * i + 1] - d_beam));
        worst_bin = std::max(worst_bin, std::abs(static_cast<double>(flow[2 * i]))); // a turn keeps every range
    }
    std::printf("[labels] flow on a full circle: %zu cells with flow, %zu across the seam, worst %.2e beams\n", finite,
                crossing, worst_beam);
    EXPECT_GT(crossing, 0u) << "no labelled point crosses the seam: the case is not tested";
    EXPECT_LT(worst_beam, 1e-3);
    EXPECT_LT(worst_bin, 1e-3);
}

// Flow of a frame to itself (the same pose, the same frame): every labelled cell's point is where its
// own pixel sees it, so it has a flow, and the flow is 0. Over the bundled scene's seabed, pitched 10 deg
// down, the vertical side lobes' tier views hold points below the main band, past the default sinc
// pattern's first null (23.2 deg, the elevation gate) and past the slices' bottom row (25.3 deg at a
// slice's centre column, for the default's three 49.6-degree slices). Those points too: before each
// direction was looked up in the view whose elevation band holds it, everything below the slices'
// bottom row counted as hidden (here 11547 of the 12162 such points).
TEST_P(LabelBackendTest, FlowOfAFrameToItselfIsZeroWhereverThereIsALabel) {
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    Pose pose;
    pose.pitch_deg = 10.0;
    // (planar beams have no tier views: their pixel grid ends at the slices' rows.) The tent and nearest
    // kernels too: the tent puts a pixel up to half a bin beyond either end of the window into the end bin,
    // its point where the pixel is, so that half bin counts as inside the window (the flow's bin then runs
    // from -0.5 to bins + 0.5).
    struct Case {
        BeamGeometry geometry;
        RangeKernel kernel;
        const char* what;
    };
    for (const Case& c : {Case{BeamGeometry::line_array, RangeKernel::footprint, "line array"},
                          Case{BeamGeometry::planar, RangeKernel::footprint, "planar"},
                          Case{BeamGeometry::line_array, RangeKernel::tent, "line array, tent"},
                          Case{BeamGeometry::line_array, RangeKernel::nearest, "line array, nearest"}}) {
        const bool line_array = c.geometry == BeamGeometry::line_array;
        SonarConfig config = quiet_config();
        config.beam_geometry = c.geometry;
        config.range_kernel = c.kernel;
        auto r = render_once(GetParam(), config, scene.value(), pose, SaveFlags::labels);
        ASSERT_TRUE(r);
        std::vector<float> flow;
        ASSERT_TRUE(r->renderer.label_flow(r->frame, pose, r->frame, pose, flow));
        const Frame& f = r->frame;
        std::size_t labelled = 0, without = 0, nonzero = 0, steep = 0, steep_without = 0;
        for (std::size_t i = 0; i < f.instance.size(); ++i) {
            if (f.instance[i] == 0) continue;
            ++labelled;
            const double x = f.point[3 * i], y = f.point[3 * i + 1], z = f.point[3 * i + 2];
            const bool below_slices = std::asin(z / std::sqrt(x * x + y * y + z * z)) < -26.0 * kDeg;
            steep += below_slices;
            if (std::isnan(flow[2 * i]) || std::isnan(flow[2 * i + 1])) {
                ++without;
                steep_without += below_slices;
                continue;
            }
            // exactly 0: with the same pose the point is not carried to the world frame and back (which
            // left it a few ulps off, flows up to 3e-13 bins)
            nonzero += flow[2 * i] != 0.0f || flow[2 * i + 1] != 0.0f;
        }
        const char* what = c.what;
        std::printf("[labels] flow to itself, %s: %zu labelled cells, %zu without a flow; %zu below the slices, %zu "
                    "of them without\n",
                    what, labelled, without, steep, steep_without);
        if (line_array) {
            EXPECT_GT(steep, labelled / 100) << what; // the tier views do hold labelled points here
        }
        EXPECT_EQ(steep_without, 0u) << what;
        // Nor any other: a point lies in its pixel's range footprint, up to half of it beyond the pixel's own
        // range, and the footprint's far end counts where no pixel's range reaches the point (1336 cells had
        // no flow before it did: the seabed's far edge at the fan's edges, the top of an object seen from
        // below).
        EXPECT_EQ(without, 0u) << what;
        EXPECT_EQ(nonzero, 0u) << what;
    }
}

// Flow, occlusion: from the origin a sphere at (14, 5, 0) is in view beside a wall at x = 8; from
// (0, -6.67, 0) the wall lies on the line to the sphere and hides it. The sphere's cells get no flow;
// the wall's, in view from both, do.
TEST_P(LabelBackendTest, FlowStopsAtAnOccluder) {
    const SonarConfig config = labels_config(BeamGeometry::line_array);
    Scene scene;
    add_sphere(scene, 14.0, 5.0, 0.0, 0.4, 48, -10.0, kSphereId);
    AcousticMaterial m;
    m.backscatter_db = -20.0;
    add_quad(scene, 8.0, 0.0, 0.0, 4.0, 4.0, m, 0.0, kQuadId);
    Pose start, aside;
    aside.y_m = -6.67;
    const FlowRun run = flow_between(GetParam(), config, scene, start, aside);
    ASSERT_TRUE(run.rendered);
    const auto& r = run.rendered;
    EXPECT_EQ(std::count(run.next.instance.begin(), run.next.instance.end(), kSphereId), 0); // hidden indeed
    const std::vector<float>& flow = run.flow;
    std::size_t sphere = 0, sphere_flow = 0, wall = 0, wall_flow = 0;
    for (std::size_t i = 0; i < r->frame.instance.size(); ++i) {
        const bool has = !std::isnan(flow[2 * i]);
        if (r->frame.instance[i] == kSphereId) {
            ++sphere;
            sphere_flow += has;
        } else if (r->frame.instance[i] == kQuadId) {
            ++wall;
            wall_flow += has;
        }
    }
    std::printf("[labels] occluded flow: sphere %zu cells, %zu with flow; wall %zu cells, %zu with flow\n", sphere,
                sphere_flow, wall, wall_flow);
    EXPECT_GT(sphere, 0u);
    EXPECT_EQ(sphere_flow, 0u);
    EXPECT_GT(wall_flow, wall * 8 / 10);
}

// Frame::visibility against geometry: a wall 8 m away covering azimuths below 0 (y in [-4, 0] at
// x = 8) hides exactly the starboard half of a sphere 14 m ahead (the sonar's view of it is symmetric
// about azimuth 0); the wall itself is hidden nowhere. Then, alone, the sphere with range_max = 13.5:
// the part of its visible surface beyond 13.5 m is outside the window. A ray at angle t from the
// centre direction meets the sphere (distance D, radius a) at r(t) = D cos t - sqrt(a^2 - D^2 sin^2 t),
// so that part is the cap t < t_out with r(t_out) = 13.5, its share of the disc t < asin(a / D) in
// solid angle (1 - cos t_out) / (1 - cos t_max). Tolerance: the pixels along the disc's edge and the
// cut (one pixel wide, about 8 % of a 13-pixel-radius disc; 0.05 on a half).
// A sphere of radius a at distance D straight ahead and, 8 m away, a wall covering the azimuths below 0
// (the visibility tests).
void add_sphere_behind_half_wall(Scene& scene, double D, double a, std::uint32_t sphere_id, std::uint32_t wall_id) {
    add_sphere(scene, D, 0.0, 0.0, a, 96, -10.0, sphere_id);
    AcousticMaterial m;
    m.backscatter_db = -20.0;
    add_quad(scene, 8.0, -2.0, 0.0, 4.0, 6.0, m, 0.0, wall_id);
}

TEST_P(LabelBackendTest, VisibilityOfAHalfHiddenAndAPartlyOutsideObject) {
    const double D = 14.0, a = 1.0;
    {
        const SonarConfig config = labels_config(BeamGeometry::line_array);
        Scene scene;
        add_sphere_behind_half_wall(scene, D, a, kSphereId, kQuadId);
        auto r = render_once(GetParam(), config, scene, {}, SaveFlags::labels);
        ASSERT_TRUE(r);
        const auto& vis = r->frame.visibility;
        ASSERT_EQ(vis.size(), 2u);
        EXPECT_EQ(vis[0].instance, kSphereId);
        EXPECT_EQ(vis[1].instance, kQuadId);
        const double hidden = double(vis[0].hidden) / vis[0].pixels;
        std::printf("[labels] sphere behind a half wall: %u pixels, hidden %.3f (expected 0.5); wall hidden %u\n",
                    vis[0].pixels, hidden, vis[1].hidden);
        EXPECT_NEAR(hidden, 0.5, 0.05);
        EXPECT_EQ(vis[0].outside, 0u);
        EXPECT_EQ(vis[1].hidden, 0u);
    }
    {
        SonarConfig config = labels_config(BeamGeometry::line_array);
        config.range_max_m = 13.5;
        Scene scene;
        add_sphere(scene, D, 0.0, 0.0, a, 96, -10.0, kSphereId);
        auto r = render_once(GetParam(), config, scene, {}, SaveFlags::labels);
        ASSERT_TRUE(r);
        ASSERT_EQ(r->frame.visibility.size(), 1u);
        const ObjectVisibility& v = r->frame.visibility[0];
        // r(t) = 13.5 by bisection on t in [0, t_max] (r grows with t)
        const double t_max = std::asin(a / D);
        double lo = 0.0, hi = t_max;
        for (int i = 0; i < 100; ++i) {
            const double t = 0.5 * (lo + hi);
            const double range = D * std::cos(t) - std::sqrt(std::max(0.0, a * a - D * D * std::sin(t) * std::sin(t)));
            (range < 13.5 ? lo : hi) = t;
        }
        const double expected = 1.0 - (1.0 - std::cos(lo)) / (1.0 - std::cos(t_max));
        const double outside = double(v.outside) / v.pixels;
        std::printf("[labels] sphere across range_max: %u pixels, outside %.3f (expected %.3f)\n", v.pixels, outside,
                    expected);
        EXPECT_EQ(v.hidden, 0u);
        EXPECT_NEAR(outside, expected, 0.05);
    }
}

// The objects are drawn alone one after another into one image that is not cleared between them: each
// one's tally puts the pixels it drew back to empty (src/stages/labels.cpp, Alone::depth). Here the wall
// has the lower id and so is drawn first, 6 m nearer than the sphere: a pixel of it left behind would
// win the strict depth test against the sphere there, and the sphere would lose the half behind the wall
// from its own pixels (and from `hidden`). A second frame of the same renderer (whose image the first
// frame's last object left) must count the same, and so must a renderer labelling the sphere alone.
TEST_P(LabelBackendTest, ObjectsDrawnAloneDoNotSeeTheObjectsDrawnBefore) {
    const double D = 14.0, a = 1.0;
    const std::uint32_t wall_id = 3, sphere_id = 5;
    const SonarConfig config = labels_config(BeamGeometry::line_array);
    Scene scene;
    add_sphere_behind_half_wall(scene, D, a, sphere_id, wall_id);
    auto r = render_once(GetParam(), config, scene, {}, SaveFlags::labels);
    ASSERT_TRUE(r);
    const std::vector<ObjectVisibility> first = r->frame.visibility;
    ASSERT_EQ(first.size(), 2u);
    ASSERT_EQ(first[0].instance, wall_id);
    ASSERT_EQ(first[1].instance, sphere_id);
    ASSERT_TRUE(r->renderer.render({}, 1, r->frame));
    ASSERT_EQ(r->frame.visibility.size(), 2u);
    for (std::size_t i = 0; i < first.size(); ++i) {
        EXPECT_EQ(r->frame.visibility[i].pixels, first[i].pixels) << i;
        EXPECT_EQ(r->frame.visibility[i].hidden, first[i].hidden) << i;
        EXPECT_EQ(r->frame.visibility[i].outside, first[i].outside) << i;
    }
    Scene sphere_only;
    add_sphere(sphere_only, D, 0.0, 0.0, a, 96, -10.0, sphere_id);
    auto alone = render_once(GetParam(), config, sphere_only, {}, SaveFlags::labels | SaveFlags::depth);
    ASSERT_TRUE(alone);
    ASSERT_EQ(alone->frame.visibility.size(), 1u);
    EXPECT_EQ(alone->frame.visibility[0].hidden, 0u);
    // Alone in the scene, the sphere drawn alone is the frame's depth image: the same rasterizer on the
    // CPU backend (every pixel, so a tally that misses a row or column of what it drew fails), the GPU's
    // coverage on Vulkan (a few pixels along the silhouette may differ: 2 % of a 1148-pixel disc).
    const auto frame_pixels = static_cast<std::uint32_t>(
        std::count_if(alone->frame.depth.begin(), alone->frame.depth.end(), [](float d) { return d > 0.0f; }));
    if (GetParam() == Backend::cpu)
        EXPECT_EQ(alone->frame.visibility[0].pixels, frame_pixels);
    else
        EXPECT_NEAR(double(alone->frame.visibility[0].pixels), double(frame_pixels), 0.02 * frame_pixels);
    // the sphere's own pixels do not depend on the wall in front of it, half of them hidden by it
    EXPECT_EQ(first[1].pixels, alone->frame.visibility[0].pixels);
    EXPECT_NEAR(double(first[1].hidden) / first[1].pixels, 0.5, 0.05);
    EXPECT_EQ(first[0].hidden, 0u);
}

// Flow with cpu.vector_loops off runs the plain loop where this CPU would take four labelled cells at a
// time (AVX2): the same flow, byte for byte. Line array and planar fans, each with a move that takes
// points out of the window, past the fan's edges (a yaw of 20 deg) and in front of the sonar (a step
// forward), so that the lanes' other cases (beam_coordinate's edges, NaN ranges, no view) come up; and
// a frame of 37 beams, whose labelled cells do not fill whole groups of four.
TEST(CpuVectorLoops, FlowOffGivesTheSameBytes) {
    if (!cpu::use_avx2(SonarConfig{})) GTEST_SKIP() << "this CPU has no AVX2: both settings run the same loop";
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    Pose from, to;
    from.pitch_deg = to.pitch_deg = 10.0;
    to.x_m = 3.0;
    to.y_m = 1.0;
    to.yaw_deg = 20.0;
    std::vector<std::pair<const char*, SonarConfig>> configs;
    configs.emplace_back("line array", quiet_config());
    configs.emplace_back("planar", quiet_config());
    configs.back().second.beam_geometry = BeamGeometry::planar;
    configs.emplace_back("37 beams", quiet_config());
    configs.back().second.beams = 37;
    for (const auto& [name, config] : configs) {
        std::vector<float> flows[2];
        std::size_t labelled = 0;
        for (int off = 0; off < 2; ++off) {
            SonarConfig c = config;
            c.cpu_vector_loops = off ? CpuVectorLoops::off : CpuVectorLoops::automatic;
            auto r = render_once(Backend::cpu, c, scene.value(), from, SaveFlags::labels);
            ASSERT_TRUE(r) << name;
            Frame next = r->renderer.make_frame();
            ASSERT_TRUE(r->renderer.render(to, 1, next)) << name;
            ASSERT_TRUE(r->renderer.label_flow(r->frame, from, next, to, flows[off])) << name;
            labelled = static_cast<std::size_t>(
                std::count_if(r->frame.instance.begin(), r->frame.instance.end(), [](auto id) { return id != 0; }));
        }
        std::size_t finite = 0;
        for (std::size_t i = 0; i < flows[0].size(); i += 2)
            finite += !std::isnan(flows[0][i]);
        std::printf("[labels] flow, %s: %zu labelled cells, %zu with a flow\n", name, labelled, finite);
        EXPECT_GT(finite, labelled / 4) << name; // most of the seabed stays in view
        EXPECT_LT(finite, labelled) << name;     // and some of it leaves
        ASSERT_EQ(flows[0].size(), flows[1].size()) << name;
        EXPECT_EQ(std::memcmp(flows[0].data(), flows[1].data(), flows[0].size() * sizeof(float)), 0) << name;
    }
}

// Flow finds the beam an angle falls on through BeamBuckets instead of a binary search: the same first
// beam below the angle for evenly spaced, sine-spaced and irregular tables (2 to 1024 beams), at random
// angles, at every beam's own angle and just beside it.
TEST(LabelFlowBeams, BucketsFindTheBinarySearchsBeam) {
    std::uint64_t state = 88172645463325252ull;
    auto uniform = [&] { // [0, 1)
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        return double(state >> 11) * 0x1.0p-53;
    };
    for (std::size_t n : {2u, 3u, 7u, 130u, 512u, 1024u}) {
        for (int kind = 0; kind < 3; ++kind) {
            std::vector<double> t(n);
            for (std::size_t j = 0; j < n; ++j) {
                const double x = 1.0 - 2.0 * double(j) / double(n - 1); // 1 .. -1
                const double spacing = 2.2 / double(n - 1); // kind 2: each angle moved by up to 0.3 spacings
                t[j] = kind == 0   ? 1.1 * x
                       : kind == 1 ? std::asin(0.9 * x)
                                   : 1.1 * x + 0.3 * spacing * std::sin(7.0 * j);
            }
            ASSERT_TRUE(std::is_sorted(t.rbegin(), t.rend()) && std::adjacent_find(t.begin(), t.end()) == t.end());
            const cpu::BeamBuckets buckets(t);
            ASSERT_EQ(buckets.first.size(), 4 * n);
            std::vector<double> angles;
            for (int i = 0; i < 2000; ++i)
                angles.push_back(t[n - 1] + (t[0] - t[n - 1]) * uniform());
            for (std::size_t j = 1; j + 1 < n; ++j) {
                angles.push_back(t[j]);
                angles.push_back(std::nextafter(t[j], 10.0));
                angles.push_back(std::nextafter(t[j], -10.0));
            }
            for (double a : angles) {
                if (!(a > t[n - 1] && a < t[0])) continue;
                const auto expected = static_cast<std::size_t>(
                    std::upper_bound(t.begin(), t.end(), a, [](double x, double angle) { return x > angle; }) -
                    t.begin());
                ASSERT_EQ(buckets.first_below(t, a), expected) << n << " beams, table " << kind << ", angle " << a;
            }
        }
    }
}

INSTANTIATE_TEST_SUITE_P(Backends, LabelBackendTest, ::testing::Values(Backend::vulkan, Backend::cpu),
                         [](const ::testing::TestParamInfo<Backend>& param_info) {
                             return param_info.param == Backend::cpu ? std::string("cpu") : std::string("vulkan");
                         });

} // namespace
} // namespace vksonar::testing
