// Tests of the depth pass's culling by clusters (build_depth_clusters, cull_depth_clusters,
// docs/pipeline.md §1): what is skipped, and that a culled frame equals the unculled one bit for bit.
// Every tolerance is justified next to it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
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

} // namespace
} // namespace vksonar
