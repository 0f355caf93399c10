// compose_depth_draws: world -> sonar -> slice camera -> clip, composed in double and rounded to
// float once, so a scene 1e5 m from the world origin renders like one at the origin.
#include <algorithm>
#include <array>
#include <cmath>

#include "core/angles.h"
#include "core/mat4.h"
#include "core/plan.h"
#include "scene/scene_data.h"

namespace vksonar {

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
                const std::uint32_t index = scene.indices[cluster.first_index + k];
                cluster.index_min = any ? std::min(cluster.index_min, index) : index;
                cluster.index_max = any ? std::max(cluster.index_max, index) : index;
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

// The planes of the clip volume that clip point (x, y, z, w) lies beyond by more than its tolerance along
// x, y and z, as bits: -x, +x, -y, +y, near (z > w), far (z < 0).
constexpr unsigned kAllPlanes = 0x3fu;
[[gnu::always_inline]] inline unsigned planes_beyond(double x, double y, double z, double w, double tol_x, double tol_y,
                                                     double tol_z) {
    return unsigned(x < -w - tol_x) | unsigned(x > w + tol_x) << 1 | unsigned(y < -w - tol_y) << 2 |
           unsigned(y > w + tol_y) << 3 | unsigned(z > w + tol_z) << 4 | unsigned(z < -tol_z) << 5;
}

// The products of a box's corners through clip_from_local m: term[k][side][r] = m[k * 4 + r] times the
// box's min (side 0) or max (side 1) along axis k, in double (cluster_corner_clip's terms).
[[gnu::always_inline]] inline void box_terms(const float* bounds_min, const float* bounds_max, const float* m,
                                             double (&term)[3][2][4]) {
    for (int k = 0; k < 3; ++k) {
        for (int r = 0; r < 4; ++r) {
            term[k][0][r] = double(m[k * 4 + r]) * double(bounds_min[k]);
            term[k][1][r] = double(m[k * 4 + r]) * double(bounds_max[k]);
        }
    }
}

// Whether the cluster's box, through clip_from_local m, lies clearly outside one plane of the clip
// volume: each of its eight corners as cluster_corner_clip gives it (the same products, summed in the
// same order), every corner outside that plane by more than its own tolerance. The products are made
// once for the eight corners (24 instead of 96) and the corners are the lanes of each loop, which the
// compiler makes vector code. Every corner is tested (cluster_corner_clip's callers may stop at the
// first corner inside every plane: the same answer, as an AND that is 0 stays 0); most of a big
// terrain's clusters lie outside a view, and those test all eight either way.
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
__attribute__((target_clones("avx2", "default")))
#endif
bool box_outside_clip_volume(const DepthCluster& cluster, const float* m) {
    double term[3][2][4];
    box_terms(cluster.bounds_min, cluster.bounds_max, m, term);
    double clip[4][8], magnitude[4][8]; // [row][corner]; corner bit k: max along axis k
    for (int r = 0; r < 4; ++r) {
        const double base = double(m[12 + r]);
        for (int c = 0; c < 8; ++c) {
            const double t0 = term[0][c & 1][r], t1 = term[1][(c >> 1) & 1][r], t2 = term[2][(c >> 2) & 1][r];
            double v = base, a = std::abs(base);
            v += t0;
            a += std::abs(t0);
            v += t1;
            a += std::abs(t1);
            v += t2;
            a += std::abs(t2);
            clip[r][c] = v;
            magnitude[r][c] = a;
        }
    }
    // a plane's bit stays set while every corner is beyond it
    unsigned beyond_every_corner = kAllPlanes;
    for (int c = 0; c < 8; ++c) {
        // The GPU sums these terms in float: its clip coordinates may differ from these by a few ulp of
        // the terms' magnitudes. 1e-5 of them is far beyond that and far below a pixel.
        beyond_every_corner &=
            planes_beyond(clip[0][c], clip[1][c], clip[2][c], clip[3][c], 1e-5 * (magnitude[0][c] + magnitude[3][c]),
                          1e-5 * (magnitude[1][c] + magnitude[3][c]), 1e-5 * (magnitude[2][c] + magnitude[3][c]));
    }
    return beyond_every_corner != 0u;
}

// A box made of several clusters' boxes (their union), through m, clearly outside one plane of the clip
// volume: every corner beyond it by 2e-5 of the largest magnitude any point of the box can have (the
// per-axis larger of |m x min| and |m x max|, summed), where box_outside_clip_volume allows each corner
// 1e-5 of its own. Each member's corners lie in the box, and an affine function's largest value over a
// box is at one of its corners, so each member's corners are beyond the plane by more than their own
// tolerance (rounding adds some 1e-16 of the magnitudes, far inside the factor of 2): every member is
// culled by box_outside_clip_volume too, and the flags are the same as when each is tested.
bool union_clearly_outside_clip_volume(const float* bounds_min, const float* bounds_max, const float* m) {
    double term[3][2][4];
    box_terms(bounds_min, bounds_max, m, term);
    double largest[4]; // per row: |base| + sum over the axes of the larger |term|
    for (int r = 0; r < 4; ++r) {
        largest[r] = std::abs(double(m[12 + r]));
        for (int k = 0; k < 3; ++k)
            largest[r] += std::max(std::abs(term[k][0][r]), std::abs(term[k][1][r]));
    }
    const double tol_x = 2e-5 * (largest[0] + largest[3]);
    const double tol_y = 2e-5 * (largest[1] + largest[3]);
    const double tol_z = 2e-5 * (largest[2] + largest[3]);
    unsigned beyond_every_corner = kAllPlanes;
    for (int c = 0; c < 8; ++c) {
        double clip[4];
        for (int r = 0; r < 4; ++r)
            clip[r] = double(m[12 + r]) + term[0][c & 1][r] + term[1][(c >> 1) & 1][r] + term[2][(c >> 2) & 1][r];
        beyond_every_corner &= planes_beyond(clip[0], clip[1], clip[2], clip[3], tol_x, tol_y, tol_z);
    }
    return beyond_every_corner != 0u;
}

// Consecutive clusters of one draw tested together first (spatially ordered meshes make them
// neighbours: a terrain's run of eight is a patch of 8 x 256 triangles).
constexpr std::size_t kCullGroup = 8;

} // namespace

void cull_depth_clusters_in_slice(const std::vector<DepthCluster>& clusters, std::size_t draws,
                                  const std::vector<shared::DepthPush>& pushes, std::size_t slice,
                                  std::uint8_t* drawn_row) {
    // A big terrain's clusters mostly lie outside a view: a group of them clearly outside is culled with
    // one test of their union's box (union_clearly_outside_clip_volume: the same flags as testing each).
    for (std::size_t c = 0; c < clusters.size();) {
        const std::uint32_t draw = clusters[c].draw;
        const float* m = pushes[slice * draws + draw].clip_from_local;
        std::size_t end = c + 1;
        while (end < clusters.size() && end - c < kCullGroup && clusters[end].draw == draw)
            ++end;
        if (end - c > 1) {
            float lo[3], hi[3];
            for (int k = 0; k < 3; ++k) {
                lo[k] = clusters[c].bounds_min[k];
                hi[k] = clusters[c].bounds_max[k];
                for (std::size_t i = c + 1; i < end; ++i) {
                    lo[k] = std::min(lo[k], clusters[i].bounds_min[k]);
                    hi[k] = std::max(hi[k], clusters[i].bounds_max[k]);
                }
            }
            if (union_clearly_outside_clip_volume(lo, hi, m)) {
                std::fill(drawn_row + c, drawn_row + end, std::uint8_t(0));
                c = end;
                continue;
            }
        }
        for (; c < end; ++c)
            drawn_row[c] = !box_outside_clip_volume(clusters[c], m);
    }
}

void cull_depth_clusters(const std::vector<DepthCluster>& clusters, std::size_t draws,
                         const std::vector<shared::DepthPush>& pushes, std::vector<std::uint8_t>& drawn) {
    const std::size_t slices = draws ? pushes.size() / draws : 0;
    drawn.resize(slices * clusters.size());
    for (std::size_t s = 0; s < slices; ++s)
        cull_depth_clusters_in_slice(clusters, draws, pushes, s, drawn.data() + s * clusters.size());
}

} // namespace vksonar
