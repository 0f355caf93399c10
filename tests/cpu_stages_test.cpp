// Tests of the CPU reference stages (src/stages/cpu_*.cpp) against docs/pipeline.md, on scenes
// built by hand as SceneData. Every tolerance is justified next to it.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "core/plan.h"
#include "core/sonar_math.hpp"
#include "scene/scene_data.h"
#include "stages/cpu_stages.h"
#include "vksonar/scene.h"

namespace vksonar {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;
using Mat4 = std::array<double, 16>;
constexpr Mat4 kIdentity{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};

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
Mat4 yaw_translate(double yaw_deg, double tx, double ty, double tz) {
    const double c = std::cos(yaw_deg * kDeg), s = std::sin(yaw_deg * kDeg);
    return {c, s, 0, 0, -s, c, 0, 0, 0, 0, 1, 0, tx, ty, tz, 1};
}

// A small sonar: 1 slice of 64 columns x 32 rows, 32 beams, 128 bins over 0.5..40 m.
SonarConfig small_config() {
    SonarConfig c;
    c.hfov_deg = 40.0;
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

Plan plan_for(const SonarConfig& config, const SceneData& scene) {
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

PixelRay pixel_ray(const Plan& plan, std::uint32_t c, std::uint32_t j) {
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

double view_z(const Plan& plan, float d) {
    return math_f64::view_z_from_depth(d, plan.depth_a, plan.depth_b);
}

struct DepthBuffers {
    std::vector<float> depth;
    std::vector<std::uint32_t> material;
};

DepthBuffers run_depth(const Plan& plan, const SceneData& scene, const Pose& pose = {}) {
    std::vector<shared::DepthPush> draws;
    compose_depth_draws(plan, scene, pose, draws);
    DepthBuffers b;
    b.depth.assign(std::size_t(plan.rows) * plan.columns, -1.0f); // the pass must clear
    b.material.assign(b.depth.size(), 12345u);
    cpu::depth_pass(plan, scene, draws, b.depth.data(), b.material.data());
    return b;
}

// A DepthPush whose clip_from_local is the identity: local (x, y, z) = (x_ndc, y_ndc, z_ndc), w = 1.
shared::DepthPush identity_push(std::uint32_t material_id) {
    shared::DepthPush p{};
    for (int k = 0; k < 16; ++k)
        p.clip_from_local[k] = float(kIdentity[k]);
    p.material_id = material_id;
    return p;
}

// ---------------------------------------------------------------------------------------------
// 1. Depth pass

// The shaders find a column's slice by a float multiply (sonar_math.h, slice_of_column): it must equal
// the integer quotient for every column of up to kMaxSlices slices, at every slice width up to 2048
// and at the widths near powers of two up to the 2^17 the comment claims.
TEST(SonarMath, SliceOfColumnEqualsTheIntegerQuotient) {
    std::vector<std::uint32_t> widths;
    for (std::uint32_t w = 1; w <= 2048; ++w)
        widths.push_back(w);
    for (std::uint32_t p = 12; p <= 17; ++p) {
        widths.push_back((1u << p) - 1);
        widths.push_back(1u << p);
        widths.push_back((1u << p) + 1);
    }
    widths.pop_back(); // 2^17 + 1 is past the claim
    widths.pop_back(); // so is 2^17
    for (std::uint32_t w : widths) {
        const float inv = 1.0f / static_cast<float>(w);
        for (std::uint32_t c = 0; c < w * shared::kMaxSlices; ++c)
            ASSERT_EQ(math_f32::slice_of_column(c, inv), c / w) << "column " << c << ", slice width " << w;
    }
}

TEST(CpuDepth, PlaneFacingSonarCoversExpectedPixelsAtViewZ10) {
    SceneBuilder b;
    const std::uint32_t m = b.material(-20.0);
    b.draw(b.quad_x(10.0, -2.0, 2.0, -0.5, 0.5), m);
    const Plan plan = plan_for(small_config(), b.scene);
    ASSERT_EQ(plan.slices, 1u);
    const DepthBuffers out = run_depth(plan, b.scene);
    int covered = 0, checked = 0;
    for (std::uint32_t j = 0; j < plan.rows; ++j) {
        for (std::uint32_t c = 0; c < plan.columns; ++c) {
            const std::size_t p = std::size_t(j) * plan.columns + c;
            const PixelRay ray = pixel_ray(plan, c, j);
            // The pixel-centre ray meets x = 10 at (y, z) = 10 (D_y, D_z).
            const double y = 10.0 * ray.D[1], z = 10.0 * ray.D[2];
            const double margin = std::min(2.0 - std::abs(y), 0.5 - std::abs(z));
            // 1 mm from the rectangle's edge: float vertices and matrices move edges by ~1e-6 m.
            if (std::abs(margin) < 1e-3) continue;
            ++checked;
            const bool inside = margin > 0;
            EXPECT_EQ(out.depth[p] > 0.0f, inside) << "pixel " << c << "," << j;
            if (inside) {
                ++covered;
                EXPECT_EQ(out.material[p], m);
                // float depth: d ~ 0.033 has ulp ~4e-9, i.e. ~1e-7 relative in view z, plus float matrix
                // entries (~6e-8 each); 1e-5 leaves two orders of margin.
                EXPECT_NEAR(view_z(plan, out.depth[p]) / 10.0, 1.0, 1e-5);
            } else {
                EXPECT_EQ(out.depth[p], 0.0f);
                EXPECT_EQ(out.material[p], shared::kNoMaterial);
            }
        }
    }
    EXPECT_GT(covered, 50);
    EXPECT_GT(checked, int(plan.rows * plan.columns) - 20);
}

TEST(CpuDepth, SonarInsideClosedBoxCoversEverySliceWithClippedTriangles) {
    SceneBuilder b;
    const double lo[3] = {-10, -10, -10}, hi[3] = {10, 10, 10};
    b.draw(b.box(lo, hi), b.material(-20.0));
    SonarConfig config = small_config();
    config.hfov_deg = 130.0;
    config.beams = 64;
    config.pixels_per_beam = 1.0;
    const Plan plan = plan_for(config, b.scene);
    ASSERT_EQ(plan.slices, 3u);
    const DepthBuffers out = run_depth(plan, b.scene);
    for (std::uint32_t j = 0; j < plan.rows; ++j) {
        for (std::uint32_t c = 0; c < plan.columns; ++c) {
            const std::size_t p = std::size_t(j) * plan.columns + c;
            const PixelRay ray = pixel_ray(plan, c, j);
            const double expected = 10.0 / std::max({std::abs(ray.D[0]), std::abs(ray.D[1]), std::abs(ray.D[2])});
            ASSERT_GT(out.depth[p], 0.0f) << "hole at pixel " << c << "," << j;
            ASSERT_EQ(out.material[p], 0u);
            // see PlaneFacingSonar...: float depth gives ~1e-7 relative in view z.
            EXPECT_NEAR(view_z(plan, out.depth[p]) / expected, 1.0, 1e-5) << "pixel " << c << "," << j;
        }
    }
}

TEST(CpuDepth, NearerSurfaceWinsInEitherDrawOrder) {
    for (int order = 0; order < 2; ++order) {
        SceneBuilder b;
        const std::uint32_t near_m = b.material(-20.0), far_m = b.material(-30.0);
        const std::uint32_t near_q = b.quad_x(6.0, -1.0, 1.0, -0.4, 0.4);
        const std::uint32_t far_q = b.quad_x(8.0, -3.0, 3.0, -1.0, 1.0);
        if (order == 0) {
            b.draw(near_q, near_m);
            b.draw(far_q, far_m);
        } else {
            b.draw(far_q, far_m);
            b.draw(near_q, near_m);
        }
        const Plan plan = plan_for(small_config(), b.scene);
        const DepthBuffers out = run_depth(plan, b.scene);
        int near_pixels = 0, far_pixels = 0;
        for (std::uint32_t j = 0; j < plan.rows; ++j) {
            for (std::uint32_t c = 0; c < plan.columns; ++c) {
                const std::size_t p = std::size_t(j) * plan.columns + c;
                const PixelRay ray = pixel_ray(plan, c, j);
                const bool in_near = std::abs(6.0 * ray.D[1]) < 0.99 && std::abs(6.0 * ray.D[2]) < 0.39;
                const bool in_far = std::abs(8.0 * ray.D[1]) < 2.99 && std::abs(8.0 * ray.D[2]) < 0.99;
                if (in_near) {
                    ++near_pixels;
                    EXPECT_EQ(out.material[p], near_m) << "order " << order;
                    EXPECT_NEAR(view_z(plan, out.depth[p]), 6.0, 6e-5); // 1e-5 relative, as above
                } else if (in_far) {
                    ++far_pixels;
                    EXPECT_EQ(out.material[p], far_m) << "order " << order;
                    EXPECT_NEAR(view_z(plan, out.depth[p]), 8.0, 8e-5);
                }
            }
        }
        EXPECT_GT(near_pixels, 20);
        EXPECT_GT(far_pixels, 20);
    }
}

TEST(CpuDepth, EqualDepthKeepsTheFirstDrawBecauseTheTestIsStrict) {
    SceneBuilder b;
    const std::uint32_t first = b.material(-20.0), second = b.material(-30.0);
    const std::uint32_t q = b.quad_x(10.0, -2.0, 2.0, -1.0, 1.0);
    b.draw(q, first);
    b.draw(q, second); // identical geometry: identical depths, GREATER fails
    const Plan plan = plan_for(small_config(), b.scene);
    const DepthBuffers out = run_depth(plan, b.scene);
    int hits = 0;
    for (std::size_t p = 0; p < out.depth.size(); ++p) {
        if (out.depth[p] > 0.0f) {
            ++hits;
            EXPECT_EQ(out.material[p], first);
        }
    }
    EXPECT_GT(hits, 100);
}

// Renders each draw alone (identity matrices in `pushes`) and returns per-pixel coverage counts.
std::vector<int> coverage_counts(const Plan& plan, const SceneData& scene, const std::vector<shared::DepthPush>& pushes,
                                 std::vector<std::vector<bool>>* masks = nullptr) {
    std::vector<int> count(std::size_t(plan.rows) * plan.columns, 0);
    for (std::size_t i = 0; i < scene.draws.size(); ++i) {
        SceneData one = scene;
        one.draws = {scene.draws[i]};
        std::vector<shared::DepthPush> p;
        for (std::uint32_t s = 0; s < plan.slices; ++s)
            p.push_back(pushes[s * scene.draws.size() + i]);
        std::vector<float> depth(count.size());
        std::vector<std::uint32_t> material(count.size());
        cpu::depth_pass(plan, one, p, depth.data(), material.data());
        std::vector<bool> mask(count.size());
        for (std::size_t k = 0; k < count.size(); ++k) {
            mask[k] = depth[k] > 0.0f;
            count[k] += mask[k];
        }
        if (masks) masks->push_back(mask);
    }
    return count;
}

TEST(CpuDepth, TopLeftRuleCoversSharedEdgesThroughPixelCentresExactlyOnce) {
    // Identity clip matrix: screen x = (x_ndc + 1) W / 2, y = (y_ndc + 1) H / 2 with W = 64, H = 32, so
    // vertices at dyadic screen positions are exact and the edges below run through pixel centres.
    SceneBuilder b;
    b.material(-20.0);
    const Plan plan = plan_for(small_config(), b.scene);
    ASSERT_EQ(plan.columns, 64u);
    ASSERT_EQ(plan.rows, 32u);
    auto ndc = [&](double sx, double sy) {
        return std::array<float, 3>{float(sx * 2.0 / plan.columns - 1.0), float(sy * 2.0 / plan.rows - 1.0), 0.5f};
    };
    // Square with corners at pixel centres (2.5, 1.5) .. (10.5, 9.5): by the top-left rule it covers
    // columns 2..9 and rows 1..8 (left and top edges in, right and bottom edges out).
    const std::array<float, 3> A = ndc(2.5, 1.5), B = ndc(10.5, 1.5), C = ndc(10.5, 9.5), D = ndc(2.5, 9.5);
    // Also a horizontal and a vertical shared edge through pixel centres: a square split into 4 by
    // its centre E = (6.5, 5.5).
    const std::array<float, 3> E = ndc(6.5, 5.5);
    auto tri = [](std::vector<float>& p, const std::array<float, 3>& a, const std::array<float, 3>& c,
                  const std::array<float, 3>& d) {
        p.insert(p.end(), a.begin(), a.end());
        p.insert(p.end(), c.begin(), c.end());
        p.insert(p.end(), d.begin(), d.end());
    };
    const std::vector<std::vector<std::array<std::array<float, 3>, 3>>> splits = {
        {{A, B, C}, {A, C, D}},                       // diagonal A-C, both counter-clockwise on screen
        {{A, C, B}, {A, C, D}},                       // mixed windings
        {{A, B, D}, {B, C, D}},                       // diagonal B-D
        {{A, B, E}, {B, C, E}, {C, D, E}, {D, A, E}}, // fan around a pixel centre
        {{E, B, A}, {C, B, E}, {E, D, C}, {A, D, E}}, // same fan, reversed windings
    };
    for (std::size_t k = 0; k < splits.size(); ++k) {
        SceneBuilder sb;
        sb.material(-20.0);
        std::vector<shared::DepthPush> pushes;
        for (const auto& t : splits[k]) {
            std::vector<float> p;
            tri(p, t[0], t[1], t[2]);
            sb.draw(sb.mesh(p, {0, 1, 2}), 0);
            pushes.push_back(identity_push(0));
        }
        const std::vector<int> count = coverage_counts(plan, sb.scene, pushes);
        for (std::uint32_t j = 0; j < plan.rows; ++j) {
            for (std::uint32_t c = 0; c < plan.columns; ++c) {
                const bool inside = c >= 2 && c <= 9 && j >= 1 && j <= 8;
                EXPECT_EQ(count[std::size_t(j) * plan.columns + c], inside ? 1 : 0)
                    << "split " << k << " pixel " << c << "," << j;
            }
        }
    }
}

TEST(CpuDepth, ScissorConfinesEachSliceToItsOwnColumns) {
    SonarConfig config = small_config();
    config.hfov_deg = 100.0; // 2 slices
    SceneBuilder b;
    b.material(-20.0);
    // One triangle far larger than the viewport (NDC +-4), drawn only in slice 1.
    b.draw(b.mesh({-4.f, -4.f, 0.5f, 4.f, -4.f, 0.5f, 0.f, 4.f, 0.5f}, {0, 1, 2}), 0);
    const Plan plan = plan_for(config, b.scene);
    ASSERT_EQ(plan.slices, 2u);
    shared::DepthPush none = identity_push(7);
    for (float& v : none.clip_from_local)
        v = 0.0f; // all vertices at w = 0: nothing can be drawn
    const std::vector<shared::DepthPush> pushes = {none, identity_push(7)};
    std::vector<float> depth(std::size_t(plan.rows) * plan.columns);
    std::vector<std::uint32_t> material(depth.size());
    cpu::depth_pass(plan, b.scene, pushes, depth.data(), material.data());
    for (std::uint32_t j = 0; j < plan.rows; ++j) {
        for (std::uint32_t c = 0; c < plan.columns; ++c) {
            const std::size_t p = std::size_t(j) * plan.columns + c;
            const bool slice1 = c >= plan.slice_columns;
            // The triangle (screen y from 0 at the top) covers the centre rows of slice 1 fully.
            if (!slice1) {
                EXPECT_EQ(depth[p], 0.0f) << c << "," << j;
                EXPECT_EQ(material[p], shared::kNoMaterial);
            } else if (j >= plan.rows / 4 && j < 3 * plan.rows / 4) {
                EXPECT_EQ(depth[p], 0.5f) << c << "," << j;
                EXPECT_EQ(material[p], 7u);
            }
        }
    }
}

// Culling (build_depth_clusters, cull_depth_clusters): composes the pose's draws, culls, and checks
// that the frame drawn with the culling is the frame drawn without it, bit for bit (a cluster is only
// skipped where none of its triangles could cover a pixel). Returns the drawn flags; hits, if given,
// receives the number of pixels hit (else at least one must be).
std::vector<std::uint8_t> culled_and_checked(const Plan& plan, const SceneData& scene, const Pose& pose,
                                             std::vector<DepthCluster>& clusters, std::size_t* hits = nullptr) {
    std::vector<shared::DepthPush> pushes;
    std::vector<std::uint8_t> drawn;
    compose_depth_draws(plan, scene, pose, pushes);
    build_depth_clusters(scene, clusters);
    cull_depth_clusters(clusters, scene.draws.size(), pushes, drawn);
    EXPECT_EQ(drawn.size(), std::size_t(plan.slices) * clusters.size());
    const std::size_t pixels = std::size_t(plan.rows) * plan.columns;
    std::vector<float> depth_all(pixels), depth_culled(pixels);
    std::vector<std::uint32_t> material_all(pixels), material_culled(pixels);
    cpu::depth_pass(plan, scene, pushes, depth_all.data(), material_all.data());
    const cpu::DepthClusters culled{clusters, drawn};
    cpu::depth_pass(plan, scene, pushes, depth_culled.data(), material_culled.data(), nullptr, &culled);
    EXPECT_EQ(depth_all, depth_culled) << "pose x " << pose.x_m << " yaw " << pose.yaw_deg;
    EXPECT_EQ(material_all, material_culled);
    const auto hit = std::size_t(std::count_if(depth_all.begin(), depth_all.end(), [](float d) { return d > 0.0f; }));
    if (hits) {
        *hits = hit;
    } else {
        EXPECT_GT(hit, 0u); // something was drawn
    }
    return drawn;
}

TEST(DepthClusters, RunsKeepDrawAndTriangleOrderAndBoundTheirVertices) {
    SceneBuilder b;
    b.material(-20.0);
    std::vector<float> positions;
    std::vector<std::uint32_t> indices;
    const std::uint32_t triangles = 2 * kClusterTriangles + 7; // three runs: full, full, 7
    for (std::uint32_t t = 0; t < triangles; ++t) {
        for (int k = 0; k < 3; ++k) {
            positions.insert(positions.end(), {float(t), float(k), float(t % 5)});
            indices.push_back(3 * t + std::uint32_t(k));
        }
    }
    const std::uint32_t strip = b.mesh(positions, indices);
    const double lo[3] = {-1, -2, -3}, hi[3] = {1, 2, 3};
    b.draw(b.box(lo, hi), 0);
    b.draw(strip, 0);
    std::vector<DepthCluster> clusters;
    build_depth_clusters(b.scene, clusters);
    ASSERT_EQ(clusters.size(), 4u);
    EXPECT_EQ(clusters[0].draw, 0u);
    EXPECT_EQ(clusters[0].index_count, 36u);
    EXPECT_EQ(clusters[0].bounds_min[2], -3.0f);
    EXPECT_EQ(clusters[0].bounds_max[1], 2.0f);
    const MeshRange& mesh = b.scene.meshes[strip];
    for (std::uint32_t r = 0; r < 3; ++r) {
        const DepthCluster& run = clusters[1 + r];
        EXPECT_EQ(run.draw, 1u);
        EXPECT_EQ(run.first_vertex, mesh.first_vertex);
        EXPECT_EQ(run.first_index, mesh.first_index + r * 3 * kClusterTriangles); // consecutive, in order
        EXPECT_EQ(run.index_count, r < 2 ? 3 * kClusterTriangles : 21u);
        // triangle t has x = t, y in {0, 1, 2}, z = t % 5
        EXPECT_EQ(run.bounds_min[0], float(r * kClusterTriangles));
        EXPECT_EQ(run.bounds_max[0], float(std::min(triangles, (r + 1) * kClusterTriangles) - 1));
        EXPECT_EQ(run.bounds_min[1], 0.0f);
        EXPECT_EQ(run.bounds_max[1], 2.0f);
        EXPECT_EQ(run.bounds_max[2], 4.0f);
    }
}

TEST(DepthClusters, CullingSkipsWhatCannotBeSeenAndChangesNoPixel) {
    SonarConfig config = small_config();
    config.hfov_deg = 130.0;                 // 3 slices of 43.3 deg
    for (const double origin : {0.0, 1e5}) { // far from the world origin: the tolerance must scale
        SceneBuilder b;
        b.material(-20.0);
        auto box_at = [&](double x, double y, double z, double half) {
            const double lo[3] = {x - half, y - half, z - half}, hi[3] = {x + half, y + half, z + half};
            b.draw(b.box(lo, hi), 0, yaw_translate(0.0, origin, origin, 0.0));
        };
        box_at(15, 0, 0, 0.5);  // 0: straight ahead, +-1.9 deg: the middle slice only
        box_at(-15, 0, 0, 0.5); // 1: behind the sonar
        box_at(60, 0, 0, 0.5);  // 2: beyond range_max (40 m)
        box_at(15, 0, 10, 0.5); // 3: 34 deg above the beam (vfov 10 deg)
        box_at(0, 0, 0, 1.0);   // 4: the sonar inside it: every slice
        const double slab_lo[3] = {2, -30, -1.05}, slab_hi[3] = {30, 30, -1};
        b.draw(b.box(slab_lo, slab_hi), 0, yaw_translate(0.0, origin, origin, 0.0)); // 5: seabed: every slice
        const Plan plan = plan_for(config, b.scene);
        ASSERT_EQ(plan.slices, 3u);
        for (const double yaw : {0.0, 40.0}) {
            Pose pose;
            pose.x_m = origin;
            pose.y_m = origin;
            pose.yaw_deg = yaw;
            std::vector<DepthCluster> clusters;
            const std::vector<std::uint8_t> drawn = culled_and_checked(plan, b.scene, pose, clusters);
            ASSERT_EQ(clusters.size(), 6u); // 12 triangles a box: one cluster each, in draw order
            auto is_drawn = [&](std::uint32_t s, std::size_t c) { return drawn[s * clusters.size() + c] != 0; };
            for (std::uint32_t s = 0; s < plan.slices; ++s) {
                for (std::size_t c : {1, 2, 3})
                    EXPECT_FALSE(is_drawn(s, c)) << "box " << c << " slice " << s;
                for (std::size_t c : {4, 5})
                    EXPECT_TRUE(is_drawn(s, c)) << "box " << c << " slice " << s;
                const double centre_deg = plan.slice_info[s].center_azimuth_rad / kDeg;
                // box 0 is at azimuth -yaw from the sonar: drawn only in the slice that contains it
                EXPECT_EQ(is_drawn(s, 0), std::abs(centre_deg + yaw) < 130.0 / 6.0) << "slice " << s;
            }
        }
    }
}

TEST(DepthClusters, ALargeSeabedIsDrawnOnlyWhereEachSliceSeesIt) {
    SonarConfig config = small_config();
    config.hfov_deg = 130.0;
    SceneBuilder b;
    b.material(-20.0);
    // A 60 x 60 m seabed 1 m below the sonar, centred on it: 64 x 64 quads, 8192 triangles in rows.
    std::vector<float> positions;
    std::vector<std::uint32_t> indices;
    const std::uint32_t n = 64;
    for (std::uint32_t j = 0; j <= n; ++j)
        for (std::uint32_t i = 0; i <= n; ++i)
            positions.insert(positions.end(), {-30.0f + 60.0f * float(i) / n, -30.0f + 60.0f * float(j) / n, -1.0f});
    for (std::uint32_t j = 0; j < n; ++j) {
        for (std::uint32_t i = 0; i < n; ++i) {
            const std::uint32_t a = j * (n + 1) + i;
            indices.insert(indices.end(), {a, a + 1, a + n + 2, a, a + n + 2, a + n + 1});
        }
    }
    b.draw(b.mesh(positions, indices), 0);
    const Plan plan = plan_for(config, b.scene);
    for (const double yaw : {0.0, 25.0, 90.0, 180.0}) {
        Pose pose;
        pose.yaw_deg = yaw;
        std::vector<DepthCluster> clusters;
        const std::vector<std::uint8_t> drawn = culled_and_checked(plan, b.scene, pose, clusters);
        ASSERT_EQ(clusters.size(), 8192u / kClusterTriangles);
        for (std::uint32_t s = 0; s < plan.slices; ++s) {
            // Each run is a band of 4 grid rows (4 m in y) across the whole seabed. A slice 43 deg
            // wide, looking out to 40 m with the seabed visible beyond 1 m / tan(vfov/2 + margin),
            // cannot see every band: at least one is skipped, and at least one is drawn.
            const auto first = drawn.begin() + std::ptrdiff_t(s * clusters.size());
            const auto drawn_here = std::count(first, first + std::ptrdiff_t(clusters.size()), std::uint8_t(1));
            EXPECT_GT(drawn_here, 0) << "yaw " << yaw << " slice " << s;
            EXPECT_LT(drawn_here, std::ptrdiff_t(clusters.size())) << "yaw " << yaw << " slice " << s;
        }
    }
}

// The bundled scenes seen from random poses (seeded), 130 and 360 degrees: culled frames equal the
// frames drawn without culling, bit for bit, while the culling does skip clusters.
TEST(DepthClusters, BundledScenesFromRandomPosesAreTheSameCulled) {
    std::mt19937 rng(20261123u);
    std::uniform_real_distribution<double> x(-5.0, 40.0), y(-20.0, 20.0), z(-7.0, 3.0), tilt(-40.0, 40.0),
        yaw(-180.0, 180.0);
    std::size_t poses_with_hits = 0, skipped = 0, pairs = 0;
    for (const char* name : {"default", "harbour", "tilted_seafloor"}) {
        auto scene = Scene::load_gltf(std::string(VKSONAR_ASSET_DIR "/scenes/") + name + ".gltf");
        ASSERT_TRUE(scene.ok()) << name;
        for (const double hfov : {130.0, 360.0}) {
            SonarConfig config;
            config.hfov_deg = hfov;
            const Plan plan = plan_for(config, scene.value().data());
            for (int i = 0; i < 8; ++i) {
                Pose pose;
                pose.x_m = x(rng);
                pose.y_m = y(rng);
                pose.z_m = z(rng);
                pose.roll_deg = tilt(rng);
                pose.pitch_deg = tilt(rng);
                pose.yaw_deg = yaw(rng);
                std::vector<DepthCluster> clusters;
                std::size_t hits = 0;
                const std::vector<std::uint8_t> drawn =
                    culled_and_checked(plan, scene.value().data(), pose, clusters, &hits);
                poses_with_hits += hits > 0;
                skipped += std::size_t(std::count(drawn.begin(), drawn.end(), std::uint8_t(0)));
                pairs += drawn.size();
            }
        }
    }
    EXPECT_GT(poses_with_hits, 24u); // most of the 48 poses see something
    EXPECT_GT(skipped, pairs / 4);   // and the culling had work to do
}

TEST(CpuDepth, MeshFanHasNoGapsOrOverlapsUnderPerspectiveAndFarClipping) {
    // A 24-triangle disc of radius 8 m centred 35 m ahead, turned 60 deg about z so that it crosses the
    // far plane (40 m): clipped fan triangles must still tile the disc exactly once.
    const int n = 24;
    const double R = 8.0;
    std::vector<float> pos = {0.f, 0.f, 0.f};
    for (int i = 0; i < n; ++i) {
        const double a = 2 * kPi * i / n + 0.1;
        pos.insert(pos.end(), {0.f, float(R * std::cos(a)), float(R * std::sin(a))});
    }
    SceneBuilder b;
    const std::uint32_t mat = b.material(-20.0);
    const Mat4 place = yaw_translate(60.0, 35.0, 0.0, 0.0);
    for (int i = 0; i < n; ++i) {
        std::vector<std::uint32_t> t = {0, std::uint32_t(1 + i), std::uint32_t(1 + (i + 1) % n)};
        if (i % 3 == 0) std::swap(t[1], t[2]); // mixed windings
        b.draw(b.mesh(pos, t), mat, place);
    }
    const Plan plan = plan_for(small_config(), b.scene);
    std::vector<shared::DepthPush> pushes;
    compose_depth_draws(plan, b.scene, Pose{}, pushes);
    const std::vector<int> count = coverage_counts(plan, b.scene, pushes);
    const double yaw = 60.0 * kDeg;
    const double normal[3] = {std::cos(yaw), std::sin(yaw), 0.0}; // disc plane: local x axis
    const double inner = R * std::cos(kPi / n);                   // inscribed radius of the polygon
    int inside = 0, clipped = 0;
    for (std::uint32_t j = 0; j < plan.rows; ++j) {
        for (std::uint32_t c = 0; c < plan.columns; ++c) {
            const int k = count[std::size_t(j) * plan.columns + c];
            ASSERT_LE(k, 1) << "double coverage at " << c << "," << j;
            const PixelRay ray = pixel_ray(plan, c, j);
            // P = z D on the plane n . (P - centre) = 0
            const double z = (normal[0] * 35.0) / (normal[0] * ray.D[0] + normal[1] * ray.D[1]);
            const double P[3] = {z * ray.D[0] - 35.0, z * ray.D[1], z * ray.D[2]};
            const double radius = std::sqrt(P[0] * P[0] + P[1] * P[1] + P[2] * P[2]);
            if (radius < inner - 0.01 && z < plan.far_m - 0.01 && z > 0) {
                ++inside;
                EXPECT_EQ(k, 1) << "gap at " << c << "," << j;
            }
            if (radius < inner - 0.01 && z > plan.far_m + 0.01) {
                ++clipped;
                EXPECT_EQ(k, 0) << "beyond the far plane at " << c << "," << j;
            }
        }
    }
    EXPECT_GT(inside, 200);
    EXPECT_GT(clipped, 20);
}

TEST(CpuDepth, DegenerateAndInvalidTrianglesProduceNothing) {
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    SceneBuilder b;
    b.material(-20.0);
    // 0-2: collinear; 3-5: repeated vertex; 6-8: NaN vertex; 9-11: Inf vertex; 12-14: behind the sonar
    // 15-17: a sliver with all three vertices within 1e-9 m of a line.
    const std::vector<float> pos = {10,  -1, 0,  10,  0,   0,     10,  1, 0,  //
                                    10,  -1, -1, 10,  1,   1,     10,  1, 1,  //
                                    10,  -1, -1, nan, 1,   1,     10,  1, -1, //
                                    10,  -1, -1, 10,  inf, 1,     10,  1, -1, //
                                    -10, -1, -1, -10, 1,   1,     -10, 1, -1, //
                                    10,  -1, 0,  10,  1,   1e-9f, 10,  0, 0.5e-9f};
    std::vector<std::uint32_t> idx;
    for (std::uint32_t i = 0; i < 18; ++i)
        idx.push_back(i);
    idx.insert(idx.end(), {0, 1, 99}); // index out of range of the vertex array
    b.draw(b.mesh(pos, idx), 0);
    const Plan plan = plan_for(small_config(), b.scene);
    const DepthBuffers out = run_depth(plan, b.scene);
    for (std::size_t p = 0; p < out.depth.size(); ++p) {
        ASSERT_EQ(out.depth[p], 0.0f) << "pixel " << p;
        ASSERT_EQ(out.material[p], shared::kNoMaterial);
    }
}

// ---------------------------------------------------------------------------------------------
// 2. Normals

template <class Real> class CpuNormals : public ::testing::Test {};
using Precisions = ::testing::Types<float, double>;
TYPED_TEST_SUITE(CpuNormals, Precisions);

std::vector<float> run_normals_plan(const Plan& plan, const std::vector<float>& depth, bool f64) {
    std::vector<float> n(depth.size() * 4, -7.0f);
    if (f64) {
        cpu::normals<double>(plan, depth.data(), n.data());
    } else {
        cpu::normals<float>(plan, depth.data(), n.data());
    }
    return n;
}

TYPED_TEST(CpuNormals, TiltedPlaneMatchesClosedFormIncidence) {
    const bool f64 = std::is_same_v<TypeParam, double>;
    // Plane through (12, 0, 0) with unit normal n = Rz(30) Ry(-20) (-1, 0, 0), facing the sonar.
    const double yaw = 30 * kDeg, pitch = 20 * kDeg;
    const double n[3] = {-std::cos(yaw) * std::cos(pitch), -std::sin(yaw) * std::cos(pitch), std::sin(pitch)};
    // Build the plane as a big quad spanned by two tangents.
    const double t1[3] = {-std::sin(yaw), std::cos(yaw), 0.0};
    const double t2[3] = {n[1] * t1[2] - n[2] * t1[1], n[2] * t1[0] - n[0] * t1[2], n[0] * t1[1] - n[1] * t1[0]};
    std::vector<float> pos;
    for (int k = 0; k < 4; ++k) {
        const double a = (k == 1 || k == 2) ? 30.0 : -30.0, c = k >= 2 ? 30.0 : -30.0;
        pos.insert(pos.end(),
                   {float(12.0 + a * t1[0] + c * t2[0]), float(a * t1[1] + c * t2[1]), float(a * t1[2] + c * t2[2])});
    }
    SceneBuilder b;
    b.draw(b.mesh(pos, {0, 1, 2, 0, 2, 3}), b.material(-20.0));
    const Plan plan = plan_for(small_config(), b.scene);
    const DepthBuffers d = run_depth(plan, b.scene);
    const std::vector<float> out = run_normals_plan(plan, d.depth, f64);
    int checked = 0;
    for (std::uint32_t j = 0; j < plan.rows; ++j) {
        for (std::uint32_t c = 0; c < plan.columns; ++c) {
            const std::size_t p = std::size_t(j) * plan.columns + c;
            ASSERT_GT(d.depth[p], 0.0f); // the plane fills the view
            const PixelRay ray = pixel_ray(plan, c, j);
            const double len = std::sqrt(ray.D[0] * ray.D[0] + ray.D[1] * ray.D[1] + ray.D[2] * ray.D[2]);
            const double expected = -(n[0] * ray.D[0] + n[1] * ray.D[1] + n[2] * ray.D[2]) / len;
            // Positions carry float depth error (~1e-7 relative, ~1e-6 m) over a neighbour spacing of
            // ~0.2 m: tangents are good to ~1e-5; 1e-3 is the contract's tolerance for planes.
            EXPECT_NEAR(out[4 * p + 3], expected, 1e-3) << "pixel " << c << "," << j;
            for (int k = 0; k < 3; ++k)
                EXPECT_NEAR(out[4 * p + k], n[k], 1e-3);
            ++checked;
        }
    }
    EXPECT_EQ(checked, int(plan.rows * plan.columns));
}

TYPED_TEST(CpuNormals, DepthDiscontinuityHasNoSpikesOrNaN) {
    const bool f64 = std::is_same_v<TypeParam, double>;
    // A box whose front face (x = 5) faces the sonar, in front of a wall at 20 m turned 25 deg.
    SceneBuilder b;
    const std::uint32_t wall_m = b.material(-30.0), box_m = b.material(-20.0);
    const double lo[3] = {5.0, -0.6, -0.4}, hi[3] = {6.0, 0.6, 0.4};
    b.draw(b.box(lo, hi), box_m);
    b.draw(b.quad_x(0.0, -40.0, 40.0, -40.0, 40.0), wall_m, yaw_translate(25.0, 20.0, 0.0, 0.0));
    const Plan plan = plan_for(small_config(), b.scene);
    const DepthBuffers d = run_depth(plan, b.scene);
    const std::vector<float> out = run_normals_plan(plan, d.depth, f64);
    const double wall_n[3] = {-std::cos(25 * kDeg), -std::sin(25 * kDeg), 0.0};
    int box_pixels = 0, wall_edge_pixels = 0;
    for (std::uint32_t j = 0; j < plan.rows; ++j) {
        for (std::uint32_t c = 0; c < plan.columns; ++c) {
            const std::size_t p = std::size_t(j) * plan.columns + c;
            ASSERT_GT(d.depth[p], 0.0f);
            const float* q = &out[4 * p];
            for (int k = 0; k < 4; ++k)
                ASSERT_TRUE(std::isfinite(q[k])) << c << "," << j;
            EXPECT_NEAR(q[0] * q[0] + q[1] * q[1] + q[2] * q[2], 1.0, 1e-5); // unit length, float rounding
            EXPECT_GE(q[3], 0.0f);
            EXPECT_LE(q[3], 1.0f);
            const PixelRay ray = pixel_ray(plan, c, j);
            const double len = std::sqrt(ray.D[0] * ray.D[0] + ray.D[1] * ray.D[1] + ray.D[2] * ray.D[2]);
            const bool is_box = d.material[p] == box_m;
            const double* n = wall_n;
            const double box_n[3] = {-1.0, 0.0, 0.0};
            if (is_box) n = box_n;
            const double expected = -(n[0] * ray.D[0] + n[1] * ray.D[1] + n[2] * ray.D[2]) / len;
            // Every pixel, including both sides of the silhouette, must see its own surface: the
            // one-sided difference picks the neighbour of closer range (tolerance: see the plane test).
            EXPECT_NEAR(q[3], expected, 1e-3) << (is_box ? "box" : "wall") << " pixel " << c << "," << j;
            if (is_box) ++box_pixels;
            if (!is_box && c > 0 && c + 1 < plan.columns && (d.material[p - 1] == box_m || d.material[p + 1] == box_m))
                ++wall_edge_pixels;
        }
    }
    EXPECT_GT(box_pixels, 20);
    EXPECT_GT(wall_edge_pixels, 4);
}

TYPED_TEST(CpuNormals, IsolatedPixelsAndLinesFaceTheSonar) {
    const bool f64 = std::is_same_v<TypeParam, double>;
    SceneBuilder b;
    b.material(-20.0);
    const Plan plan = plan_for(small_config(), b.scene);
    const float d = float(plan.depth_b + plan.depth_a / 10.0); // view z = 10 m
    std::vector<float> depth(std::size_t(plan.rows) * plan.columns, 0.0f);
    depth[std::size_t(5) * plan.columns + 7] = d; // isolated pixel
    for (std::uint32_t c = 20; c < 40; ++c)
        depth[std::size_t(12) * plan.columns + c] = d; // 1-row line
    const std::vector<float> out = run_normals_plan(plan, depth, f64);
    for (std::uint32_t j = 0; j < plan.rows; ++j) {
        for (std::uint32_t c = 0; c < plan.columns; ++c) {
            const std::size_t p = std::size_t(j) * plan.columns + c;
            const float* q = &out[4 * p];
            if (depth[p] == 0.0f) {
                for (int k = 0; k < 4; ++k)
                    EXPECT_EQ(q[k], 0.0f);
                continue;
            }
            // No vertical neighbour: the facing fallback n = -P / r with cos = 1 exactly.
            EXPECT_EQ(q[3], 1.0f);
            const PixelRay ray = pixel_ray(plan, c, j);
            const double len = std::sqrt(ray.D[0] * ray.D[0] + ray.D[1] * ray.D[1] + ray.D[2] * ray.D[2]);
            for (int k = 0; k < 3; ++k)
                EXPECT_NEAR(q[k], -ray.D[k] / len, 1e-6); // float rounding of a unit vector
        }
    }
}

TYPED_TEST(CpuNormals, GrazingPlaneStaysFiniteAndSmall) {
    const bool f64 = std::is_same_v<TypeParam, double>;
    // A floor 1 m below the sonar seen out to 40 m: incidence goes to grazing at the far end.
    SceneBuilder b;
    b.draw(b.mesh({0.5f, -50.f, -1.f, 60.f, -50.f, -1.f, 60.f, 50.f, -1.f, 0.5f, 50.f, -1.f}, {0, 1, 2, 0, 2, 3}),
           b.material(-20.0));
    const Plan plan = plan_for(small_config(), b.scene);
    const DepthBuffers d = run_depth(plan, b.scene);
    const std::vector<float> out = run_normals_plan(plan, d.depth, f64);
    int hits = 0;
    for (std::size_t p = 0; p < d.depth.size(); ++p) {
        if (d.depth[p] <= 0.0f) continue;
        ++hits;
        for (int k = 0; k < 4; ++k)
            ASSERT_TRUE(std::isfinite(out[4 * p + k]));
        const std::uint32_t c = std::uint32_t(p % plan.columns), j = std::uint32_t(p / plan.columns);
        const PixelRay ray = pixel_ray(plan, c, j);
        const double len = std::sqrt(ray.D[0] * ray.D[0] + ray.D[1] * ray.D[1] + ray.D[2] * ray.D[2]);
        const double expected = std::abs(ray.D[2]) / len; // floor normal (0, 0, 1)
        // Neighbouring rows differ by up to ~40% in range near grazing, so the one-sided branch runs
        // there; a floor is still a plane: same 1e-3 as the plane test.
        EXPECT_NEAR(out[4 * p + 3], expected, 1e-3) << c << "," << j;
    }
    EXPECT_GT(hits, 100);
}

// normal_method = sobel5 on analytic depth (no rasterizer: the surfaces are exact, so the only
// errors are the stencils' and the float depth's). small_config has 64 x 32 pixels of ~0.31 deg.

// Depth of the first hit of each pixel ray; hit(D) returns the view z of P = z D, or <= 0 for a miss.
template <class Hit> std::vector<float> analytic_depth(const Plan& plan, Hit hit) {
    std::vector<float> depth(std::size_t(plan.rows) * plan.columns, 0.0f);
    for (std::uint32_t j = 0; j < plan.rows; ++j) {
        for (std::uint32_t c = 0; c < plan.columns; ++c) {
            const double z = hit(pixel_ray(plan, c, j).D);
            if (z > 0) depth[std::size_t(j) * plan.columns + c] = float(plan.depth_b + plan.depth_a / z);
        }
    }
    return depth;
}

// Sphere of radius kSphereR about (kSphereX, 0, 0): it fills the view vertically, its silhouette
// and the image border give the fallback paths.
constexpr double kSphereX = 12.0, kSphereR = 3.0;
double sphere_hit(const double* D) {
    const double a = D[0] * D[0] + D[1] * D[1] + D[2] * D[2], b = -2.0 * kSphereX * D[0];
    const double cc = kSphereX * kSphereX - kSphereR * kSphereR, disc = b * b - 4 * a * cc;
    return disc < 0 ? 0.0 : (-b - std::sqrt(disc)) / (2 * a);
}

Plan plan_with(NormalMethod method) {
    SonarConfig config = small_config();
    config.normal_method = method;
    SceneBuilder b;
    b.material(-20.0);
    return plan_for(config, b.scene);
}

// Angle in degrees between the output normal of pixel p and the sphere's outward normal there.
double sphere_error_deg(const Plan& plan, const std::vector<float>& depth, const std::vector<float>& out,
                        std::size_t p) {
    const PixelRay ray = pixel_ray(plan, std::uint32_t(p % plan.columns), std::uint32_t(p / plan.columns));
    const double z = view_z(plan, depth[p]);
    // atan2(|n x m|, n . m) and not acos: a point off the sphere by the depth's rounding or noise
    // has |P - centre| != R, and acos near 1 would turn a 1e-7 length error into 0.03 deg.
    const double n[3] = {z * ray.D[0] - kSphereX, z * ray.D[1], z * ray.D[2]};
    const double m[3] = {out[4 * p], out[4 * p + 1], out[4 * p + 2]};
    const double cr[3] = {n[1] * m[2] - n[2] * m[1], n[2] * m[0] - n[0] * m[2], n[0] * m[1] - n[1] * m[0]};
    return std::atan2(std::sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]),
                      n[0] * m[0] + n[1] * m[1] + n[2] * m[2]) /
           kDeg;
}

// True if pixel (c, j) and its 5x5 window lie on the surface: no miss and not the image border.
bool interior5(const Plan& plan, const std::vector<float>& depth, std::int64_t c, std::int64_t j) {
    for (std::int64_t y = j - 2; y <= j + 2; ++y) {
        for (std::int64_t x = c - 2; x <= c + 2; ++x) {
            if (x < 0 || y < 0 || x >= plan.columns || y >= plan.rows) return false;
            if (!(depth[std::size_t(y) * plan.columns + std::size_t(x)] > 0.0f)) return false;
        }
    }
    return true;
}

struct SphereErrors {
    double rms3 = 0, rms5 = 0, max3 = 0, max5 = 0;
    int interior = 0, differ = 0;
};

SphereErrors sphere_errors(const std::vector<float>& depth, bool f64) {
    const Plan p3 = plan_with(NormalMethod::sobel3), p5 = plan_with(NormalMethod::sobel5);
    const std::vector<float> n3 = run_normals_plan(p3, depth, f64), n5 = run_normals_plan(p5, depth, f64);
    SphereErrors e;
    for (std::uint32_t j = 0; j < p5.rows; ++j) {
        for (std::uint32_t c = 0; c < p5.columns; ++c) {
            const std::size_t p = std::size_t(j) * p5.columns + c;
            if (!interior5(p5, depth, c, j)) {
                // Within 2 pixels of a miss or the border sobel5 is exactly the sobel3 path.
                for (int k = 0; k < 4; ++k)
                    EXPECT_EQ(n5[4 * p + k], n3[4 * p + k]) << c << "," << j;
                continue;
            }
            const double e3 = sphere_error_deg(p5, depth, n3, p), e5 = sphere_error_deg(p5, depth, n5, p);
            e.rms3 += e3 * e3;
            e.rms5 += e5 * e5;
            e.max3 = std::max(e.max3, e3);
            e.max5 = std::max(e.max5, e5);
            e.differ += n3[4 * p] != n5[4 * p] || n3[4 * p + 1] != n5[4 * p + 1] || n3[4 * p + 2] != n5[4 * p + 2];
            ++e.interior;
        }
    }
    e.rms3 = std::sqrt(e.rms3 / std::max(e.interior, 1));
    e.rms5 = std::sqrt(e.rms5 / std::max(e.interior, 1));
    std::printf("[sobel] %d interior pixels, %d differ; sobel3 rms %.3e max %.3e deg, sobel5 rms %.3e max %.3e deg\n",
                e.interior, e.differ, e.rms3, e.rms3 > 0 ? e.max3 : 0.0, e.rms5, e.max5);
    return e;
}

TYPED_TEST(CpuNormals, Sobel5TiltedPlaneIsExact) {
    const bool f64 = std::is_same_v<TypeParam, double>;
    // The plane of TiltedPlaneMatchesClosedFormIncidence, through (12, 0, 0), facing the sonar.
    const double yaw = 30 * kDeg, pitch = 20 * kDeg;
    const double n[3] = {-std::cos(yaw) * std::cos(pitch), -std::sin(yaw) * std::cos(pitch), std::sin(pitch)};
    const Plan plan = plan_with(NormalMethod::sobel5);
    const std::vector<float> depth =
        analytic_depth(plan, [&](const double* D) { return 12.0 * n[0] / (n[0] * D[0] + n[1] * D[1] + n[2] * D[2]); });
    const std::vector<float> out = run_normals_plan(plan, depth, f64);
    for (std::size_t p = 0; p < depth.size(); ++p) {
        ASSERT_GT(depth[p], 0.0f);
        // Any weighted sum of position differences on a plane lies in the plane: exact up to the
        // float depth (~1e-7 relative over ~0.065 m spacing, x 16 weight sum): 1e-3 as for sobel3.
        for (int k = 0; k < 3; ++k)
            EXPECT_NEAR(out[4 * p + k], n[k], 1e-3) << p;
    }
}

TYPED_TEST(CpuNormals, Sobel5OnSmoothSphereHasBoundedCurvatureBias) {
    const bool f64 = std::is_same_v<TypeParam, double>;
    const Plan plan = plan_with(NormalMethod::sobel5);
    const std::vector<float> depth = analytic_depth(plan, sphere_hit);
    const SphereErrors e = sphere_errors(depth, f64);
    ASSERT_GT(e.interior, 500); // most of the 64 x 32 image
    // Without noise the wider stencil is the less accurate one on a curved surface: the normal turns
    // by ~1-3 deg per pixel here, and Taylor expansion gives the 5x5 twice the 3x3's smoothing bias
    // (second moment of (1 4 6 4 1) is 1 pixel^2, of (1 2 1) 0.5) and 2.5x its derivative truncation
    // (5/12 h^2 f''' vs 1/6 h^2 f'''). So sobel5 must be worse than sobel3 (else it did not run) but
    // by no more than 2.5x (else the weights or the order are wrong). Measured: 0.17 vs 0.26 deg rms.
    EXPECT_GT(e.rms5, e.rms3);
    EXPECT_LE(e.rms5, 2.5 * e.rms3);
    EXPECT_GT(e.differ, e.interior / 2); // on a curved surface the 5x5 result is not the 3x3 one
}

TYPED_TEST(CpuNormals, Sobel5AveragesDepthNoise) {
    const bool f64 = std::is_same_v<TypeParam, double>;
    const Plan plan = plan_with(NormalMethod::sobel5);
    // Range noise of +-1 cm at ~10 m (a coarse or jittered depth), uniform, deterministic: large
    // enough to dominate the curvature bias of the previous test.
    std::uint32_t state = 12345u;
    const std::vector<float> depth = analytic_depth(plan, [&](const double* D) {
        state = state * 1664525u + 1013904223u;
        const double noise = (double(state >> 8) / double(1u << 24) * 2.0 - 1.0) * 1e-2;
        const double z = sphere_hit(D);
        return z > 0 ? z * (1.0 + noise / 10.0) : z;
    });
    const SphereErrors e = sphere_errors(depth, f64);
    ASSERT_GT(e.interior, 500);
    // Independent noise on each position: the tangent's noise-to-signal ratio is
    // sqrt(sum w^2) / sum(derivative gain): sqrt(2 * 6) / 8 = 0.43 for 3x3, sqrt(70 * 10) / 128 = 0.21
    // for 5x5, so the rms angle error should roughly halve (measured on a noisy plane: 0.48x);
    // 0.75 leaves room for the curvature bias, which goes the other way. Measured: 1.3 vs 0.7 deg.
    EXPECT_LT(e.rms5, 0.75 * e.rms3);
    // Near the silhouette the range changes by more than edge_relative_jump over 2 pixels: those
    // pixels take the sobel3 path even though their window has no miss.
    EXPECT_GT(e.differ, e.interior / 2);
}

// ---------------------------------------------------------------------------------------------
// 3. Echo

template <class Real> class CpuEchoTyped : public ::testing::Test {};
TYPED_TEST_SUITE(CpuEchoTyped, Precisions);

TYPED_TEST(CpuEchoTyped, PixelMatchesSonarEquationOnHandComputedInputs) {
    using Real = TypeParam;
    SceneBuilder b;
    b.material(-20.0);                                    // material 0: lambert
    b.material(-10.0, AcousticMaterial::Model::constant); // material 1
    b.draw(b.quad_x(10, -1, 1, -1, 1), 0);
    const Plan plan = plan_for(small_config(), b.scene);
    const std::size_t n = std::size_t(plan.rows) * plan.columns;
    std::vector<float> depth(n, 0.0f), normals(4 * n, 0.0f), echo(2 * n, -1.0f);
    std::vector<std::uint32_t> material(n, shared::kNoMaterial);
    auto depth_at = [&](double z) { return float(plan.depth_b + plan.depth_a / z); };
    // pixel a: lambert, cos 0.6; b: constant model; c: no material id; d/e: outside the range window.
    const std::size_t pa = 3 * plan.columns + 11, pb = 20 * plan.columns + 50, pc = 31 * plan.columns + 0;
    const std::size_t pd = 10 * plan.columns + 10, pe = 11 * plan.columns + 12;
    depth[pa] = depth_at(7.5);
    material[pa] = 0;
    normals[4 * pa + 3] = 0.6f;
    depth[pb] = depth_at(23.0);
    material[pb] = 1;
    normals[4 * pb + 3] = 0.1f;
    depth[pc] = depth_at(2.0);
    normals[4 * pc + 3] = 0.8f;
    depth[pd] = depth_at(0.47); // slant range 0.485 m < range_min 0.5 m (near plane 0.463 m)
    material[pd] = 0;
    depth[pe] = depth_at(39.99); // slant range > 40 m off axis
    material[pe] = 0;
    cpu::echo<Real>(plan, depth.data(), material.data(), normals.data(), echo.data());

    for (std::size_t p : {pa, pb, pc, pd, pe}) {
        // Hand-computed inputs in double from the contract.
        const std::uint32_t c = std::uint32_t(p % plan.columns), j = std::uint32_t(p / plan.columns);
        const double u = (2.0 * (c + 0.5) / plan.slice_columns - 1.0) * plan.tan_half_h;
        const double v = (2.0 * (j + 0.5) / plan.rows - 1.0) * plan.tan_half_v;
        const double z = plan.depth_a / (double(depth[p]) - plan.depth_b);
        const double r = z * std::sqrt(1 + u * u + v * v);
        const std::uint32_t m = material[p] == shared::kNoMaterial ? 0u : material[p];
        const double f = plan.materials[m].model == shared::kScatterLambert ? double(normals[4 * p + 3]) : 1.0;
        const double omega = (2 * plan.tan_half_h / plan.slice_columns) * (2 * plan.tan_half_v / plan.rows) /
                             std::pow(1 + u * u + v * v, 1.5);
        const double psi = std::atan2(-v, std::sqrt(1 + u * u));
        const double bv =
            math_f64::pattern_power(shared::kPatternSinc, plan.vpattern_k, plan.vpattern_halfwidth_rad, psi);
        double expected = Math<double>::echo_energy(double(plan.materials[m].backscatter_linear), f, omega, r,
                                                    plan.alpha_db_per_m, bv, true, true);
        if (r < 0.5 || r >= 40.0) expected = 0.0;
        // float storage of the result: 6e-8; in float arithmetic, about ten roundings plus exp/pow of
        // arguments ~10 (relative 1e-6): 1e-5.
        const double tol = std::is_same_v<Real, double> ? 2e-7 : 1e-5;
        EXPECT_NEAR(echo[2 * p], expected, tol * expected) << "pixel " << p;
        EXPECT_NEAR(echo[2 * p + 1], r, tol * r);
    }
    EXPECT_EQ(echo[2 * pd], 0.0f);
    EXPECT_EQ(echo[2 * pe], 0.0f);
    EXPECT_GT(echo[2 * pa], 0.0f);
    // Empty pixels give (0, 0).
    EXPECT_EQ(echo[0], 0.0f);
    EXPECT_EQ(echo[1], 0.0f);
}

TEST(CpuEcho, IncidenceOffIgnoresNormalsAndVerticalPatternOffIsOne) {
    SceneBuilder b;
    b.material(-20.0);
    SonarConfig config = small_config();
    config.effects.incidence = EffectMode::off;
    config.effects.vertical_pattern = EffectMode::off;
    config.effects.absorption = EffectMode::off;
    config.effects.spreading = EffectMode::off;
    const Plan plan = plan_for(config, b.scene);
    const std::size_t n = std::size_t(plan.rows) * plan.columns;
    std::vector<float> depth(n, 0.0f), echo(2 * n);
    std::vector<std::uint32_t> material(n, 0);
    const std::size_t p = 2 * plan.columns + 5; // far off the vertical axis: b_v would be small
    depth[p] = float(plan.depth_b + plan.depth_a / 12.0);
    cpu::echo<double>(plan, depth.data(), material.data(), nullptr, echo.data());
    const std::uint32_t c = 5, j = 2;
    const double u = math_f64::pixel_coord(c, plan.slice_columns, plan.tan_half_h);
    const double v = math_f64::pixel_coord(j, plan.rows, plan.tan_half_v);
    const double r = echo[2 * p + 1];
    const double omega =
        math_f64::pixel_solid_angle(u, v, 2 * plan.tan_half_h / plan.slice_columns, 2 * plan.tan_half_v / plan.rows);
    // f = 1, b = 1, no absorption, footprint r^2 Omega without spreading.
    const double expected = plan.materials[0].backscatter_linear * omega * r * r;
    EXPECT_NEAR(echo[2 * p], expected, 2e-7 * expected); // double arithmetic, float storage
}

// ---------------------------------------------------------------------------------------------
// 4. Beamform

template <class Real> class CpuBeamform : public ::testing::Test {};
TYPED_TEST_SUITE(CpuBeamform, Precisions);

struct BeamformOut {
    std::vector<float> profiles, beams, polar;
};

template <class Real> BeamformOut run_beamform(const Plan& plan, const std::vector<float>& echo2) {
    BeamformOut o;
    o.profiles.assign(std::size_t(plan.bins) * plan.columns, -1.0f);
    o.beams.assign(std::size_t(plan.bins) * plan.beams, -1.0f);
    o.polar.assign(std::size_t(plan.bins) * plan.beams, -1.0f);
    cpu::beamform<Real>(plan, echo2.data(), o.profiles.data(), o.beams.data(), o.polar.data());
    return o;
}

// Random echo: energies in (0, 1) at ranges inside the window, a third of the pixels empty.
std::vector<float> random_echo(const Plan& plan, double* total) {
    std::mt19937 rng(1234);
    std::uniform_real_distribution<double> uni(0.0, 1.0);
    std::vector<float> e(std::size_t(plan.rows) * plan.columns * 2, 0.0f);
    *total = 0;
    for (std::size_t p = 0; p < e.size() / 2; ++p) {
        if (uni(rng) < 0.33) continue;
        const double r = plan.config.range_min_m + uni(rng) * (plan.config.range_max_m - plan.config.range_min_m);
        e[2 * p] = float(uni(rng));
        float rf = float(r);
        if (rf >= float(plan.config.range_max_m)) rf = std::nextafter(float(plan.config.range_max_m), 0.0f);
        e[2 * p + 1] = rf;
        *total += e[2 * p];
    }
    return e;
}

TYPED_TEST(CpuBeamform, TentKernelConservesEnergyAndIsBitIdenticalRunToRun) {
    using Real = TypeParam;
    SceneBuilder b;
    b.material(-20.0);
    SonarConfig config = small_config();
    config.effects.horizontal_pattern = EffectMode::off;
    const Plan plan = plan_for(config, b.scene);
    double total = 0;
    const std::vector<float> echo2 = random_echo(plan, &total);
    const BeamformOut a = run_beamform<Real>(plan, echo2);
    const BeamformOut again = run_beamform<Real>(plan, echo2);
    EXPECT_EQ(0, std::memcmp(a.polar.data(), again.polar.data(), a.polar.size() * sizeof(float)));
    EXPECT_EQ(0, std::memcmp(a.profiles.data(), again.profiles.data(), a.profiles.size() * sizeof(float)));

    double sum_profiles = 0, sum_beams = 0, sum_polar = 0;
    for (float x : a.profiles)
        sum_profiles += x;
    for (float x : a.beams)
        sum_beams += x;
    for (float x : a.polar)
        sum_polar += x;
    // ~1400 values of ~0.5 summed per column into ~128 bins: float accumulation error ~ sqrt(rows) eps
    // per bin, float storage 6e-8; 1e-5 relative covers float arithmetic with a wide margin, double
    // arithmetic only sees the float roundings of the stored intermediates (1e-6).
    const double tol = (std::is_same_v<Real, double> ? 1e-6 : 1e-5) * total;
    EXPECT_NEAR(sum_profiles, total, tol);
    EXPECT_NEAR(sum_beams, total, tol);
    EXPECT_NEAR(sum_polar, total, tol);
    for (std::size_t i = 0; i < a.polar.size(); ++i)
        EXPECT_EQ(a.polar[i], a.beams[i]); // pattern off: copy
}

TYPED_TEST(CpuBeamform, RangeKernelsPlaceEnergyInTheContractsBins) {
    using Real = TypeParam;
    SceneBuilder b;
    b.material(-20.0);
    for (RangeKernel kernel : {RangeKernel::nearest, RangeKernel::tent}) {
        SonarConfig config = small_config();
        config.range_kernel = kernel;
        config.effects.horizontal_pattern = EffectMode::off;
        const Plan plan = plan_for(config, b.scene);
        const double w = plan.bin_width_m, r0 = plan.config.range_min_m;
        struct Case {
            double r, e;
        };
        // column 0: bin centre of bin 10; column 1: a quarter into bin 20; column 2: just above range_min;
        // column 3: just below range_max.
        const Case cases[4] = {
            {r0 + 10.5 * w, 1.0}, {r0 + 20.25 * w, 2.0}, {r0 + 0.1 * w, 4.0}, {r0 + (plan.bins - 0.1) * w, 8.0}};
        std::vector<float> echo2(std::size_t(plan.rows) * plan.columns * 2, 0.0f);
        for (int c = 0; c < 4; ++c) {
            echo2[2 * (std::size_t(7) * plan.columns + c)] = float(cases[c].e);
            echo2[2 * (std::size_t(7) * plan.columns + c) + 1] = float(cases[c].r);
        }
        const BeamformOut o = run_beamform<Real>(plan, echo2);
        auto prof = [&](std::uint32_t k, std::uint32_t c) {
            return double(o.profiles[std::size_t(k) * plan.columns + c]);
        };
        // Tolerances: ranges are stored as float (ulp ~2e-6 m at 20 m, i.e. 7e-6 of a 0.31 m bin).
        const double tol = 1e-4;
        if (kernel == RangeKernel::nearest) {
            EXPECT_EQ(prof(10, 0), 1.0);
            EXPECT_EQ(prof(20, 1), 2.0);
            EXPECT_EQ(prof(0, 2), 4.0);
            EXPECT_EQ(prof(plan.bins - 1, 3), 8.0);
        } else {
            EXPECT_NEAR(prof(10, 0), 1.0, tol);
            // t = 19.75: 0.25 to bin 19, 0.75 to bin 20
            EXPECT_NEAR(prof(19, 1), 0.25 * 2.0, tol * 2);
            EXPECT_NEAR(prof(20, 1), 0.75 * 2.0, tol * 2);
            EXPECT_NEAR(prof(0, 2), 4.0, tol * 4);             // share below bin 0 kept in bin 0
            EXPECT_NEAR(prof(plan.bins - 1, 3), 8.0, tol * 8); // share above the last bin kept
        }
        for (int c = 0; c < 4; ++c) {
            double s = 0;
            for (std::uint32_t k = 0; k < plan.bins; ++k)
                s += prof(k, c);
            EXPECT_NEAR(s, cases[c].e, 1e-6 * cases[c].e); // nothing lost; float roundings only
        }
    }
}

TYPED_TEST(CpuBeamform, ResampleAndSidelobeFollowTheirFormulas) {
    using Real = TypeParam;
    SceneBuilder b;
    b.material(-20.0);
    SonarConfig config = small_config();
    config.horizontal_beamwidth_deg = 4.0; // several side-lobe taps
    const Plan plan = plan_for(config, b.scene);
    ASSERT_TRUE(plan.effects.horizontal_pattern);
    ASSERT_GT(plan.sidelobe_taps, 3u);
    double total = 0;
    const std::vector<float> echo2 = random_echo(plan, &total);
    const BeamformOut o = run_beamform<Real>(plan, echo2);
    const std::int64_t K = (plan.sidelobe_taps - 1) / 2;
    double max_rel = 0;
    for (std::uint32_t k = 0; k < plan.bins; ++k) {
        for (std::uint32_t j = 0; j < plan.beams; ++j) {
            double B = 0; // resample from the definition: every column, weight by the table
            for (std::uint32_t c = 0; c < plan.columns; ++c) {
                const double w = plan.column_beam[c] == j       ? plan.column_weight[c]
                                 : plan.column_beam[c] + 1 == j ? 1.0 - plan.column_weight[c]
                                                                : 0.0;
                B += w * o.profiles[std::size_t(k) * plan.columns + c];
            }
            double P = 0;
            for (std::uint32_t t = 0; t < plan.sidelobe_taps; ++t) {
                const std::int64_t src = std::int64_t(j) - K + t;
                if (src < 0 || src >= std::int64_t(plan.beams)) continue;
                P += double(plan.sidelobe_weight[j * plan.sidelobe_taps + t]) *
                     o.beams[std::size_t(k) * plan.beams + src];
            }
            const double gotB = o.beams[std::size_t(k) * plan.beams + j],
                         gotP = o.polar[std::size_t(k) * plan.beams + j];
            // Sums of <= ~10 positive float terms: float arithmetic is good to ~1e-6 relative.
            EXPECT_NEAR(gotB, B, 2e-6 * B + 1e-30);
            EXPECT_NEAR(gotP, P, 2e-6 * P + 1e-30);
            if (P > 0) max_rel = std::max(max_rel, std::abs(gotP - P) / P);
        }
    }
    this->RecordProperty("max_rel_sidelobe", std::to_string(max_rel));
}

// ---------------------------------------------------------------------------------------------
// Backend

// A seabed tilted down ahead, a box on it and a wall behind: every stage has work to do.
SceneData test_scene() {
    SceneBuilder b;
    const std::uint32_t bed = b.material(-30.0), box = b.material(-15.0),
                        wall = b.material(-25.0, AcousticMaterial::Model::constant);
    b.draw(b.mesh({0.5f, -30.f, -1.0f, 45.f, -30.f, -6.0f, 45.f, 30.f, -6.0f, 0.5f, 30.f, -1.0f}, {0, 1, 2, 0, 2, 3}),
           bed);
    const double lo[3] = {12.0, -1.0, -3.0}, hi[3] = {13.5, 1.5, -1.0};
    b.draw(b.box(lo, hi), box, yaw_translate(20.0, 0, 0, 0));
    b.draw(b.quad_x(0.0, -20.0, 20.0, -8.0, 8.0), wall, yaw_translate(-15.0, 30.0, 0.0, 0.0));
    return b.scene;
}

Frame sized_frame(const Plan& plan) {
    Frame f;
    f.beams = plan.beams;
    f.bins = plan.bins;
    f.columns = plan.columns;
    f.rows = plan.rows;
    f.clean.resize(std::size_t(plan.bins) * plan.beams);
    return f;
}

TEST(CpuBackend, RunsTheContractsStagesAndFillsRequestedIntermediates) {
    const SceneData scene = test_scene();
    for (bool incidence : {true, false}) {
        SonarConfig config = small_config();
        config.effects.incidence = incidence ? EffectMode::on : EffectMode::off;
        const Plan plan = plan_for(config, scene);
        auto backend = cpu::make_backend(plan, scene);
        ASSERT_TRUE(backend);
        EXPECT_STREQ(backend->name(), "cpu");
        Frame frame = sized_frame(plan);
        Pose pose;
        pose.yaw_deg = 5.0;
        const std::uint32_t mask = save_depth | save_normals | save_echo | save_profiles;
        auto r = backend->render(pose, mask, frame);
        ASSERT_TRUE(r.ok()) << r.error().message;
        const std::vector<std::string> expected = incidence
                                                      ? std::vector<std::string>{"depth", "normals", "echo", "beamform"}
                                                      : std::vector<std::string>{"depth", "echo", "beamform"};
        EXPECT_EQ(frame.stages_run, expected);
        ASSERT_EQ(frame.times.size(), expected.size());
        for (std::size_t i = 0; i < expected.size(); ++i) {
            EXPECT_EQ(frame.times[i].stage, expected[i]);
            EXPECT_GE(frame.times[i].ms, 0.0);
        }
        const std::size_t pixels = std::size_t(plan.rows) * plan.columns;
        EXPECT_EQ(frame.depth.size(), pixels);
        EXPECT_EQ(frame.material.size(), pixels);
        EXPECT_EQ(frame.normals.size(), incidence ? 4 * pixels : 0u);
        EXPECT_EQ(frame.echo.size(), 2 * pixels);
        EXPECT_EQ(frame.profiles.size(), std::size_t(plan.bins) * plan.columns);
        EXPECT_EQ(frame.beam_profiles.size(), std::size_t(plan.bins) * plan.beams);
        ASSERT_EQ(frame.clean.size(), std::size_t(plan.bins) * plan.beams);
        double sum = 0;
        for (float x : frame.clean) {
            ASSERT_TRUE(std::isfinite(x));
            ASSERT_GE(x, 0.0f);
            sum += x;
        }
        EXPECT_GT(sum, 0.0);

        // Same pose again: bit-identical scan, and no new buffers (the frame's data pointer is kept).
        const std::vector<float> first = frame.clean;
        const float* data = frame.clean.data();
        frame.times.clear();
        frame.stages_run.clear();
        auto r2 = backend->render(pose, mask, frame);
        ASSERT_TRUE(r2.ok());
        EXPECT_EQ(frame.clean.data(), data);
        EXPECT_EQ(0, std::memcmp(first.data(), frame.clean.data(), first.size() * sizeof(float)));
    }
}

TEST(CpuBackend, NonFinitePoseIsAnErrorNamingTheField) {
    const SceneData scene = test_scene();
    const Plan plan = plan_for(small_config(), scene);
    auto backend = cpu::make_backend(plan, scene);
    Frame frame = sized_frame(plan);
    Pose pose;
    pose.pitch_deg = std::numeric_limits<double>::quiet_NaN();
    auto r = backend->render(pose, 0, frame);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("pitch"), std::string::npos) << r.error().message;
}

TEST(CpuBackend, DoubleAndFloatPrecisionAgree) {
    const SceneData scene = test_scene();
    SonarConfig config = small_config();
    config.cpu_precision = Precision::f32;
    const Plan p32 = plan_for(config, scene);
    config.cpu_precision = Precision::f64;
    const Plan p64 = plan_for(config, scene);
    Frame f32 = sized_frame(p32), f64 = sized_frame(p64);
    Pose pose;
    pose.yaw_deg = -3.0;
    ASSERT_TRUE(cpu::make_backend(p32, scene)->render(pose, save_echo, f32).ok());
    ASSERT_TRUE(cpu::make_backend(p64, scene)->render(pose, save_echo, f64).ok());
    double total32 = 0, total64 = 0, peak = 0;
    for (std::size_t i = 0; i < f64.clean.size(); ++i) {
        total32 += f32.clean[i];
        total64 += f64.clean[i];
        peak = std::max(peak, double(f64.clean[i]));
    }
    ASSERT_GT(total64, 0.0);
    // Per cell, relative to the scan's peak: a cell that holds only a small tent share of a pixel
    // has an ill-conditioned relative error (its share moves with the pixel's range), so cells are
    // compared against the peak.
    double max_rel_peak = 0;
    for (std::size_t i = 0; i < f64.clean.size(); ++i) {
        max_rel_peak = std::max(max_rel_peak, std::abs(double(f32.clean[i]) - f64.clean[i]) / peak);
    }
    // Both share the float depth buffer, so the differences are float arithmetic in the later
    // stages: per-pixel energies agree to a few 1e-6 (about ten roundings and an exp of ~-4), and a
    // range moved by float rounding (~1e-6 of a bin) moves that much of a pixel's tent weight.
    EXPECT_NEAR(total32 / total64, 1.0, 1e-5);
    EXPECT_LT(max_rel_peak, 1e-5);
    double max_rel_pixel = 0;
    for (std::size_t p = 0; p < f64.echo.size(); p += 2) {
        if (f64.echo[p] > 0)
            max_rel_pixel = std::max(max_rel_pixel, std::abs(double(f32.echo[p]) - f64.echo[p]) / f64.echo[p]);
    }
    EXPECT_LT(max_rel_pixel, 1e-4);
    RecordProperty("f32_vs_f64_total", std::to_string(total32 / total64 - 1.0));
    RecordProperty("f32_vs_f64_max_cell_over_peak", std::to_string(max_rel_peak));
    RecordProperty("f32_vs_f64_max_pixel", std::to_string(max_rel_pixel));
    std::printf("f32 vs f64: total %.3g, max cell / peak %.3g, max pixel %.3g\n", total32 / total64 - 1.0, max_rel_peak,
                max_rel_pixel);
}

} // namespace
} // namespace vksonar
