// compose_depth_draws: world -> sonar -> slice camera -> clip, composed in double and rounded to
// float once, so a scene 1e5 m from the world origin renders like one at the origin.
#include <algorithm>
#include <array>
#include <cmath>

#include "core/angles.h"
#include "core/plan.h"
#include "scene/scene_data.h"

namespace vksonar {

// Column-major 4x4 in double.
using Mat4 = std::array<double, 16>;

Mat4 multiply(const Mat4& a, const Mat4& b) {
    Mat4 r{};
    for (int col = 0; col < 4; ++col) {
        for (int row = 0; row < 4; ++row) {
            double s = 0;
            for (int k = 0; k < 4; ++k)
                s += a[k * 4 + row] * b[col * 4 + k];
            r[col * 4 + row] = s;
        }
    }
    return r;
}

// sonar_from_world = inverse of [R | t] with R = Rz(yaw) Ry(pitch) Rx(roll).
Mat4 sonar_from_world(const Pose& pose) {
    const double cr = std::cos(pose.roll_deg * kDegToRad), sr = std::sin(pose.roll_deg * kDegToRad);
    const double cp = std::cos(pose.pitch_deg * kDegToRad), sp = std::sin(pose.pitch_deg * kDegToRad);
    const double cy = std::cos(pose.yaw_deg * kDegToRad), sy = std::sin(pose.yaw_deg * kDegToRad);
    // R (row-major, world_from_sonar)
    const double R[3][3] = {{cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr},
                            {sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr},
                            {-sp, cp * sr, cp * cr}};
    const double t[3] = {pose.x_m, pose.y_m, pose.z_m};
    Mat4 m{};
    for (int row = 0; row < 3; ++row) {
        double tr = 0;
        for (int col = 0; col < 3; ++col) {
            m[col * 4 + row] = R[col][row]; // transpose
            tr += R[col][row] * t[col];
        }
        m[12 + row] = -tr;
    }
    m[15] = 1.0;
    return m;
}

namespace {

// clip_from_sonar for one view: camera axes (right, down, forward) then the reversed-Z projection
// clip = (x / tan_half_h, y / tan_half_v, A + B z, z) so that z_ndc = A / z + B.
Mat4 clip_from_sonar(const Plan& plan, std::uint32_t view) {
    const ViewGeometry& g = plan.view_geometry[view];
    Mat4 m{};
    for (int k = 0; k < 3; ++k) {
        m[k * 4 + 0] = g.right[k] / g.tan_half_h;
        m[k * 4 + 1] = g.down[k] / g.tan_half_v;
        m[k * 4 + 2] = plan.depth_b * g.forward[k];
        m[k * 4 + 3] = g.forward[k];
    }
    m[12 + 2] = plan.depth_a;
    return m;
}

} // namespace

void compose_depth_draws(const Plan& plan, const SceneData& scene, const Pose& pose,
                         std::vector<shared::DepthPush>& out) {
    const std::size_t draws = scene.draws.size();
    out.resize(plan.views * draws);
    const Mat4 sonar_world = sonar_from_world(pose);
    for (std::size_t i = 0; i < draws; ++i) {
        const SceneDraw& d = scene.draws[i];
        const Mat4 sonar_local = multiply(sonar_world, d.world_from_local);
        for (std::uint32_t s = 0; s < plan.views; ++s) {
            const Mat4 clip_local = multiply(clip_from_sonar(plan, s), sonar_local);
            shared::DepthPush& push = out[s * draws + i];
            for (int k = 0; k < 16; ++k)
                push.clip_from_local[k] = static_cast<float>(clip_local[k]);
            // With labels the instance rides above the material (Renderer::create has checked both fit).
            push.material_id = plan.labels ? d.material | d.instance << shared::kInstanceShift : d.material;
            push.pad0 = push.pad1 = push.pad2 = 0;
        }
    }
}

void build_depth_clusters(const SceneData& scene, std::vector<DepthCluster>& out) {
    out.clear();
    const std::size_t vertex_limit = scene.positions.size() / 3;
    for (std::size_t i = 0; i < scene.draws.size(); ++i) {
        const std::uint32_t mesh_index = scene.draws[i].mesh;
        if (mesh_index >= scene.meshes.size()) continue;
        const MeshRange& mesh = scene.meshes[mesh_index];
        const std::uint32_t index_count = mesh.index_count - mesh.index_count % 3;
        if (std::size_t(mesh.first_index) + index_count > scene.indices.size()) continue;
        for (std::uint32_t begin = 0; begin < index_count; begin += 3 * kClusterTriangles) {
            DepthCluster cluster;
            cluster.draw = static_cast<std::uint32_t>(i);
            cluster.first_index = mesh.first_index + begin;
            cluster.index_count = std::min(3 * kClusterTriangles, index_count - begin);
            cluster.first_vertex = mesh.first_vertex;
            bool any = false, valid = true;
            for (std::uint32_t k = 0; k < cluster.index_count; ++k) {
                const std::size_t v = std::size_t(mesh.first_vertex) + scene.indices[cluster.first_index + k];
                if (v >= vertex_limit) {
                    valid = false;
                    break;
                }
                for (int a = 0; a < 3; ++a) {
                    const float x = scene.positions[3 * v + std::size_t(a)];
                    cluster.bounds_min[a] = any ? std::min(cluster.bounds_min[a], x) : x;
                    cluster.bounds_max[a] = any ? std::max(cluster.bounds_max[a], x) : x;
                }
                any = true;
            }
            if (valid && any) out.push_back(cluster);
        }
    }
}

void cluster_corner_clip(const DepthCluster& cluster, const float* m, int corner, double clip[4], double magnitude[4]) {
    const double p[3] = {corner & 1 ? cluster.bounds_max[0] : cluster.bounds_min[0],
                         corner & 2 ? cluster.bounds_max[1] : cluster.bounds_min[1],
                         corner & 4 ? cluster.bounds_max[2] : cluster.bounds_min[2]};
    for (int r = 0; r < 4; ++r) {
        clip[r] = double(m[12 + r]);
        magnitude[r] = std::abs(clip[r]);
        for (int k = 0; k < 3; ++k) {
            const double term = double(m[k * 4 + r]) * p[k];
            clip[r] += term;
            magnitude[r] += std::abs(term);
        }
    }
}

namespace {

// cluster_corner_clip's products, made once for the eight corners: term[k][side][r] is
// m[k * 4 + r] times the box's min (side 0) or max (side 1) along axis k. corner_clip then sums them
// as cluster_corner_clip does, in the same order: the same values, with 24 products instead of 96 for
// a cluster whose corners are all tested (most of a big terrain, culled).
struct ClusterTerms {
    double base[4];
    double term[3][2][4];
};

ClusterTerms cluster_terms(const DepthCluster& cluster, const float* m) {
    ClusterTerms t;
    for (int r = 0; r < 4; ++r) {
        t.base[r] = double(m[12 + r]);
        for (int k = 0; k < 3; ++k) {
            t.term[k][0][r] = double(m[k * 4 + r]) * double(cluster.bounds_min[k]);
            t.term[k][1][r] = double(m[k * 4 + r]) * double(cluster.bounds_max[k]);
        }
    }
    return t;
}

void corner_clip(const ClusterTerms& t, int corner, double clip[4], double magnitude[4]) {
    for (int r = 0; r < 4; ++r) {
        clip[r] = t.base[r];
        magnitude[r] = std::abs(clip[r]);
        for (int k = 0; k < 3; ++k) {
            const double term = t.term[k][(corner >> k) & 1][r];
            clip[r] += term;
            magnitude[r] += std::abs(term);
        }
    }
}

} // namespace

void cull_depth_clusters(const std::vector<DepthCluster>& clusters, std::size_t draws,
                         const std::vector<shared::DepthPush>& pushes, std::vector<std::uint8_t>& drawn) {
    const std::size_t slices = draws ? pushes.size() / draws : 0;
    drawn.resize(slices * clusters.size());
    for (std::size_t s = 0; s < slices; ++s) {
        for (std::size_t c = 0; c < clusters.size(); ++c) {
            const DepthCluster& cluster = clusters[c];
            const ClusterTerms terms = cluster_terms(cluster, pushes[s * draws + cluster.draw].clip_from_local);
            unsigned outside_every_corner = 0x3fu; // planes: -x, +x, -y, +y, near (z > w), far (z < 0)
            for (int corner = 0; corner < 8 && outside_every_corner; ++corner) {
                double clip[4], magnitude[4];
                corner_clip(terms, corner, clip, magnitude);
                // The GPU sums these terms in float: its clip coordinates may differ from these by a few
                // ulp of the terms' magnitudes. 1e-5 of them is far beyond that and far below a pixel.
                const double tol_x = 1e-5 * (magnitude[0] + magnitude[3]);
                const double tol_y = 1e-5 * (magnitude[1] + magnitude[3]);
                const double tol_z = 1e-5 * (magnitude[2] + magnitude[3]);
                unsigned outside = 0;
                if (clip[0] < -clip[3] - tol_x) outside |= 0x01u;
                if (clip[0] > clip[3] + tol_x) outside |= 0x02u;
                if (clip[1] < -clip[3] - tol_y) outside |= 0x04u;
                if (clip[1] > clip[3] + tol_y) outside |= 0x08u;
                if (clip[2] > clip[3] + tol_z) outside |= 0x10u;
                if (clip[2] < -tol_z) outside |= 0x20u;
                outside_every_corner &= outside;
            }
            drawn[s * clusters.size() + c] = outside_every_corner == 0u;
        }
    }
}

} // namespace vksonar
