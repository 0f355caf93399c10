// accuracy.normal_method = geometric: the depth pass records each pixel's face normal. Analytic
// checks on both backends (a tilted plane; a strip one pixel tall, where the Sobel has nothing to
// differentiate), the plan's rule that only geometric pays for the attachment, and the host-depth
// refusal. The GPU-vs-CPU comparison on the bundled scenes is in gpu_cpu_test.cpp.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/host_plan.h"
#include "test_support.h"
#include "tolerances.h"

namespace vksonar::testing {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kTiltDeg = 50.0; // plane tilt: normal (cos a, 0, -sin a), 50 deg off the sonar axis

// A plane through (10, 0, z_centre) spanned by e_y (half width `half_w`) and t = (sin a, 0, cos a)
// (half extent `half_t`); its unit normal is e_y x t = (cos a, 0, -sin a).
void add_tilted_plane(Scene& scene, double z_centre, double half_w, double half_t) {
    const double a = kTiltDeg * kPi / 180.0;
    const double tx = std::sin(a) * half_t, tz = std::cos(a) * half_t;
    const float positions[] = {float(10 - tx),       float(-half_w),       float(z_centre - tz), float(10 - tx),
                               float(half_w),        float(z_centre - tz), float(10 + tx),       float(half_w),
                               float(z_centre + tz), float(10 + tx),       float(-half_w),       float(z_centre + tz)};
    const std::uint32_t indices[] = {0, 1, 2, 0, 2, 3};
    auto mesh = scene.add_mesh(positions, 4, indices, 6);
    ASSERT_TRUE(mesh.ok()) << mesh.error().message;
    AcousticMaterial material;
    material.name = "tilted";
    material.backscatter_db = -20.0;
    SceneDraw draw;
    draw.mesh = mesh.value();
    auto material_index = scene.add_material(material);
    ASSERT_TRUE(material_index.ok()) << material_index.error().message;
    draw.material = material_index.value();
    draw.world_from_local = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    auto added = scene.add_draw(draw);
    ASSERT_TRUE(added.ok()) << added.error().message;
}

SonarConfig geometric_config(NormalMethod method = NormalMethod::geometric) {
    SonarConfig config = quiet_config();
    config.normal_method = method;
    return config;
}

// Exact unit ray of pixel (column, row) in the sonar frame, from the plan in double.
void pixel_ray(const Plan& plan, std::uint32_t column, std::uint32_t row, double ray[3]) {
    // the view's camera (a slice, or a tier view of the vertical side lobes): forward + u right + v down
    const std::uint32_t s = view_of_column(plan, column), width = view_columns(plan, s);
    const ViewGeometry& view = plan.view_geometry[s];
    const double u = (2.0 * (column - view_first_column(plan, s) + 0.5) / width - 1.0) * view.tan_half_h;
    const double v = (2.0 * (row + 0.5) / plan.rows - 1.0) * view.tan_half_v;
    double d[3];
    for (int k = 0; k < 3; ++k)
        d[k] = view.forward[k] + u * view.right[k] + v * view.down[k];
    const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (int k = 0; k < 3; ++k)
        ray[k] = d[k] / len;
}

struct PlaneErrors {
    std::size_t hits = 0;
    std::uint32_t first_row = ~0u, last_row = 0;
    double max_angle_deg = 0, max_cos_err = 0;
    double min_cos = 2, max_cos = -1;
};

// Compares a frame's normals with the plane's normal (turned to face the sonar) and its cos incidence
// with the closed form |n . ray|.
PlaneErrors plane_errors(const Plan& plan, const Frame& f) {
    const double a = kTiltDeg * kPi / 180.0;
    const double n_plane[3] = {-std::cos(a), 0.0, std::sin(a)}; // faces a sonar on the -x side
    PlaneErrors e;
    for (std::uint32_t row = 0; row < f.rows; ++row) {
        for (std::uint32_t col = 0; col < f.columns; ++col) {
            const std::size_t i = std::size_t(row) * f.columns + col;
            if (!(f.depth[i] > 0)) continue;
            ++e.hits;
            e.first_row = std::min(e.first_row, row);
            e.last_row = std::max(e.last_row, row);
            const double* n = n_plane;
            const double g[3] = {f.normals[4 * i], f.normals[4 * i + 1], f.normals[4 * i + 2]};
            const double cx = n[1] * g[2] - n[2] * g[1], cy = n[2] * g[0] - n[0] * g[2], cz = n[0] * g[1] - n[1] * g[0];
            const double angle =
                std::atan2(std::sqrt(cx * cx + cy * cy + cz * cz), n[0] * g[0] + n[1] * g[1] + n[2] * g[2]);
            e.max_angle_deg = std::max(e.max_angle_deg, angle * 180.0 / kPi);
            double ray[3];
            pixel_ray(plan, col, row, ray);
            const double cos_exact = std::abs(n[0] * ray[0] + n[1] * ray[1] + n[2] * ray[2]);
            const double cos_got = f.normals[4 * i + 3];
            e.max_cos_err = std::max(e.max_cos_err, std::abs(cos_got - cos_exact));
            e.min_cos = std::min(e.min_cos, cos_got);
            e.max_cos = std::max(e.max_cos, cos_got);
        }
    }
    return e;
}

void expect_plane_exact(Backend backend) {
    Scene scene;
    add_tilted_plane(scene, 0.0, 6.0, 3.0);
    auto r = render_once(backend, geometric_config(), scene, {}, SaveFlags::depth | SaveFlags::normals);
    ASSERT_TRUE(r);
    const Plan& plan = renderer_plan(r->renderer);
    ASSERT_TRUE(plan.face_normals);
    ASSERT_GT(plan.slices, 1u);
    const PlaneErrors e = plane_errors(plan, r->frame);
    std::printf("[geometric] %s plane: %zu hits, max angle %.2e deg, max |cos - closed form| %.2e (cos %.3f..%.3f)\n",
                backend == Backend::vulkan ? "vulkan" : "cpu", e.hits, e.max_angle_deg, e.max_cos_err, e.min_cos,
                e.max_cos);
    ASSERT_GT(e.hits, 1000u);
    EXPECT_LE(e.max_angle_deg, kGeometricPlaneAngleTolDeg); // every pixel, edges included: one plane
    EXPECT_LE(e.max_cos_err, kGeometricPlaneCosTol);
}

TEST(GeometricNormals, TiltedPlaneIsExactOnTheCpu) {
    expect_plane_exact(Backend::cpu);
}

TEST(GeometricNormals, TiltedPlaneIsExactOnVulkan) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard validation;
    expect_plane_exact(Backend::vulkan);
}

// A strip of the tilted plane 0.4 pixel tall, centred on one pixel row: every hit pixel has no valid
// vertical neighbour, so sobel3 (and sobel5) fall back to a sonar-facing normal (cos = 1), while the
// face normal still gives the plane's own incidence (cos ~ cos 50 deg = 0.64).
void expect_strip_beats_sobel(Backend backend) {
    // The plan of the default config gives the row geometry (it does not depend on the scene's shape).
    Scene probe;
    add_tilted_plane(probe, 0.0, 6.0, 3.0);
    auto probe_render = render_once(Backend::cpu, geometric_config(), probe);
    ASSERT_TRUE(probe_render);
    const Plan& plan = renderer_plan(probe_render->renderer);
    const std::uint32_t row = plan.rows / 2;
    const double v = (2.0 * (row + 0.5) / plan.rows - 1.0) * plan.tan_half_v;
    const double pixel_height_m = 10.0 * 2.0 * plan.tan_half_v / plan.rows;
    const double half_t = 0.2 * pixel_height_m / std::cos(kTiltDeg * kPi / 180.0);

    Scene strip;
    add_tilted_plane(strip, -10.0 * v, 3.0, half_t);
    auto geo = render_once(backend, geometric_config(), strip, {}, SaveFlags::depth | SaveFlags::normals);
    auto sobel =
        render_once(backend, geometric_config(NormalMethod::sobel3), strip, {}, SaveFlags::depth | SaveFlags::normals);
    ASSERT_TRUE(geo && sobel);
    const PlaneErrors g = plane_errors(renderer_plan(geo->renderer), geo->frame);
    const PlaneErrors s = plane_errors(renderer_plan(sobel->renderer), sobel->frame);
    std::printf("[geometric] %s strip: %zu hits in rows %u..%u; geometric max |cos err| %.2e, sobel3 %.3f\n",
                backend == Backend::vulkan ? "vulkan" : "cpu", g.hits, g.first_row, g.last_row, g.max_cos_err,
                s.max_cos_err);
    ASSERT_GT(g.hits, 20u);
    ASSERT_EQ(g.first_row, row); // one row only: the Sobel has no vertical neighbour anywhere
    ASSERT_EQ(g.last_row, row);
    EXPECT_LE(g.max_cos_err, kGeometricPlaneCosTol);
    EXPECT_LE(g.max_angle_deg, kGeometricPlaneAngleTolDeg);
    EXPECT_EQ(s.min_cos, 1.0); // the facing fallback, everywhere on the strip
    EXPECT_GT(s.max_cos_err, 0.3);
}

TEST(GeometricNormals, OnePixelStripBeatsSobelOnTheCpu) {
    expect_strip_beats_sobel(Backend::cpu);
}

TEST(GeometricNormals, OnePixelStripBeatsSobelOnVulkan) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard validation;
    expect_strip_beats_sobel(Backend::vulkan);
}

TEST(GeometricNormals, OnlyGeometricPlansTheAttachment) {
    Scene scene;
    add_tilted_plane(scene, 0.0, 6.0, 3.0);
    for (NormalMethod method : {NormalMethod::sobel3, NormalMethod::sobel5, NormalMethod::geometric}) {
        auto r = render_once(Backend::cpu, geometric_config(method), scene);
        ASSERT_TRUE(r);
        EXPECT_EQ(renderer_plan(r->renderer).face_normals, method == NormalMethod::geometric);
    }
    // Without the incidence effect no normals are needed, so geometric records nothing either.
    SonarConfig off = geometric_config();
    off.effects.incidence = EffectMode::off;
    auto r = render_once(Backend::cpu, off, scene);
    ASSERT_TRUE(r);
    EXPECT_FALSE(renderer_plan(r->renderer).face_normals);
}

TEST(GeometricNormals, HostDepthImageIsRefusedByName) {
    HostDepthDesc desc; // the method is checked first: the description does not matter
    auto plan = make_host_depth_plan(geometric_config(), desc);
    ASSERT_FALSE(plan.ok());
    EXPECT_NE(plan.error().message.find("accuracy.normal_method"), std::string::npos) << plan.error().message;
    EXPECT_EQ(plan.error().message.find('\n'), std::string::npos);
}

} // namespace
} // namespace vksonar::testing
