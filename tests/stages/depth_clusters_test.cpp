// Tests of the depth pass's culling by clusters (build_depth_clusters, cull_depth_clusters,
// docs/pipeline.md §1): what is skipped, and that a culled frame equals the unculled one bit for bit.
// Every tolerance is justified next to it.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "cpu_stage_support.h"

namespace vksonar {
namespace {

using namespace stage_testing;

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
    EXPECT_EQ(drawn.size(), std::size_t(plan.views) * clusters.size());
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

// An n x n-quad heightfield over a size x size m square centred on the origin, its quads in rows (two
// triangles each), height(x, y) at each vertex; returns the mesh.
template <class Height> std::uint32_t grid_mesh(SceneBuilder& b, std::uint32_t n, float size, const Height& height) {
    std::vector<float> positions;
    std::vector<std::uint32_t> indices;
    for (std::uint32_t j = 0; j <= n; ++j)
        for (std::uint32_t i = 0; i <= n; ++i) {
            const float x = -0.5f * size + size * float(i) / float(n), y = -0.5f * size + size * float(j) / float(n);
            positions.insert(positions.end(), {x, y, height(x, y)});
        }
    for (std::uint32_t j = 0; j < n; ++j)
        for (std::uint32_t i = 0; i < n; ++i) {
            const std::uint32_t a = j * (n + 1) + i;
            indices.insert(indices.end(), {a, a + 1, a + n + 2, a, a + n + 2, a + n + 1});
        }
    return b.mesh(positions, indices);
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
        // triangle t indexes 3t, 3t + 1 and 3t + 2 (mesh-local)
        EXPECT_EQ(run.index_min, 3 * r * kClusterTriangles);
        EXPECT_EQ(run.index_max, 3 * std::min(triangles, (r + 1) * kClusterTriangles) - 1);
    }
    EXPECT_EQ(clusters[0].index_min, 0u); // the box's 8 corners
    EXPECT_EQ(clusters[0].index_max, 7u);
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

// Meshes get their triangles in spatial (Morton) order when a scene is built (order_triangles_spatially,
// scene_data.h), so that the depth pass's runs are compact patches instead of an exporter's rows across
// the whole terrain. The order changes nothing else: the same triangles with the same winding, the
// same depth and material images bit for bit, while a slice draws far fewer runs.
TEST(DepthClusters, SpatialOrderKeepsTheTrianglesAndTheFrameAndCullsMore) {
    SonarConfig config = small_config();
    config.hfov_deg = 130.0;
    SceneBuilder b;
    b.material(-20.0);
    // A 120 x 120 m terrain 3 m below the sonar: 256 x 256 quads in rows, 131072 triangles, gently rolling.
    b.draw(grid_mesh(b, 256, 120.0f,
                     [](float x, float y) { return -3.0f + 0.3f * std::sin(0.2f * x) * std::cos(0.13f * y); }),
           0);
    const SceneData& rows = b.scene;
    SceneData spatial = b.scene;
    order_triangles_spatially(spatial, spatial.meshes[0]);

    // The same triangles, each with its winding: as position triples rotated so the smallest vertex
    // leads (the spatial order also gives each run its own copy of its vertices, so indices change).
    auto canonical = [](const SceneData& scene) {
        using Vertex = std::array<float, 3>;
        std::vector<std::array<Vertex, 3>> tris;
        const MeshRange& m = scene.meshes[0];
        for (std::size_t t = 0; t < m.index_count / 3; ++t) {
            std::array<Vertex, 3> tri;
            for (std::size_t k = 0; k < 3; ++k) {
                const std::size_t v = m.first_vertex + scene.indices[m.first_index + 3 * t + k];
                tri[k] = {scene.positions[3 * v], scene.positions[3 * v + 1], scene.positions[3 * v + 2]};
            }
            std::rotate(tri.begin(), std::min_element(tri.begin(), tri.end()), tri.end());
            tris.push_back(tri);
        }
        std::sort(tris.begin(), tris.end());
        return tris;
    };
    ASSERT_NE(spatial.indices, rows.indices) << "the order must change";
    EXPECT_EQ(canonical(spatial), canonical(rows));
    // Each run's indices span only its own vertices: here a 16 x 16-quad patch, 289 (measured), where a
    // run of the row order spans two grid rows, 514; the copies of the patches' borders cost 12 %.
    auto widest_span = [](const SceneData& scene) {
        std::vector<DepthCluster> runs;
        build_depth_clusters(scene, runs);
        std::uint32_t widest = 0;
        for (const DepthCluster& run : runs) {
            const auto first = scene.indices.begin() + run.first_index;
            const auto [lo, hi] = std::minmax_element(first, first + run.index_count);
            widest = std::max(widest, *hi - *lo + 1);
        }
        return widest;
    };
    const std::uint32_t row_span = widest_span(rows), spatial_span = widest_span(spatial);
    std::printf("[spatial order] widest run spans %u vertices (row order %u); %zu vertices (row order %zu)\n",
                spatial_span, row_span, spatial.positions.size() / 3, rows.positions.size() / 3);
    EXPECT_LT(spatial_span, 0.6 * row_span);
    EXPECT_LT(spatial.positions.size(), 1.2 * rows.positions.size());
    EXPECT_LT(spatial.positions.size(), 1.25 * rows.positions.size()); // the runs' shared borders
    const Plan plan = plan_for(config, rows);
    for (const double yaw : {0.0, 30.0, 135.0}) {
        Pose pose;
        pose.pitch_deg = 10.0;
        pose.yaw_deg = yaw;
        std::vector<DepthCluster> row_clusters, spatial_clusters;
        const std::vector<std::uint8_t> row_drawn = culled_and_checked(plan, rows, pose, row_clusters);
        const std::vector<std::uint8_t> spatial_drawn = culled_and_checked(plan, spatial, pose, spatial_clusters);
        ASSERT_EQ(row_clusters.size(), spatial_clusters.size());
        // the same frame from either order (no two triangles of the terrain overlap)
        std::vector<shared::DepthPush> pushes;
        compose_depth_draws(plan, rows, pose, pushes);
        const std::size_t pixels = std::size_t(plan.rows) * plan.columns;
        std::vector<float> depth_rows(pixels), depth_spatial(pixels);
        std::vector<std::uint32_t> material_rows(pixels), material_spatial(pixels);
        cpu::depth_pass(plan, rows, pushes, depth_rows.data(), material_rows.data());
        cpu::depth_pass(plan, spatial, pushes, depth_spatial.data(), material_spatial.data());
        EXPECT_EQ(depth_rows, depth_spatial) << "yaw " << yaw;
        EXPECT_EQ(material_rows, material_spatial) << "yaw " << yaw;
        const auto count = [](const std::vector<std::uint8_t>& d) { return std::count(d.begin(), d.end(), 1); };
        const double row_share = double(count(row_drawn)) / double(row_drawn.size());
        const double spatial_share = double(count(spatial_drawn)) / double(spatial_drawn.size());
        std::printf("[spatial order] yaw %5.1f: run-slices drawn, rows %.3f, spatial %.3f\n", yaw, row_share,
                    spatial_share);
        // measured 0.086-0.089 against 0.50-0.60 (a run of the row order is a strip across the terrain
        // that most slices' frusta cross; a run of the spatial order is a 7.5 m patch)
        EXPECT_LT(spatial_share, 0.3 * row_share) << "yaw " << yaw;

        // The calls the Vulkan backend records (for_each_depth_draw_call): the drawn clusters' triangles,
        // every one and in order, in fewer calls where neighbouring clusters are drawn together.
        std::size_t calls = 0, clusters_drawn = 0;
        for (std::uint32_t view = 0; view < plan.views; ++view) {
            const std::uint8_t* drawn = spatial_drawn.data() + std::size_t(view) * spatial_clusters.size();
            std::vector<std::uint32_t> by_cluster, by_call; // the first index of each triangle drawn
            for (std::size_t c = 0; c < spatial_clusters.size(); ++c) {
                if (!drawn[c]) continue;
                ++clusters_drawn;
                for (std::uint32_t i = 0; i < spatial_clusters[c].index_count; i += 3)
                    by_cluster.push_back(spatial_clusters[c].first_index + i);
            }
            for_each_depth_draw_call(spatial_clusters, drawn, [&](const DepthDrawCall& call) {
                ++calls;
                EXPECT_TRUE(drawn[call.cluster]);
                EXPECT_EQ(call.first_index, spatial_clusters[call.cluster].first_index);
                EXPECT_EQ(call.first_vertex, spatial_clusters[call.cluster].first_vertex);
                for (std::uint32_t i = 0; i < call.index_count; i += 3)
                    by_call.push_back(call.first_index + i);
            });
            EXPECT_EQ(by_call, by_cluster) << "yaw " << yaw << ", view " << view;
        }
        std::printf("[spatial order] yaw %5.1f: %zu clusters drawn in %zu calls\n", yaw, clusters_drawn, calls);
        EXPECT_GT(clusters_drawn, 0u);
        EXPECT_LT(calls, clusters_drawn);
    }
}

// cull_depth_clusters tests groups of neighbouring clusters by their union first and culls a group
// clearly outside a view at once: the flags must be exactly those of testing every cluster by the
// definition (each corner of its box through the draw's float matrix, in double; culled where every
// corner lies beyond one plane by more than 1e-5 of its terms' magnitudes), written out here on its own.
// A terrain in spatial order seen from twelve poses that put the frustum's planes through its groups,
// and a line of slivers 39 degrees to port (another draw).
TEST(DepthClusters, GroupCullingGivesTheFlagsOfEachClusterAlone) {
    SceneBuilder b;
    b.material(-20.0);
    b.draw(grid_mesh(b, 200, 100.0f, [](float x, float y) { return -3.0f + 0.4f * std::sin(0.17f * x + 0.1f * y); }),
           0);
    order_triangles_spatially(b.scene, b.scene.meshes[0]);
    std::vector<float> boxes;
    std::vector<std::uint32_t> box_indices;
    for (std::uint32_t t = 0; t < 40 * kClusterTriangles; ++t) { // 40 clusters of slivers along y = 0.8 x
        const float x = 0.05f * float(t % 2000), z = -1.0f + 0.001f * float(t / 2000);
        const auto first = std::uint32_t(boxes.size() / 3);
        boxes.insert(boxes.end(), {x, 0.8f * x, z, x + 0.05f, 0.8f * x, z, x, 0.8f * x + 0.01f, z + 0.01f});
        box_indices.insert(box_indices.end(), {first, first + 1, first + 2});
    }
    b.draw(b.mesh(boxes, box_indices), 0);
    SonarConfig config = small_config();
    config.hfov_deg = 130.0;
    const Plan plan = plan_for(config, b.scene);
    std::vector<DepthCluster> clusters;
    build_depth_clusters(b.scene, clusters);
    ASSERT_GT(clusters.size(), 150u); // 157 of the terrain, 40 of the slivers
    std::size_t culled = 0, total = 0;
    for (int pose_index = 0; pose_index < 12; ++pose_index) {
        Pose pose;
        pose.z_m = 0.5 * pose_index;
        pose.pitch_deg = 3.0 * pose_index;
        pose.yaw_deg = 31.0 * pose_index;
        std::vector<shared::DepthPush> pushes;
        std::vector<std::uint8_t> drawn;
        compose_depth_draws(plan, b.scene, pose, pushes);
        cull_depth_clusters(clusters, b.scene.draws.size(), pushes, drawn);
        ASSERT_EQ(drawn.size(), std::size_t(plan.views) * clusters.size());
        for (std::uint32_t s = 0; s < plan.views; ++s) {
            for (std::size_t c = 0; c < clusters.size(); ++c) {
                const DepthCluster& cluster = clusters[c];
                const float* m = pushes[s * b.scene.draws.size() + cluster.draw].clip_from_local;
                bool beyond[6] = {true, true, true, true, true, true};
                for (int corner = 0; corner < 8; ++corner) {
                    const double p[3] = {corner & 1 ? cluster.bounds_max[0] : cluster.bounds_min[0],
                                         corner & 2 ? cluster.bounds_max[1] : cluster.bounds_min[1],
                                         corner & 4 ? cluster.bounds_max[2] : cluster.bounds_min[2]};
                    double clip[4], size[4];
                    for (int r = 0; r < 4; ++r) {
                        clip[r] = double(m[12 + r]);
                        size[r] = std::abs(clip[r]);
                        for (int k = 0; k < 3; ++k) {
                            clip[r] += double(m[k * 4 + r]) * p[k];
                            size[r] += std::abs(double(m[k * 4 + r]) * p[k]);
                        }
                    }
                    const double tx = 1e-5 * (size[0] + size[3]), ty = 1e-5 * (size[1] + size[3]);
                    const double tz = 1e-5 * (size[2] + size[3]);
                    beyond[0] = beyond[0] && clip[0] < -clip[3] - tx;
                    beyond[1] = beyond[1] && clip[0] > clip[3] + tx;
                    beyond[2] = beyond[2] && clip[1] < -clip[3] - ty;
                    beyond[3] = beyond[3] && clip[1] > clip[3] + ty;
                    beyond[4] = beyond[4] && clip[2] > clip[3] + tz;
                    beyond[5] = beyond[5] && clip[2] < -tz;
                }
                const bool expected_culled = std::find(beyond, beyond + 6, true) != beyond + 6;
                ASSERT_EQ(drawn[s * clusters.size() + c], expected_culled ? 0 : 1)
                    << "pose " << pose_index << ", view " << s << ", cluster " << c;
                culled += expected_culled;
                ++total;
            }
        }
    }
    std::printf("[group culling] %zu of %zu cluster-views culled\n", culled, total);
    EXPECT_GT(culled, total / 4);
    EXPECT_LT(culled, total);
}

// for_each_depth_draw_call merges a run of drawn clusters only where one draw call can draw it: the
// same draw (its push constants), the same vertex offset, and each cluster's indices following the last.
TEST(DepthClusters, DrawCallsMergeOnlyClustersOneCallCanDraw) {
    auto cluster = [](std::uint32_t draw, std::uint32_t first_index, std::uint32_t count, std::uint32_t vertex) {
        DepthCluster c;
        c.draw = draw;
        c.first_index = first_index;
        c.index_count = count;
        c.first_vertex = vertex;
        return c;
    };
    const std::vector<DepthCluster> clusters = {
        cluster(0, 0, 30, 0),   // 0: a call of 0-2
        cluster(0, 30, 30, 0),  // 1
        cluster(0, 60, 9, 0),   // 2
        cluster(1, 69, 30, 0),  // 3: another draw, though its indices follow
        cluster(1, 99, 30, 7),  // 4: another vertex offset
        cluster(1, 129, 30, 7), // 5: merged with 4
        cluster(1, 300, 30, 7), // 6: a gap in the indices
        cluster(1, 330, 30, 7), // 7: culled
        cluster(1, 360, 30, 7), // 8: after a culled cluster
        cluster(2, 390, 3, 7),  // 9: culled, last
    };
    const std::vector<std::uint8_t> drawn = {1, 1, 1, 1, 1, 1, 1, 0, 1, 0};
    std::vector<std::array<std::uint32_t, 4>> calls;
    for_each_depth_draw_call(clusters, drawn.data(), [&](const DepthDrawCall& call) {
        calls.push_back({call.cluster, call.first_index, call.index_count, call.first_vertex});
    });
    const std::vector<std::array<std::uint32_t, 4>> expected = {
        {0, 0, 69, 0}, {3, 69, 30, 0}, {4, 99, 60, 7}, {6, 300, 30, 7}, {8, 360, 30, 7}};
    EXPECT_EQ(calls, expected);
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
            const Plan plan = plan_for(config, scene_data(scene.value()));
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
                    culled_and_checked(plan, scene_data(scene.value()), pose, clusters, &hits);
                poses_with_hits += hits > 0;
                skipped += std::size_t(std::count(drawn.begin(), drawn.end(), std::uint8_t(0)));
                pairs += drawn.size();
            }
        }
    }
    EXPECT_GT(poses_with_hits, 24u); // most of the 48 poses see something
    EXPECT_GT(skipped, pairs / 4);   // and the culling had work to do
}

} // namespace
} // namespace vksonar
