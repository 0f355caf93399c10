// Helpers for the numerical hard cases of docs/hard_cases.md (tests/hard_cases/*): small configs, scenes
// built in code, a render that keeps every intermediate, and the "no NaN/Inf in any stage" check.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <ostream>
#include <string>
#include <vector>

#include "test_support.h"

namespace vksonar {
// gtest prints an enum parameter as raw bytes; name the backend instead.
inline void PrintTo(Backend backend, std::ostream* os) {
    *os << (backend == Backend::vulkan ? "vulkan" : "cpu");
}
} // namespace vksonar

namespace vksonar::testing::hard {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;
constexpr SaveFlags kSaveAll = SaveFlags::depth | SaveFlags::normals | SaveFlags::echo | SaveFlags::profiles;

// Every hard case runs on both backends (one body, TEST_P over Backend).
class HardCase : public ::testing::TestWithParam<Backend> {
protected:
    void SetUp() override {
        if (GetParam() == Backend::vulkan) VKSONAR_REQUIRE_VULKAN();
    }
    ValidationGuard validation_;
};

inline std::string backend_name(const ::testing::TestParamInfo<Backend>& info) {
    return info.param == Backend::vulkan ? "vulkan" : "cpu";
}

// A small, clean (noise-free) sonar: 1 slice of 60 deg, 64 beams, 128 bins over 0.5..40 m and
// 32 x 64 rows; every deterministic effect on so that every stage runs.
inline SonarConfig small_config() {
    SonarConfig c = quiet_config();
    // The grid-level closed forms of these cases (frustum solid angles, beams by azimuth) are the
    // planar geometry's; line_array's hard cases: tests/beam_geometry_test.cpp.
    c.beam_geometry = BeamGeometry::planar;
    c.hfov_deg = 60.0;
    c.vfov_deg = 20.0;
    c.horizontal_beamwidth_deg = 2.0;
    c.beams = 64;
    c.bins = 128;
    c.range_min_m = 0.5;
    c.range_max_m = 40.0;
    c.rows_per_vfov = 16;
    c.pixels_per_beam = 2.0;
    c.fan_width_px = 64;
    c.absorption_db_per_m = 0.05;
    c.effects.incidence = EffectMode::on;
    c.effects.vertical_pattern = EffectMode::on;
    c.effects.horizontal_pattern = EffectMode::on;
    c.effects.spreading = EffectMode::on;
    c.effects.absorption = EffectMode::on;
    return c;
}

// Every value every stage produced is finite, and each lies in its documented domain.
inline void expect_every_stage_finite(const Frame& f) {
    const auto check = [](const std::vector<float>& v, const char* stage, float lo, float hi) {
        std::size_t bad = 0, first = 0;
        for (std::size_t i = 0; i < v.size(); ++i) {
            if (!(std::isfinite(v[i]) && v[i] >= lo && v[i] <= hi)) {
                if (bad++ == 0) first = i;
            }
        }
        EXPECT_EQ(bad, 0u) << stage << ": " << bad << " values non-finite or outside [" << lo << ", " << hi
                           << "], first at " << first << " = " << (bad ? v[first] : 0.0f);
    };
    const float big = 3.0e38f; // finite: everything below FLT_MAX
    check(f.depth, "depth", 0.0f, 1.0f);
    check(f.normals, "normals", -1.0001f, 1.0001f); // unit vectors and cos in [0, 1], float rounding
    check(f.echo, "echo", 0.0f, big);
    check(f.profiles, "profiles", 0.0f, big);
    check(f.beam_profiles, "beam_profiles", 0.0f, big);
    check(f.clean, "clean", 0.0f, big);
    check(f.intensity, "intensity", 0.0f, big);
    check(f.display, "display", 0.0f, 1.0f);
    EXPECT_EQ(f.clean.size(), std::size_t(f.bins) * f.beams);
    EXPECT_EQ(f.intensity.size(), f.clean.size());
    EXPECT_EQ(f.display.size(), f.clean.size());
}

// Renders with every intermediate kept and checks every stage for NaN/Inf.
inline std::unique_ptr<Rendered> render_checked(Backend backend, const SonarConfig& config, const Scene& scene,
                                                const Pose& pose = {}) {
    auto r = render_once(backend, config, scene, pose, kSaveAll);
    if (r) expect_every_stage_finite(r->frame);
    return r;
}

// Adds a mesh drawn with a column-major world matrix and a material of the given strength; its draw carries
// `instance` (SceneDraw::instance, for labels).
inline void add_mesh_draw(Scene& scene, const std::vector<float>& positions, const std::vector<std::uint32_t>& indices,
                          const std::array<double, 16>& world_from_local, const AcousticMaterial& material,
                          std::uint32_t instance = 0) {
    auto mesh = scene.add_mesh(positions.data(), static_cast<std::uint32_t>(positions.size() / 3), indices.data(),
                               static_cast<std::uint32_t>(indices.size()));
    ASSERT_TRUE(mesh.ok()) << mesh.error().message;
    SceneDraw draw;
    draw.mesh = mesh.value();
    auto material_index = scene.add_material(material);
    ASSERT_TRUE(material_index.ok()) << material_index.error().message;
    draw.material = material_index.value();
    draw.world_from_local = world_from_local;
    draw.instance = instance;
    auto added = scene.add_draw(draw);
    ASSERT_TRUE(added.ok()) << added.error().message;
}

inline void add_mesh_draw(Scene& scene, const std::vector<float>& positions, const std::vector<std::uint32_t>& indices,
                          const std::array<double, 16>& world_from_local, double backscatter_db = -20.0,
                          AcousticMaterial::Model model = AcousticMaterial::Model::lambert) {
    AcousticMaterial material;
    material.name = "m" + std::to_string(scene.materials().size());
    material.backscatter_db = backscatter_db;
    material.model = model;
    add_mesh_draw(scene, positions, indices, world_from_local, material);
}

inline std::array<double, 16> translation(double x, double y, double z) {
    return {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, x, y, z, 1};
}

// Axis-aligned closed box [lo, hi]^3 (12 triangles).
inline void add_box(Scene& scene, const std::array<double, 3>& lo, const std::array<double, 3>& hi,
                    double backscatter_db = -20.0, AcousticMaterial::Model model = AcousticMaterial::Model::lambert,
                    const std::array<double, 16>& world_from_local = translation(0, 0, 0)) {
    std::vector<float> p;
    for (int i = 0; i < 8; ++i) {
        p.push_back(static_cast<float>(i & 1 ? hi[0] : lo[0]));
        p.push_back(static_cast<float>(i & 2 ? hi[1] : lo[1]));
        p.push_back(static_cast<float>(i & 4 ? hi[2] : lo[2]));
    }
    add_mesh_draw(scene, p, {0, 2, 6, 0, 6, 4, 1, 5, 7, 1, 7, 3, 0, 4, 5, 0, 5, 1,
                             2, 3, 7, 2, 7, 6, 0, 1, 3, 0, 3, 2, 4, 6, 7, 4, 7, 5},
                  world_from_local, backscatter_db, model);
}

// UV sphere of radius r centred at the origin (segments around z, rings pole to pole).
inline void add_sphere(Scene& scene, double radius, std::uint32_t segments, std::uint32_t rings,
                       double backscatter_db = -20.0,
                       AcousticMaterial::Model model = AcousticMaterial::Model::constant) {
    std::vector<float> p;
    std::vector<std::uint32_t> idx;
    for (std::uint32_t i = 0; i <= rings; ++i) {
        const double theta = kPi * i / rings; // from +z
        for (std::uint32_t j = 0; j < segments; ++j) {
            const double phi = 2 * kPi * j / segments;
            p.push_back(static_cast<float>(radius * std::sin(theta) * std::cos(phi)));
            p.push_back(static_cast<float>(radius * std::sin(theta) * std::sin(phi)));
            p.push_back(static_cast<float>(radius * std::cos(theta)));
        }
    }
    for (std::uint32_t i = 0; i < rings; ++i) {
        for (std::uint32_t j = 0; j < segments; ++j) {
            const std::uint32_t a = i * segments + j, b = i * segments + (j + 1) % segments;
            const std::uint32_t c = a + segments, d = b + segments;
            if (i > 0) idx.insert(idx.end(), {a, c, b});
            if (i + 1 < rings) idx.insert(idx.end(), {b, c, d});
        }
    }
    add_mesh_draw(scene, p, idx, translation(0, 0, 0), backscatter_db, model);
}

// Total echo of a square plate (half-width `half`) centred `distance` ahead on the x axis and turned by
// theta about its vertical axis, from the model integrated over the plate (midpoint rule, 400^2):
// E = mu integral cos^2(theta(X)) / r(X)^4 10^(-2 alpha r / 10) dA (one cos from Lambert, one from the
// projected solid angle dOmega = cos dA / r^2). Vertical pattern off.
inline double plate_reference(double theta_rad, double half, double distance, double mu, double alpha_db_per_m = 0) {
    const int n = 400;
    const double d = 2 * half / n;
    const double nx = -std::cos(theta_rad), ny = -std::sin(theta_rad);
    double e = 0;
    for (int i = 0; i < n; ++i) {
        const double s = -half + (i + 0.5) * d; // along the plate's horizontal axis
        const double x = distance - s * std::sin(theta_rad), y = s * std::cos(theta_rad);
        for (int k = 0; k < n; ++k) {
            const double z = -half + (k + 0.5) * d;
            const double r2 = x * x + y * y + z * z;
            const double cos_t = std::abs(nx * x + ny * y) / std::sqrt(r2);
            e += cos_t * cos_t / (r2 * r2) * std::pow(10.0, -0.2 * alpha_db_per_m * std::sqrt(r2)) * d * d;
        }
    }
    return mu * e;
}

inline double total(const std::vector<float>& v) {
    double s = 0;
    for (float x : v)
        s += x;
    return s;
}

// Sum of echo energy (echo2[2p]) over all pixels.
inline double echo_total(const Frame& f) {
    double s = 0;
    for (std::size_t p = 0; p < f.echo.size() / 2; ++p)
        s += f.echo[2 * p];
    return s;
}

inline double beam_energy(const Frame& f, std::uint32_t j) {
    double e = 0;
    for (std::uint32_t k = 0; k < f.bins; ++k)
        e += f.clean[std::size_t(k) * f.beams + j];
    return e;
}

// Energy-weighted mean azimuth (rad) and range (m) of the clean scan.
struct Centroid {
    double energy = 0, azimuth_rad = 0, range_m = 0;
};
inline Centroid centroid(const Frame& f, const Plan& plan) {
    Centroid c;
    for (std::uint32_t k = 0; k < f.bins; ++k) {
        for (std::uint32_t j = 0; j < f.beams; ++j) {
            const double e = f.clean[std::size_t(k) * f.beams + j];
            c.energy += e;
            c.azimuth_rad += e * plan.beam_angle_rad[j];
            c.range_m += e * plan.bin_range_m[k];
        }
    }
    if (c.energy > 0) {
        c.azimuth_rad /= c.energy;
        c.range_m /= c.energy;
    }
    return c;
}

} // namespace vksonar::testing::hard
