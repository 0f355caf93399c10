// Helpers shared by the CPU reference stage tests (tests/stages/cpu_*_test.cpp): hand-built scenes
// (SceneData), a small sonar, and the pixel geometry of docs/pipeline.md computed in double.
#pragma once
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "core/plan.h"
#include "core/sonar_math.hpp"
#include "scene/scene_data.h"
#include "stages/cpu_stages.h"
#include "vksonar/scene.h"

namespace vksonar::stage_testing {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;
using Mat4 = std::array<double, 16>;
constexpr Mat4 kIdentity{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};

// The typed suites run each stage in both of the CPU reference's precisions.
using Precisions = ::testing::Types<float, double>;

// ---------------------------------------------------------------------------------------------
// Scene building

struct SceneBuilder {
    SceneData scene;

    std::uint32_t mesh(const std::vector<float>& positions, const std::vector<std::uint32_t>& indices) {
        MeshRange m;
        m.first_index = static_cast<std::uint32_t>(scene.indices.size());
        m.index_count = static_cast<std::uint32_t>(indices.size());
        m.first_vertex = static_cast<std::uint32_t>(scene.positions.size() / 3);
        m.vertex_count = static_cast<std::uint32_t>(positions.size() / 3);
        scene.positions.insert(scene.positions.end(), positions.begin(), positions.end());
        scene.indices.insert(scene.indices.end(), indices.begin(), indices.end());
        scene.meshes.push_back(m);
        return static_cast<std::uint32_t>(scene.meshes.size() - 1);
    }
    std::uint32_t material(double backscatter_db, AcousticMaterial::Model model = AcousticMaterial::Model::lambert) {
        AcousticMaterial m;
        m.name = "m" + std::to_string(scene.materials.size());
        m.backscatter_db = backscatter_db;
        m.model = model;
        scene.materials.push_back(m);
        return static_cast<std::uint32_t>(scene.materials.size() - 1);
    }
    void draw(std::uint32_t mesh_index, std::uint32_t material_index, const Mat4& world_from_local = kIdentity) {
        SceneDraw d;
        d.mesh = mesh_index;
        d.material = material_index;
        d.world_from_local = world_from_local;
        scene.draws.push_back(d);
    }
    // Rectangle in the plane x = x0: y in [y0, y1], z in [z0, z1] (two triangles).
    std::uint32_t quad_x(double x0, double y0, double y1, double z0, double z1) {
        const float x = float(x0), a = float(y0), b = float(y1), c = float(z0), d = float(z1);
        return mesh({x, a, c, x, b, c, x, b, d, x, a, d}, {0, 1, 2, 0, 2, 3});
    }
    // Axis-aligned box.
    std::uint32_t box(const double lo[3], const double hi[3]) {
        std::vector<float> p;
        for (int i = 0; i < 8; ++i) {
            p.push_back(float(i & 1 ? hi[0] : lo[0]));
            p.push_back(float(i & 2 ? hi[1] : lo[1]));
            p.push_back(float(i & 4 ? hi[2] : lo[2]));
        }
        // two triangles per face, mixed windings on purpose (no culling in the depth pass)
        return mesh(p, {0, 2, 6, 0, 6, 4, 1, 5, 7, 1, 7, 3, 0, 4, 5, 0, 5, 1,
                        2, 3, 7, 2, 7, 6, 0, 1, 3, 0, 3, 2, 4, 6, 7, 4, 7, 5});
    }
};

// Rotation about z (yaw) then translation, column-major.
inline Mat4 yaw_translate(double yaw_deg, double tx, double ty, double tz) {
    const double c = std::cos(yaw_deg * kDeg), s = std::sin(yaw_deg * kDeg);
    return {c, s, 0, 0, -s, c, 0, 0, 0, 0, 1, 0, tx, ty, tz, 1};
}

// A small sonar: 1 slice of 64 columns x 32 rows, 32 beams, 128 bins over 0.5..40 m.
inline SonarConfig small_config() {
    SonarConfig c;
    c.hfov_deg = 40.0;
    // The stage contracts these tests check are written on the planar beam geometry, where the
    // profile columns are the pixel columns; line_array's own: tests/beam_geometry_test.cpp.
    c.beam_geometry = BeamGeometry::planar;
    c.vfov_deg = 10.0;
    c.horizontal_beamwidth_deg = 2.0;
    c.beams = 32;
    c.bins = 128;
    c.range_min_m = 0.5;
    c.range_max_m = 40.0;
    c.rows_per_vfov = 16;
    c.pixels_per_beam = 2.0;
    c.absorption_db_per_m = 0.05;
    c.vertical_pattern = BeamPattern::sinc;
    c.horizontal_pattern = BeamPattern::sinc;
    c.range_kernel = RangeKernel::tent;
    c.effects.incidence = EffectMode::on;
    c.effects.vertical_pattern = EffectMode::on;
    c.effects.horizontal_pattern = EffectMode::on;
    c.effects.spreading = EffectMode::on;
    c.effects.absorption = EffectMode::on;
    return c;
}

inline Plan plan_for(const SonarConfig& config, const SceneData& scene) {
    auto p = make_plan(config, scene);
    EXPECT_TRUE(p.ok()) << (p.ok() ? "" : p.error().message);
    if (!p.ok()) return Plan{};
    return std::move(p.value());
}

// ---------------------------------------------------------------------------------------------
// Geometry helpers (double, from the contract)

struct PixelRay {
    double u, v;
    double D[3]; // f_s + u r_s + v d: P = z D at view depth z
};

inline PixelRay pixel_ray(const Plan& plan, std::uint32_t c, std::uint32_t j) {
    const std::uint32_t s = c / plan.slice_columns;
    PixelRay r{};
    r.u = math_f64::pixel_coord(c % plan.slice_columns, plan.slice_columns, plan.tan_half_h);
    r.v = math_f64::pixel_coord(j, plan.rows, plan.tan_half_v);
    const double phi = plan.slice_info[s].center_azimuth_rad;
    r.D[0] = std::cos(phi) + r.u * std::sin(phi);
    r.D[1] = std::sin(phi) - r.u * std::cos(phi);
    r.D[2] = -r.v;
    return r;
}

inline double view_z(const Plan& plan, float d) {
    return math_f64::view_z_from_depth(d, plan.depth_a, plan.depth_b);
}

struct DepthBuffers {
    std::vector<float> depth;
    std::vector<std::uint32_t> material;
};

inline DepthBuffers run_depth(const Plan& plan, const SceneData& scene, const Pose& pose = {}) {
    std::vector<shared::DepthPush> draws;
    compose_depth_draws(plan, scene, pose, draws);
    DepthBuffers b;
    b.depth.assign(std::size_t(plan.rows) * plan.columns, -1.0f); // the pass must clear
    b.material.assign(b.depth.size(), 12345u);
    cpu::depth_pass(plan, scene, draws, b.depth.data(), b.material.data());
    return b;
}

// A DepthPush whose clip_from_local is the identity: local (x, y, z) = (x_ndc, y_ndc, z_ndc), w = 1.
inline shared::DepthPush identity_push(std::uint32_t material_id) {
    shared::DepthPush p{};
    for (int k = 0; k < 16; ++k)
        p.clip_from_local[k] = float(kIdentity[k]);
    p.material_id = material_id;
    return p;
}
} // namespace vksonar::stage_testing
