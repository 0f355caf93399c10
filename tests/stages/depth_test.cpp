// Tests of the CPU depth pass (src/stages/cpu_depth.cpp) against docs/pipeline.md §1, on scenes
// built by hand as SceneData: fill rule, reversed-Z, slices, clipping, degenerate triangles.
// Every tolerance is justified next to it.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "core/pixel_views.h"
#include "cpu_stage_support.h"
#include "stages/gpu_cpu_support.h"

namespace vksonar {
namespace {

using namespace stage_testing;

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
                // Pixel centres within 1 cm of the near quad's edges are left out: either answer is right.
                const bool in_near = std::abs(6.0 * ray.D[1]) < 0.99 && std::abs(6.0 * ray.D[2]) < 0.39;
                const bool off_near = std::abs(6.0 * ray.D[1]) > 1.01 || std::abs(6.0 * ray.D[2]) > 0.41;
                const bool in_far = off_near && std::abs(8.0 * ray.D[1]) < 2.99 && std::abs(8.0 * ray.D[2]) < 0.99;
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
                                 std::vector<std::vector<bool>>* masks = nullptr, bool simd = true) {
    std::vector<int> count(std::size_t(plan.rows) * plan.columns, 0);
    for (std::size_t i = 0; i < scene.draws.size(); ++i) {
        SceneData one = scene;
        one.draws = {scene.draws[i]};
        std::vector<shared::DepthPush> p;
        for (std::uint32_t s = 0; s < plan.slices; ++s)
            p.push_back(pushes[s * scene.draws.size() + i]);
        std::vector<float> depth(count.size());
        std::vector<std::uint32_t> material(count.size());
        cpu::DepthRegion region;
        region.simd = simd;
        cpu::depth_pass(plan, one, p, depth.data(), material.data(), nullptr, nullptr, region);
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
    // The rasterizer's grid only: with identity clip matrices nothing else of the plan matters here.
    Plan plan = plan_for(small_config(), b.scene);
    plan.rows = plan.params.rows = 32;
    ASSERT_EQ(plan.columns, 64u);
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
        for (const bool simd : {true, false}) { // four pixels at a time (AVX2, where the CPU has it), one at a time
            const std::vector<int> count = coverage_counts(plan, sb.scene, pushes, nullptr, simd);
            for (std::uint32_t j = 0; j < plan.rows; ++j) {
                for (std::uint32_t c = 0; c < plan.columns; ++c) {
                    const bool inside = c >= 2 && c <= 9 && j >= 1 && j <= 8;
                    EXPECT_EQ(count[std::size_t(j) * plan.columns + c], inside ? 1 : 0)
                        << "split " << k << " pixel " << c << "," << j << (simd ? " simd" : " scalar");
                }
            }
        }
    }
}

TEST(CpuDepth, BandsOfRowsAndViewsGiveTheWholeImagesBytes) {
    // The CPU backend runs the pass as bands of rows of one view on its threads (cpu_backend.cpp): every pixel must
    // see the same triangles in the same order as in one pass over the image, ties (the strict GREATER
    // test keeps the first draw) and clipped triangles crossing band edges included. A room around the
    // sonar (every slice, near-plane clipping), two crossing planes at equal depth in the middle, and
    // 200 random triangles in front; the face-normal buffer too.
    SceneBuilder b;
    const double lo[3] = {-10, -10, -10}, hi[3] = {10, 10, 10};
    const std::uint32_t m0 = b.material(-20.0), m1 = b.material(-10.0), m2 = b.material(-30.0);
    b.draw(b.box(lo, hi), m0);
    b.draw(b.mesh({8, -6, -3, 8, 6, -3, 8, 6, 3, 8, -6, 3}, {0, 1, 2, 0, 2, 3}), m1);
    b.draw(b.mesh({8, -3, -6, 8, 3, -6, 8, 3, 6, 8, -3, 6}, {0, 1, 2, 0, 2, 3}), m2); // same plane: ties
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> coord(-1.0f, 1.0f), ahead(4.0f, 8.0f);
    std::vector<float> soup;
    std::vector<std::uint32_t> soup_indices;
    for (std::uint32_t t = 0; t < 200; ++t) {
        for (int k = 0; k < 3; ++k) {
            soup.insert(soup.end(), {ahead(rng), coord(rng), coord(rng)});
            soup_indices.push_back(3 * t + std::uint32_t(k));
        }
    }
    b.draw(b.mesh(soup, soup_indices), m1);
    // A seabed grid of 48 x 48 quads, 2 m below: several clusters of 512 triangles, some of them wholly
    // above or below a band (the bands skip those).
    std::vector<float> grid;
    std::vector<std::uint32_t> grid_indices;
    const std::uint32_t n = 48;
    for (std::uint32_t i = 0; i <= n; ++i)
        for (std::uint32_t j = 0; j <= n; ++j)
            grid.insert(grid.end(), {2.0f + 0.15f * float(i), -3.6f + 0.15f * float(j), -2.0f});
    for (std::uint32_t i = 0; i < n; ++i) {
        for (std::uint32_t j = 0; j < n; ++j) {
            const std::uint32_t v = i * (n + 1) + j;
            grid_indices.insert(grid_indices.end(), {v, v + n + 1, v + 1, v + 1, v + n + 1, v + n + 2});
        }
    }
    b.draw(b.mesh(grid, grid_indices), m2);
    SonarConfig config = small_config();
    config.hfov_deg = 130.0;
    config.beams = 64;
    config.vertical_coverage = 6.0; // +-30 degrees: the grid below the soup
    const Plan plan = plan_for(config, b.scene);
    std::vector<shared::DepthPush> draws;
    compose_depth_draws(plan, b.scene, Pose{}, draws);
    const std::size_t pixels = std::size_t(plan.rows) * plan.columns;
    std::vector<float> depth(pixels, -1.0f), face(4 * pixels, -1.0f);
    std::vector<std::uint32_t> material(pixels, 12345u);
    cpu::depth_pass(plan, b.scene, draws, depth.data(), material.data(), face.data());
    ASSERT_GT(std::count(material.begin(), material.end(), m0), 0);
    ASSERT_GT(std::count(material.begin(), material.end(), m1), 0);
    ASSERT_GT(std::count(material.begin(), material.end(), m2), 0);
    // The pixels four at a time (AVX2, where this CPU has it: the pass above) against one at a time: the
    // same bytes, ties, shared edges and clipped triangles included.
    {
        std::vector<float> scalar_depth(pixels, -1.0f), scalar_face(4 * pixels, -1.0f);
        std::vector<std::uint32_t> scalar_material(pixels, 12345u);
        cpu::DepthRegion one_at_a_time;
        one_at_a_time.simd = false;
        cpu::depth_pass(plan, b.scene, draws, scalar_depth.data(), scalar_material.data(), scalar_face.data(), nullptr,
                        one_at_a_time);
        EXPECT_EQ(scalar_depth, depth);
        EXPECT_EQ(scalar_material, material);
        EXPECT_EQ(scalar_face, face);
    }
    // By whole meshes, and by clusters as the CPU backend draws them.
    std::vector<DepthCluster> runs;
    std::vector<std::uint8_t> drawn;
    build_depth_clusters(b.scene, runs);
    cull_depth_clusters(runs, b.scene.draws.size(), draws, drawn);
    ASSERT_GT(runs.size(), 4u);
    const cpu::DepthClusters clusters{runs, drawn};
    // Each vertex transformed and projected once per run (the vertex cache: the room, the planes, the
    // soup and each cluster of the grid; the whole grid spans too many vertices for it) against once per
    // corner of every triangle: the same bytes, near-plane clipping and ties included.
    for (const cpu::DepthClusters* by : {static_cast<const cpu::DepthClusters*>(nullptr), &clusters}) {
        for (bool simd : {true, false}) {
            std::vector<float> cached_depth(pixels, -1.0f), cached_face(4 * pixels, -1.0f);
            std::vector<float> corner_depth(pixels, -1.0f), corner_face(4 * pixels, -1.0f);
            std::vector<std::uint32_t> cached_material(pixels, 12345u), corner_material(pixels, 12345u);
            cpu::DepthRegion cached, per_corner;
            cached.simd = per_corner.simd = simd;
            per_corner.vertex_cache = false;
            cpu::depth_pass(plan, b.scene, draws, cached_depth.data(), cached_material.data(), cached_face.data(), by,
                            cached);
            cpu::depth_pass(plan, b.scene, draws, corner_depth.data(), corner_material.data(), corner_face.data(), by,
                            per_corner);
            const char* how = by ? "clusters" : "meshes";
            EXPECT_EQ(cached_depth, depth) << how << ", simd " << simd;
            EXPECT_EQ(corner_depth, depth) << how << ", simd " << simd;
            EXPECT_EQ(corner_material, material) << how << ", simd " << simd;
            EXPECT_EQ(cached_material, material) << how << ", simd " << simd;
            EXPECT_EQ(corner_face, face) << how << ", simd " << simd;
            EXPECT_EQ(cached_face, face) << how << ", simd " << simd;
        }
    }
    for (const cpu::DepthClusters* by : {static_cast<const cpu::DepthClusters*>(nullptr), &clusters}) {
        for (std::uint32_t bands : {2u, 3u, 7u, plan.rows}) {
            std::vector<float> band_depth(pixels, -1.0f), band_face(4 * pixels, -1.0f);
            std::vector<std::uint32_t> band_material(pixels, 12345u);
            const std::uint32_t step = (plan.rows + bands - 1) / bands;
            for (std::uint32_t begin = 0; begin < plan.rows; begin += step) // each clears only its own rows
                cpu::depth_pass(plan, b.scene, draws, band_depth.data(), band_material.data(), band_face.data(), by,
                                {begin, begin + step});
            const char* how = by ? "clusters" : "meshes";
            EXPECT_EQ(band_depth, depth) << bands << " bands, " << how;
            EXPECT_EQ(band_material, material) << bands << " bands, " << how;
            EXPECT_EQ(band_face, face) << bands << " bands, " << how;
            // the same bands, one view at a time
            std::fill(band_depth.begin(), band_depth.end(), -1.0f);
            std::fill(band_face.begin(), band_face.end(), -1.0f);
            std::fill(band_material.begin(), band_material.end(), 12345u);
            for (std::uint32_t view = 0; view < plan.views; ++view)
                for (std::uint32_t begin = 0; begin < plan.rows; begin += step)
                    cpu::depth_pass(plan, b.scene, draws, band_depth.data(), band_material.data(), band_face.data(), by,
                                    {begin, begin + step, view, view + 1});
            EXPECT_EQ(band_depth, depth) << bands << " bands per view, " << how;
            EXPECT_EQ(band_material, material) << bands << " bands per view, " << how;
            EXPECT_EQ(band_face, face) << bands << " bands per view, " << how;
        }
    }
    ASSERT_GT(plan.views, 2u); // the room is seen by several slices
    // A region (a view's band) leaves every other pixel as it was (threads write theirs at the same time).
    {
        const std::uint32_t view = 1, begin = plan.rows / 4, end = 3 * plan.rows / 4;
        const std::size_t first = view_first_column(plan, view), last = first + view_columns(plan, view);
        std::vector<float> band_depth(pixels, -1.0f), band_face(4 * pixels, -1.0f);
        std::vector<std::uint32_t> band_material(pixels, 12345u);
        cpu::depth_pass(plan, b.scene, draws, band_depth.data(), band_material.data(), band_face.data(), &clusters,
                        {begin, end, view, view + 1});
        std::size_t written = 0;
        for (std::size_t p = 0; p < pixels; ++p) {
            const std::size_t row = p / plan.columns, column = p % plan.columns;
            const bool inside = row >= begin && row < end && column >= first && column < last;
            written += inside && band_material[p] != shared::kNoMaterial;
            ASSERT_EQ(band_depth[p], inside ? depth[p] : -1.0f) << "pixel " << p;
            ASSERT_EQ(band_material[p], inside ? material[p] : 12345u) << "pixel " << p;
            ASSERT_EQ(band_face[4 * p], inside ? face[4 * p] : -1.0f) << "pixel " << p;
        }
        EXPECT_GT(written, 0u);
    }
    // And a band leaves every other row as it was (threads write their bands at the same time).
    const std::uint32_t begin = plan.rows / 3, end = 2 * plan.rows / 3;
    std::vector<float> band_depth(pixels, -1.0f), band_face(4 * pixels, -1.0f);
    std::vector<std::uint32_t> band_material(pixels, 12345u);
    cpu::depth_pass(plan, b.scene, draws, band_depth.data(), band_material.data(), band_face.data(), nullptr,
                    {begin, end});
    for (std::size_t p = 0; p < pixels; ++p) {
        const bool inside = p >= std::size_t(begin) * plan.columns && p < std::size_t(end) * plan.columns;
        ASSERT_EQ(band_depth[p], inside ? depth[p] : -1.0f) << "pixel " << p;
        ASSERT_EQ(band_material[p], inside ? material[p] : 12345u) << "pixel " << p;
        ASSERT_EQ(band_face[4 * p], inside ? face[4 * p] : -1.0f) << "pixel " << p;
    }
}

// The per-run vertex cache (DepthRegion::vertex_cache) against the per-corner path on triangles that
// stress its per-vertex work: vertices from millimetres to 1e7 m away, behind the sonar, on the near
// plane's side, far off to the sides (projected to huge or infinite pixel coordinates, which the
// pixel bounds clamp), slivers and shared vertices, in several meshes with 2 to 600 vertices. Every
// depth, material and face-normal byte must agree, with the pixels four at a time and one at a time.
TEST(CpuDepth, VertexCacheGivesThePerCornerBytesOnExtremeTriangles) {
    std::mt19937 rng(2026);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    std::uniform_int_distribution<int> decade(-3, 7);
    SceneBuilder b;
    const std::uint32_t m0 = b.material(-20.0), m1 = b.material(-10.0);
    for (std::uint32_t mesh = 0; mesh < 12; ++mesh) {
        const std::uint32_t vertices = mesh == 0 ? 2u : 3u + 50u * mesh; // up to 553 (+4), all in the cache
        std::vector<float> positions;
        for (std::uint32_t v = 0; v < vertices; ++v) {
            const float scale = std::pow(10.0f, float(decade(rng)));
            // mostly ahead (x > 0), some behind; y and z up to as large as x
            positions.insert(positions.end(), {scale * (0.2f + unit(rng)), scale * unit(rng), scale * unit(rng)});
        }
        // and four far off the axis, 1 m ahead: their pixel coordinates pass 2^31, which the vertices'
        // pixel bounds must clamp before they truncate to integers
        positions.insert(positions.end(), {1.0f, 1e9f, 0.0f, 1.0f, -1e9f, 0.0f, 1.0f, 0.0f, 1e9f, 1.0f, 0.0f, -1e9f});
        std::vector<std::uint32_t> indices;
        std::uniform_int_distribution<std::uint32_t> pick(0, vertices - 1), far_off(vertices, vertices + 3);
        for (std::uint32_t t = 0; t < 2 * vertices; ++t)
            indices.insert(indices.end(), {pick(rng), pick(rng), t % 4 ? pick(rng) : far_off(rng)});
        for (std::uint32_t t = 0; t < 4; ++t) // the fan between the four
            indices.insert(indices.end(), {vertices + t, vertices + (t + 1) % 4, pick(rng)});
        b.draw(b.mesh(positions, indices), mesh % 2 ? m1 : m0);
    }
    SonarConfig config = small_config();
    config.hfov_deg = 130.0; // three slices
    const Plan plan = plan_for(config, b.scene);
    std::vector<shared::DepthPush> draws;
    compose_depth_draws(plan, b.scene, Pose{}, draws);
    const std::size_t pixels = std::size_t(plan.rows) * plan.columns;
    for (bool simd : {true, false}) {
        for (bool with_face : {true, false}) { // the face normals take the vertices' own copy
            std::vector<float> cached_depth(pixels), corner_depth(pixels);
            std::vector<float> cached_face(4 * pixels), corner_face(4 * pixels);
            std::vector<std::uint32_t> cached_material(pixels), corner_material(pixels);
            cpu::DepthRegion cached, per_corner;
            cached.simd = per_corner.simd = simd;
            per_corner.vertex_cache = false;
            cpu::depth_pass(plan, b.scene, draws, cached_depth.data(), cached_material.data(),
                            with_face ? cached_face.data() : nullptr, nullptr, cached);
            cpu::depth_pass(plan, b.scene, draws, corner_depth.data(), corner_material.data(),
                            with_face ? corner_face.data() : nullptr, nullptr, per_corner);
            const auto hit = std::count_if(cached_depth.begin(), cached_depth.end(), [](float d) { return d > 0.0f; });
            const char* how = with_face ? "with face normals" : "depth only";
            EXPECT_GT(hit, std::ptrdiff_t(pixels / 10)) << how << ", simd " << simd; // a good part is covered
            EXPECT_EQ(cached_depth, corner_depth) << how << ", simd " << simd;
            EXPECT_EQ(cached_material, corner_material) << how << ", simd " << simd;
            EXPECT_EQ(cached_face, corner_face) << how << ", simd " << simd;
        }
    }
}

// Slivers across every view, from far to port to far to starboard: each triangle's pixel box spans the
// view while its vertices' own pixel coordinates lie past 2^31 on either side (clamped before they are
// truncated to integers). Both paths draw them, row after row.
TEST(CpuDepth, VertexCacheDrawsTrianglesWhoseVerticesLieFarOutsideTheView) {
    SceneBuilder b;
    const std::uint32_t m = b.material(-20.0);
    std::vector<float> positions;
    std::vector<std::uint32_t> indices;
    for (int i = 0; i < 8; ++i) { // bands of 0.1 m at 8 m, from 0.6 m below to 0.6 m above the axis
        const float z = -0.6f + 0.15f * float(i), side = i % 2 ? 1.0f : -1.0f;
        const auto first = std::uint32_t(positions.size() / 3);
        positions.insert(positions.end(),
                         {8.0f, side * 1e10f, z, 8.0f, side * 1e10f, z + 0.1f, 8.0f, -side * 1e10f, z + 0.05f});
        indices.insert(indices.end(), {first, first + 1, first + 2});
    }
    b.draw(b.mesh(positions, indices), m);
    SonarConfig config = small_config();
    config.hfov_deg = 130.0;
    const Plan plan = plan_for(config, b.scene);
    std::vector<shared::DepthPush> draws;
    compose_depth_draws(plan, b.scene, Pose{}, draws);
    const std::size_t pixels = std::size_t(plan.rows) * plan.columns;
    std::vector<float> cached_depth(pixels), corner_depth(pixels);
    std::vector<std::uint32_t> cached_material(pixels), corner_material(pixels);
    cpu::DepthRegion per_corner;
    per_corner.vertex_cache = false;
    cpu::depth_pass(plan, b.scene, draws, cached_depth.data(), cached_material.data());
    cpu::depth_pass(plan, b.scene, draws, corner_depth.data(), corner_material.data(), nullptr, nullptr, per_corner);
    const auto hit = std::count(corner_material.begin(), corner_material.end(), m);
    EXPECT_GT(hit, std::ptrdiff_t(plan.columns)); // at least a row's worth
    EXPECT_EQ(cached_depth, corner_depth);
    EXPECT_EQ(cached_material, corner_material);
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
    // The nearest-bin kernel needs no range gate beyond the window, so the far plane is range_max.
    SonarConfig config = small_config();
    config.range_kernel = RangeKernel::nearest;
    const Plan plan = plan_for(config, b.scene);
    ASSERT_EQ(plan.far_m, config.range_max_m);
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

// ---- GPU vs CPU (tests/stages/gpu_cpu_support.h; tolerances: tests/tolerances.h) ------------------

using namespace ::vksonar::testing;

class DepthGpuCpu : public GpuCpuScene {};

TEST_P(DepthGpuCpu, DepthDiffersOnlyOnTriangleEdges) {
    auto p = render_pair(GetParam().file, quiet_config(), GetParam().pose, kSaveAll);
    ASSERT_TRUE(p);
    const Frame& g = p->gpu->frame;
    const Frame& c = p->cpu->frame;
    const Plan& plan = renderer_plan(p->gpu->renderer);
    std::size_t hits = 0, mismatched = 0;
    double max_rel_interior = 0, max_abs_range_m = 0;
    for (std::uint32_t row = 0; row < g.rows; ++row) {
        for (std::uint32_t col = 0; col < g.columns; ++col) {
            const std::size_t i = static_cast<std::size_t>(row) * g.columns + col;
            hits += g.depth[i] > 0;
            const bool same_surface = g.material[i] == c.material[i] && (g.depth[i] > 0) == (c.depth[i] > 0);
            const double zg = g.depth[i] > 0 ? plan.depth_a / (g.depth[i] - plan.depth_b) : 0;
            const double zc = c.depth[i] > 0 ? plan.depth_a / (c.depth[i] - plan.depth_b) : 0;
            const double rel = zg > 0 ? std::abs(zg - zc) / zg : 0;
            if (!same_surface || rel > kDepthInteriorRelTol) {
                ++mismatched;
            } else {
                max_rel_interior = std::max(max_rel_interior, rel);
                // The same difference as slant range in metres, r = z |(u, v, 1)| in the pixel's own view
                // (a tier view's extents are not the slices'), over the pixels the range window records:
                // the depth pass also covers the corners beyond range_max, where the bound below would
                // scale with their range instead.
                const std::uint32_t index = view_of_column(plan, col);
                const math_f64::PixelView view = pixel_view<double>(plan, index);
                const double u = math_f64::pixel_coord(col - view_first_column(plan, index), view_columns(plan, index),
                                                       view.tan_half_h);
                const double v = math_f64::pixel_coord(row, plan.rows, view.tan_half_v);
                const double stretch = std::sqrt(1 + u * u + v * v);
                if (zc * stretch < plan.config.range_max_m)
                    max_abs_range_m = std::max(max_abs_range_m, std::abs(zg - zc) * stretch);
            }
        }
    }
    ASSERT_GT(hits, 0u);
    RecordProperty("depth_mismatched_pixels", static_cast<int>(mismatched));
    std::printf("[depth] %s: %zu of %zu hit pixels differ (edges), max interior view-z rel diff %.2e, max slant "
                "range diff %.2e m\n",
                GetParam().file.c_str(), mismatched, hits, max_rel_interior, max_abs_range_m);
    EXPECT_LE(static_cast<double>(mismatched), kDepthEdgePixelBudget * hits);
    EXPECT_LE(max_abs_range_m, kDepthInteriorRelTol * plan.config.range_max_m);
}

INSTANTIATE_TEST_SUITE_P(BundledScenes, DepthGpuCpu, ::testing::ValuesIn(bundled_scenes()), scene_name);

} // namespace
} // namespace vksonar
