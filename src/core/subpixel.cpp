// Sub-pixel objects: which clusters skip the raster at a pose, and their triangles' returns
// (src/core/subpixel.h; the math: docs/pipeline.md "Sub-pixel objects").
#include "core/subpixel.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>

#include "core/angles.h"
#include "core/mat4.h"
#include "core/pixel_views.h"
#include "core/plan.h"
#include "core/sonar_math.hpp"
#include "scene/scene_data.h"

namespace vksonar {
namespace {

using Vec3 = std::array<double, 3>;
using M = Math<double>;

// A triangle is split into n x n pieces (n^2 similar triangles) so that no piece is longer than a
// pixel (the smaller side): n = ceil(longest edge / (nearest distance x pixel)), at most kMaxSplit (past
// it a piece is longer than a pixel, its energy still whole: a coarse mesh's triangle 8 pixels long).
constexpr std::uint32_t kMaxSplit = 8;

// The split of a triangle with longest edge `longest` whose nearest point may be as near as `near`.
std::uint32_t split_of(double longest, double near, double pixel) {
    if (!(near > 0)) return kMaxSplit;
    return static_cast<std::uint32_t>(std::clamp(std::ceil(longest / (near * pixel)), 1.0, double(kMaxSplit)));
}

Vec3 transform_point(const std::array<double, 16>& m, const Vec3& p) {
    Vec3 r{};
    for (int row = 0; row < 3; ++row)
        r[row] = m[12 + row] + m[row] * p[0] + m[4 + row] * p[1] + m[8 + row] * p[2];
    return r;
}

Vec3 sub(const Vec3& a, const Vec3& b) {
    return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}
double dot(const Vec3& a, const Vec3& b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
Vec3 cross(const Vec3& a, const Vec3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double norm(const Vec3& a) {
    return std::sqrt(dot(a, a));
}

// A cluster's size in the world: the centre of its box, the radius of the sphere about it that holds
// its vertices, and the middle one of its box's three extents (the box's axes through world_from_local):
// a cable's box is long along one axis and a diameter across the other two.
struct ClusterSize {
    Vec3 centre;
    double radius = 0, middle_extent = 0;
};

// The extents of the box [lo, hi] along its axes through m, sorted.
std::array<double, 3> box_extents(const std::array<double, 16>& m, const double* lo, const double* hi) {
    std::array<double, 3> extent{};
    for (int a = 0; a < 3; ++a) {
        const double axis = std::sqrt(m[4 * a] * m[4 * a] + m[4 * a + 1] * m[4 * a + 1] + m[4 * a + 2] * m[4 * a + 2]);
        extent[a] = axis * (hi[a] - lo[a]);
    }
    std::sort(extent.begin(), extent.end());
    return extent;
}

// The radius about `centre` that holds the vertices of clusters [begin, end) through m.
double vertex_radius(const SceneData& scene, const std::vector<DepthCluster>& clusters, std::uint32_t begin,
                     std::uint32_t end, const std::array<double, 16>& m, const Vec3& centre) {
    double radius = 0;
    for (std::uint32_t c = begin; c < end; ++c)
        for (std::uint32_t k = 0; k < clusters[c].index_count; ++k) {
            const std::size_t v = std::size_t(clusters[c].first_vertex) + scene.indices[clusters[c].first_index + k];
            const Vec3 p =
                transform_point(m, {scene.positions[3 * v], scene.positions[3 * v + 1], scene.positions[3 * v + 2]});
            radius = std::max(radius, norm(sub(p, centre)));
        }
    return radius;
}

// The size of clusters [begin, end) (one draw's) together. The box is tight on the vertices, so half
// its largest extent is a lower bound on the radius: where that already reaches `enough`, the vertices
// are not walked and the radius is that bound (a large seabed costs no pass over its vertices).
ClusterSize size_of(const SceneData& scene, const std::vector<DepthCluster>& clusters, std::uint32_t begin,
                    std::uint32_t end, double enough) {
    const std::array<double, 16>& m = scene.draws[clusters[begin].draw].world_from_local;
    double lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
        lo[a] = clusters[begin].bounds_min[a];
        hi[a] = clusters[begin].bounds_max[a];
    }
    for (std::uint32_t c = begin; c < end; ++c)
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], double(clusters[c].bounds_min[a]));
            hi[a] = std::max(hi[a], double(clusters[c].bounds_max[a]));
        }
    const std::array<double, 3> extent = box_extents(m, lo, hi);
    ClusterSize size;
    size.centre = transform_point(m, {0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])});
    size.middle_extent = extent[1];
    size.radius = 0.5 * extent[2];
    if (size.radius < enough) size.radius = vertex_radius(scene, clusters, begin, end, m, size.centre);
    return size;
}

// Which way a mesh's triangles face, if it has an outside: +1 counter-clockwise out, -1 in, 0 none (an
// open sheet: the sonar sees both of its sides). It has one when its triangles are consistently wound
// (every edge, by its ends' positions, shared by at most two triangles, once each way) and closed, or
// closed but for holes that are small against its area (an open tube's ends: the isoperimetric bound
// of its boundary's length, L^2 / 4 pi, under 1 % of its area). The side is the sign of its signed
// volume about its box's centre: the volume of the mesh closed by cones from the centre to its holes,
// which take at most the holes' area times the mesh's radius / 3 from it (an open tube loses a third):
// where they could take more the mesh counts as open.
// Positions, not indices: the loader gives each run of a mesh its own copies of the vertices
// (order_triangles_spatially), and a generated mesh may repeat a pole's vertex per segment. Positions
// are compared on a grid of 1e-6 of the mesh's size, so that copies that differ by rounding (sin(pi) is
// not 0) still meet.
std::int32_t mesh_facing(const SceneData& scene, const MeshRange& mesh) {
    const std::uint32_t triangles = mesh.index_count / 3;
    const std::size_t vertex_limit = scene.positions.size() / 3;
    auto position = [&](std::uint32_t t, int i, Vec3& p) {
        const std::size_t v = std::size_t(mesh.first_vertex) + scene.indices[mesh.first_index + 3 * t + i];
        if (v >= vertex_limit) return false;
        p = {scene.positions[3 * v], scene.positions[3 * v + 1], scene.positions[3 * v + 2]};
        return true;
    };
    double size = 0;
    Vec3 lo{}, hi{};
    for (std::uint32_t t = 0; t < triangles; ++t)
        for (int i = 0; i < 3; ++i) {
            Vec3 p;
            if (!position(t, i, p)) return 0;
            size = std::max({size, std::abs(p[0]), std::abs(p[1]), std::abs(p[2])});
            for (int a = 0; a < 3; ++a) {
                lo[a] = t == 0 && i == 0 ? p[a] : std::min(lo[a], p[a]);
                hi[a] = t == 0 && i == 0 ? p[a] : std::max(hi[a], p[a]);
            }
        }
    if (!(size > 0)) return 0;
    const Vec3 centre{0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])};
    const double radius = 0.5 * norm(sub(hi, lo));
    const double quantum = 1e-6 * size;
    using Key = std::array<std::int64_t, 3>;
    auto key = [&](const Vec3& p) {
        return Key{std::llround(p[0] / quantum), std::llround(p[1] / quantum), std::llround(p[2] / quantum)};
    };
    struct Edge {
        Key lo, hi;
        int direction;
        double length;
    };
    std::vector<Edge> edges;
    edges.reserve(std::size_t(triangles) * 3);
    double volume6 = 0, area = 0; // six times the signed volume
    for (std::uint32_t t = 0; t < triangles; ++t) {
        Vec3 p[3] = {}; // every position was checked above
        for (int i = 0; i < 3; ++i) {
            position(t, i, p[i]);
            p[i] = sub(p[i], centre);
        }
        const Vec3 n = cross(p[1], p[2]);
        volume6 += dot(p[0], n);
        area += 0.5 * norm(cross(sub(p[1], p[0]), sub(p[2], p[0])));
        Key corner[3];
        for (int i = 0; i < 3; ++i)
            corner[i] = key({p[i][0] + centre[0], p[i][1] + centre[1], p[i][2] + centre[2]});
        // A collapsed triangle (two corners at one vertex: a UV sphere's pole row written as quads) joins
        // nothing: its one real edge P-Q, once each way, would make the edge its neighbours share a
        // four-sided one, and the closed mesh an open sheet seen from both sides (+3 dB).
        if (corner[0] == corner[1] || corner[1] == corner[2] || corner[2] == corner[0]) continue;
        for (int i = 0; i < 3; ++i) {
            const Key& from = corner[i];
            const Key& to = corner[(i + 1) % 3];
            const double length = norm(sub(p[(i + 1) % 3], p[i]));
            edges.push_back(from < to ? Edge{from, to, 1, length} : Edge{to, from, -1, length});
        }
    }
    std::sort(edges.begin(), edges.end(),
              [](const Edge& x, const Edge& y) { return x.lo < y.lo || (x.lo == y.lo && x.hi < y.hi); });
    auto same = [](const Edge& x, const Edge& y) { return x.lo == y.lo && x.hi == y.hi; };
    // The edges only one triangle has, in the direction it has them: the holes' rims.
    std::vector<Edge> rim;
    for (std::size_t i = 0; i < edges.size();) {
        std::size_t n = 1;
        while (i + n < edges.size() && same(edges[i], edges[i + n]))
            ++n;
        if (n > 2 || (n == 2 && edges[i].direction + edges[i + 1].direction != 0)) return 0;
        if (n == 1)
            rim.push_back(edges[i].direction > 0 ? edges[i] : Edge{edges[i].hi, edges[i].lo, 1, edges[i].length});
        i += n;
    }
    // Each hole's rim walked round from edge to edge (a rim vertex with two ways on is no hole's: then
    // the whole rim counts as one): the most area it can enclose, perimeter^2 / 4 pi.
    std::sort(rim.begin(), rim.end(), [](const Edge& x, const Edge& y) { return x.lo < y.lo; });
    std::vector<std::uint8_t> walked(rim.size(), 0);
    double holes = 0, whole = 0;
    bool loops = true;
    for (std::size_t i = 0; i < rim.size(); ++i) {
        whole += rim[i].length;
        if (i + 1 < rim.size() && rim[i + 1].lo == rim[i].lo) loops = false;
    }
    for (std::size_t start = 0; start < rim.size() && loops; ++start) {
        if (walked[start]) continue;
        double perimeter = 0;
        std::size_t e = start;
        while (!walked[e]) {
            walked[e] = 1;
            perimeter += rim[e].length;
            const auto next = std::lower_bound(rim.begin(), rim.end(), rim[e].hi,
                                               [](const Edge& x, const Key& k) { return x.lo < k; });
            if (next == rim.end() || next->lo != rim[e].hi) {
                loops = false; // a rim that does not close
                break;
            }
            e = static_cast<std::size_t>(next - rim.begin());
        }
        holes += perimeter * perimeter / (4 * kPi);
    }
    if (!loops) holes = whole * whole / (4 * kPi);
    if (holes > 0.01 * area || !(std::abs(volume6) > 2 * holes * radius)) return 0; // 6 x (1/3) A r
    return volume6 > 0 ? 1 : -1;
}

// The pixel's sides (focal-normalized, at the image centre; towards a slice's edges a pixel is smaller, by
// cos^2 of its angle off the axis at most): an object under two of the smaller side across skips the
// raster, one up to four of the larger side (the coarser sampling) is drawn silent (subpixel.h).
struct PixelSides {
    double small, large;
};
PixelSides pixel_sides(const Plan& plan) {
    const double du = 2.0 * plan.tan_half_h / plan.slice_columns, dv = 2.0 * plan.tan_half_v / plan.rows;
    return {std::min(du, dv), std::max(du, dv)};
}
constexpr double kSilentPixels = 4.0; // up to this many of the larger pixel side across: drawn silent

// How thick a cluster is across its length, in the world: twice the largest distance of its vertices
// from its principal axis (the line through their mean along the covariance's main eigenvector), which
// finds a cable's run in any direction (its box is thin only along the mesh's own axes). Infinity where
// it cannot be under `limit`: three of its vertices span too tall a triangle, or their rms distance from
// the axis already reaches limit / 2; only a thin candidate costs the second pass.
double cluster_thickness(const SceneData& scene, const DepthCluster& cluster, double limit) {
    const std::array<double, 16>& m = scene.draws[cluster.draw].world_from_local;
    auto vertex = [&](std::uint32_t k) {
        const std::size_t v = std::size_t(cluster.first_vertex) + scene.indices[cluster.first_index + k];
        return transform_point(m, {scene.positions[3 * v], scene.positions[3 * v + 1], scene.positions[3 * v + 2]});
    };
    const std::uint32_t n = cluster.index_count;
    if (n == 0) return std::numeric_limits<double>::infinity();
    // An exact reject first, from three of its vertices: within limit / 2 of one line, a triangle is no
    // taller than limit over its longest side (its area at most half its diameter times the strip's
    // width). A seabed's patch fails that at once, without a pass over its vertices.
    const std::uint32_t samples[2][3] = {{0, n / 2, n - 1}, {n / 4, (3 * n) / 4, n / 3}};
    for (const auto& sample : samples) {
        const Vec3 a = vertex(sample[0]), b = vertex(sample[1]), c = vertex(sample[2]);
        const double longest = std::max({norm(sub(b, a)), norm(sub(c, a)), norm(sub(c, b))});
        if (longest > 0 && norm(cross(sub(b, a), sub(c, a))) / longest > limit)
            return std::numeric_limits<double>::infinity();
    }
    const Vec3 origin = vertex(0); // sums relative to a vertex: no cancellation far from the world's origin
    Vec3 sum{};
    double cov[3][3] = {};
    for (std::uint32_t k = 0; k < n; ++k) {
        const Vec3 p = sub(vertex(k), origin);
        for (int i = 0; i < 3; ++i) {
            sum[i] += p[i];
            for (int j = 0; j <= i; ++j)
                cov[i][j] += p[i] * p[j];
        }
    }
    const Vec3 mean{sum[0] / n, sum[1] / n, sum[2] / n};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j <= i; ++j) {
            cov[i][j] = cov[i][j] / n - mean[i] * mean[j];
            cov[j][i] = cov[i][j];
        }
    // the main axis by power iteration from the box's longest axis (its eigenvalue dominates a line's)
    Vec3 axis{1, 0, 0};
    double best = -1;
    for (int a = 0; a < 3; ++a)
        if (cov[a][a] > best) {
            best = cov[a][a];
            axis = {a == 0 ? 1.0 : 0.0, a == 1 ? 1.0 : 0.0, a == 2 ? 1.0 : 0.0};
        }
    for (int iteration = 0; iteration < 64; ++iteration) {
        Vec3 next{};
        for (int i = 0; i < 3; ++i)
            next[i] = cov[i][0] * axis[0] + cov[i][1] * axis[1] + cov[i][2] * axis[2];
        const double length = norm(next);
        if (!(length > 0)) break;
        axis = {next[0] / length, next[1] / length, next[2] / length};
    }
    Vec3 c_axis{};
    for (int i = 0; i < 3; ++i)
        c_axis[i] = cov[i][0] * axis[0] + cov[i][1] * axis[1] + cov[i][2] * axis[2];
    const double across = cov[0][0] + cov[1][1] + cov[2][2] - dot(axis, c_axis); // rms^2 off the axis
    if (!(across < 0.25 * limit * limit)) return std::numeric_limits<double>::infinity();
    double widest = 0;
    for (std::uint32_t k = 0; k < n; ++k) {
        const Vec3 d = sub(sub(vertex(k), origin), mean);
        const double along = dot(d, axis);
        widest = std::max(widest, dot(d, d) - along * along);
    }
    return 2 * std::sqrt(widest);
}

// The most pieces a draw candidate's triangles give (before the two columns each piece feeds): it
// is drawn silent or skipped only at a distance D > radius / (2 kSilentPixels / 2 x larger pixel side),
// so no point of it is nearer than that less its radius, and each triangle splits at most as split_of
// says from there.
std::uint64_t draw_pieces(const SceneData& scene, const std::vector<DepthCluster>& clusters, std::uint32_t begin,
                          std::uint32_t end, double radius, const PixelSides& pixel) {
    const std::array<double, 16>& m = scene.draws[clusters[begin].draw].world_from_local;
    const double nearest = radius / (0.5 * kSilentPixels * pixel.large) - radius;
    std::uint64_t pieces = 0;
    for (std::uint32_t c = begin; c < end; ++c)
        for (std::uint32_t t = 0; t + 3 <= clusters[c].index_count; t += 3) {
            Vec3 p[3];
            for (int i = 0; i < 3; ++i) {
                const std::size_t v =
                    std::size_t(clusters[c].first_vertex) + scene.indices[clusters[c].first_index + t + i];
                p[i] = transform_point(
                    m, {scene.positions[3 * v], scene.positions[3 * v + 1], scene.positions[3 * v + 2]});
            }
            const double longest = std::max({norm(sub(p[1], p[0])), norm(sub(p[2], p[0])), norm(sub(p[2], p[1]))});
            const std::uint64_t split = split_of(longest, nearest - longest, pixel.small);
            pieces += split * split;
        }
    return pieces;
}

// The candidates (Plan::subpixel_candidates): each draw that could be at most kSilentPixels of the larger
// pixel side across somewhere within gate_max of the sonar, else each of its clusters that could be
// thinner than a pixel there; f(begin, end, thin, size, most returns its triangles can give).
template <class F>
void for_each_candidate(const Plan& plan, const SceneData& scene, const std::vector<DepthCluster>& clusters,
                        const F& f) {
    const PixelSides pixel = pixel_sides(plan);
    const std::uint64_t per_piece = 2; // a piece feeds two columns: cone columns, or planar pixel columns
    for (std::uint32_t begin = 0; begin < clusters.size();) {
        std::uint32_t end = begin + 1;
        while (end < clusters.size() && clusters[end].draw == clusters[begin].draw)
            ++end;
        // radius < silent * (gate_max + radius), silent = kSilentPixels / 2 x the larger pixel side
        const double silent = 0.5 * kSilentPixels * pixel.large;
        const double largest = silent < 1 ? silent * plan.gate_max_m / (1 - silent) : plan.gate_max_m;
        const ClusterSize size = size_of(scene, clusters, begin, end, largest);
        if (size.radius < largest) {
            f(begin, end, false, size, draw_pieces(scene, clusters, begin, end, size.radius, pixel) * per_piece);
        } else {
            for (std::uint32_t c = begin; c < end; ++c) {
                const std::array<double, 16>& m = scene.draws[clusters[c].draw].world_from_local;
                const double lo[3] = {clusters[c].bounds_min[0], clusters[c].bounds_min[1], clusters[c].bounds_min[2]};
                const double hi[3] = {clusters[c].bounds_max[0], clusters[c].bounds_max[1], clusters[c].bounds_max[2]};
                const double limit = pixel.small * plan.gate_max_m;
                double thickness = box_extents(m, lo, hi)[1];
                if (!(thickness < limit)) thickness = cluster_thickness(scene, clusters[c], limit);
                if (!(thickness < limit)) continue;
                ClusterSize cs = size_of(scene, clusters, c, c + 1, std::numeric_limits<double>::infinity());
                cs.middle_extent = std::min(cs.middle_extent, thickness);
                f(c, c + 1, true, cs, std::uint64_t(clusters[c].index_count / 3) * kMaxSplit * kMaxSplit * per_piece);
            }
        }
        begin = end;
    }
}

} // namespace

void plan_subpixel(Plan& plan, const SceneData& scene) {
    plan.subpixel_candidates.clear();
    plan.subpixel_capacity = 0;
    if (scene.draws.empty() || plan.slice_columns == 0 || plan.rows == 0) return;
    std::vector<DepthCluster> clusters;
    build_depth_clusters(scene, clusters);
    std::vector<std::int32_t> mesh_facings(scene.meshes.size(), 2); // 2: not looked at yet
    std::uint64_t total = 0;
    for_each_candidate(
        plan, scene, clusters,
        [&](std::uint32_t begin, std::uint32_t end, bool thin, const ClusterSize& size, std::uint64_t pieces) {
            const SceneDraw& draw = scene.draws[clusters[begin].draw];
            std::int32_t& facing = mesh_facings[draw.mesh];
            if (facing == 2) facing = mesh_facing(scene, scene.meshes[draw.mesh]);
            SubpixelCandidate c;
            c.cluster_begin = begin;
            c.cluster_end = end;
            // a mirroring world_from_local turns the triangles' winding over
            c.facing = determinant3(draw.world_from_local) < 0 ? -facing : facing;
            c.thin = thin;
            for (int a = 0; a < 3; ++a)
                c.centre[a] = size.centre[a];
            c.radius = size.radius;
            c.middle_extent = size.middle_extent;
            plan.subpixel_candidates.push_back(c);
            total += pieces;
        });
    plan.subpixel_capacity = static_cast<std::uint32_t>(std::min<std::uint64_t>(total, kMaxSubpixelReturns));
    if (plan.subpixel_capacity == 0) plan.subpixel_candidates.clear();
}

void SubpixelReturns::prepare(const Plan& plan) {
    capacity_ = plan.subpixel_capacity;
    count_ = clusters_taken_ = draws_silent_ = 0;
    column_begin_.assign(std::size_t(plan.profile_columns) + 1, 0u);
    returns_.assign(capacity_, shared::SubpixelReturn{});
    unsorted_.assign(capacity_, shared::SubpixelReturn{});
    labels_.assign(capacity_, SubpixelLabel{});
    unsorted_labels_.assign(capacity_, SubpixelLabel{});
    unsorted_column_.assign(capacity_, 0u);
}

void SubpixelReturns::build(const Plan& plan, const SceneData& scene, const Pose& pose,
                            const std::vector<DepthCluster>& clusters, std::vector<shared::DepthPush>& pushes,
                            std::vector<std::uint8_t>& drawn) {
    count_ = clusters_taken_ = draws_silent_ = 0;
    std::fill(column_begin_.begin(), column_begin_.end(), 0u);
    if (capacity_ == 0) return;
    const PixelSides pixel = pixel_sides(plan);
    const double pa = pixel.small; // pieces are split to under this
    const std::array<double, 16> sonar_world = sonar_from_world(pose);
    // (facet_echo and ray_vertical_power read the constants every view shares: view 0's will do)
    const M::EchoConstants k = echo_constants<double>(plan, 0);
    const M::EchoTerms terms = echo_terms<double>(plan, true);
    const std::uint32_t H = plan.rows;
    const double half_fov = plan.params.cone_half_fov_rad, inv_cone_step = plan.params.inv_cone_step;
    const int cone_count = static_cast<int>(plan.profile_columns);
    const std::size_t cluster_count = clusters.size();
    std::uint32_t instance = 0; // the object's whose pieces are being listed
    // One piece: its centroid q (sonar frame), area and unit normal n (counter-clockwise), into the list.
    auto add_piece = [&](const Vec3& q, double area, const Vec3& n, std::int32_t facing,
                         const shared::MaterialGpu& mat) -> bool {
        const double r = norm(q);
        if (!(r > 0)) return true;
        const double c = dot(n, q) / r; // cos of the ray to the piece against its counter-clockwise normal
        const double cos_incidence = facing > 0 ? -c : (facing < 0 ? c : std::abs(c));
        if (!(cos_incidence > 0)) return true; // faces away: the object's own front hides it
        const double energy = M::facet_echo(k, terms, mat, area, std::min(cos_incidence, 1.0), r,
                                            M::ray_vertical_power(k, terms, q[2] / r, q[1] / r));
        if (!(energy > 0)) return true;
        // Its pixel: in the view whose cell holds its direction (the elevation band, a tier view's azimuth
        // wedge: each direction in one view, as the pixels' vertical power counts it), or with the vertical
        // pattern off (no cells: every pixel counts) the first view whose frustum holds it.
        const double sin_e = q[2] / r;
        for (std::uint32_t s = 0; s < plan.views; ++s) {
            const ViewGeometry& view = plan.view_geometry[s];
            const double view_z = q[0] * view.forward[0] + q[1] * view.forward[1] + q[2] * view.forward[2];
            if (!(view_z > 0)) continue;
            const double u = (q[0] * view.right[0] + q[1] * view.right[1] + q[2] * view.right[2]) / view_z;
            const double v = (q[0] * view.down[0] + q[1] * view.down[1] + q[2] * view.down[2]) / view_z;
            if (!(std::abs(u) <= view.tan_half_h && std::abs(v) <= view.tan_half_v)) continue;
            if (terms.vertical_pattern) {
                if (!(sin_e >= view.sin_elevation_min && sin_e <= view.sin_elevation_max)) continue;
                if (view.wedge && !(q[1] * view.wedge_start[0] - q[0] * view.wedge_start[1] >= 0 &&
                                    q[1] * view.wedge_end[0] - q[0] * view.wedge_end[1] < 0))
                    continue;
            }
            const std::uint32_t W = view_columns(plan, s);
            const auto column = std::min(static_cast<std::uint32_t>((u / view.tan_half_h + 1.0) * 0.5 * W), W - 1);
            const auto row = std::min(static_cast<std::uint32_t>((v / view.tan_half_v + 1.0) * 0.5 * H), H - 1);
            shared::SubpixelReturn ret{row * plan.columns + view_first_column(plan, s) + column, static_cast<float>(r),
                                       0.0f, static_cast<float>(view_z)};
            auto push = [&](std::uint32_t profile_column, double e) {
                if (count_ >= capacity_) return false;
                ret.energy = static_cast<float>(e);
                unsorted_[count_] = ret;
                unsorted_labels_[count_] = {static_cast<float>(q[0]), static_cast<float>(q[1]),
                                            static_cast<float>(q[2]), instance};
                unsorted_column_[count_] = profile_column;
                ++count_;
                return true;
            };
            if (!plan.line_array) {
                // planar: the two pixel columns whose centres it lies between, linearly (the line array's
                // cone_share below does the same with the cone columns). Its nearest column alone made a small
                // target's response across a beam a staircase of column steps: up to 0.6 dB off the pattern
                // on the main lobe's skirt.
                // Between two slices the neighbour's edge column stands in (the slices meet edge to edge, their
                // columns as wide there); at the fan's edges and a tier view's the edge column takes it all.
                const double at = (u / view.tan_half_h + 1.0) * 0.5 * W - 0.5; // column centres at integers
                const double below = std::floor(at);
                const double upper = at - below;
                const bool slice = s < plan.slices;
                std::uint32_t lower_column = 0;
                if (below >= 0.0 && below + 1.0 < W) {
                    lower_column = s * W + static_cast<std::uint32_t>(below);
                } else if (below < 0.0 && slice && s > 0) {
                    lower_column = s * W - 1; // the previous slice's last column
                } else if (below >= 0.0 && slice && s + 1 < plan.slices) {
                    lower_column = s * W + W - 1; // and the next slice's first after it
                } else {
                    return push(below < 0.0 ? s * W : s * W + W - 1, energy);
                }
                if (!push(lower_column, energy * (1.0 - upper))) return false;
                return upper > 0.0 ? push(lower_column + 1, energy * upper) : true;
            }
            // the cone columns of its steering angle, sin(theta) = y / r (array_axis_cosine)
            const double x = M::cone_coord(q[1] / r, half_fov, inv_cone_step);
            const int below = static_cast<int>(std::floor(x));
            for (int cone = std::max(below, 0); cone <= std::min(below + 1, cone_count - 1); ++cone) {
                const double share = M::cone_share(x, cone, cone_count);
                if (share > 0 && !push(static_cast<std::uint32_t>(cone), energy * share)) return false;
            }
            return true;
        }
        return true; // in no view: outside the pixel grid, not heard
    };

    const std::size_t draw_count = scene.draws.size();
    for (const SubpixelCandidate& candidate : plan.subpixel_candidates) {
        const std::uint32_t draw_index = clusters[candidate.cluster_begin].draw;
        const SceneDraw& draw = scene.draws[draw_index];
        instance = draw.instance;
        const Vec3 centre =
            transform_point(sonar_world, {candidate.centre[0], candidate.centre[1], candidate.centre[2]});
        const double distance = norm(centre), nearest = distance - candidate.radius;
        // Heard at all (else the depth pass keeps it: it draws nothing inside the gate either way)?
        if (!(nearest < plan.gate_max_m && distance + candidate.radius > plan.gate_min_m)) continue;
        bool skip_raster, silent = false;
        if (candidate.thin) {
            skip_raster = nearest > 0 && candidate.middle_extent < pixel.small * nearest;
            if (!skip_raster) continue;
        } else {
            skip_raster = candidate.radius < pixel.small * distance; // under two pixels across
            silent = !skip_raster && candidate.radius < 0.5 * kSilentPixels * pixel.large * distance;
            if (!skip_raster && !silent) continue;
        }
        const std::array<double, 16> sonar_local = multiply(sonar_world, draw.world_from_local);
        const shared::MaterialGpu& mat =
            plan.materials[M::material_index(draw.material, static_cast<std::uint32_t>(plan.materials.size()))];
        const std::uint32_t first = count_;
        bool fits = true;
        for (std::uint32_t ci = candidate.cluster_begin; ci < candidate.cluster_end && fits; ++ci) {
            const DepthCluster& cluster = clusters[ci];
            for (std::uint32_t t = 0; t + 3 <= cluster.index_count && fits; t += 3) {
                Vec3 p[3];
                for (int i = 0; i < 3; ++i) {
                    const std::size_t v =
                        std::size_t(cluster.first_vertex) + scene.indices[cluster.first_index + t + i];
                    p[i] = transform_point(
                        sonar_local, {scene.positions[3 * v], scene.positions[3 * v + 1], scene.positions[3 * v + 2]});
                }
                const Vec3 e1 = sub(p[1], p[0]), e2 = sub(p[2], p[0]);
                const Vec3 normal = cross(e1, e2);
                const double twice_area = norm(normal);
                if (!(twice_area > 0)) continue;
                // A closed mesh's triangle that faces away at all three corners faces away at every piece
                // (a piece's centroid is a mean of the corners, n . q their mean): skipped whole.
                if (candidate.facing != 0) {
                    const double side = candidate.facing > 0 ? 1.0 : -1.0;
                    if (side * dot(normal, p[0]) >= 0 && side * dot(normal, p[1]) >= 0 && side * dot(normal, p[2]) >= 0)
                        continue;
                }
                const Vec3 n{normal[0] / twice_area, normal[1] / twice_area, normal[2] / twice_area};
                const Vec3 centroid{(p[0][0] + p[1][0] + p[2][0]) / 3, (p[0][1] + p[1][1] + p[2][1]) / 3,
                                    (p[0][2] + p[1][2] + p[2][2]) / 3};
                const double longest = std::max({norm(e1), norm(e2), norm(sub(p[2], p[1]))});
                const std::uint32_t split = split_of(longest, norm(centroid) - longest, pa);
                // split^2 pieces: the triangles of the grid p0 + (i e1 + j e2) / split, upright (i + j <
                // split) and inverted (i + j < split - 1), each of area / split^2, centroid at (i + o, j + o)
                // / split with o = 1/3 upright, 2/3 inverted.
                const double piece_area = 0.5 * twice_area / (double(split) * split), inv = 1.0 / split;
                for (std::uint32_t i = 0; i < split && fits; ++i) {
                    for (std::uint32_t j = 0; i + j < split && fits; ++j) {
                        for (int kind = 0; kind < 2 && fits; ++kind) {
                            if (kind == 1 && i + j + 1 >= split) break;
                            const double o = kind == 0 ? 1.0 / 3.0 : 2.0 / 3.0;
                            const double a = (i + o) * inv, b = (j + o) * inv;
                            const Vec3 q{p[0][0] + a * e1[0] + b * e2[0], p[0][1] + a * e1[1] + b * e2[1],
                                         p[0][2] + a * e1[2] + b * e2[2]};
                            fits = add_piece(q, piece_area, n, candidate.facing, mat);
                        }
                    }
                }
            }
        }
        if (!fits) { // the list is full: this object and the rest go to the depth pass as before
            count_ = first;
            break;
        }
        if (skip_raster) {
            for (std::uint32_t ci = candidate.cluster_begin; ci < candidate.cluster_end; ++ci)
                for (std::size_t s = 0; s < plan.views; ++s)
                    drawn[s * cluster_count + ci] = 0;
            clusters_taken_ += candidate.cluster_end - candidate.cluster_begin;
        } else { // drawn for its depth only (the instance, with labels, stays above the material)
            for (std::size_t s = 0; s < plan.views; ++s) {
                std::uint32_t& id = pushes[s * draw_count + draw_index].material_id;
                id = (id & ~shared::kMaterialIdMask) | plan.subpixel_silent_material;
            }
            ++draws_silent_;
        }
    }

    // sorted by column, each column's returns in the order they were listed
    for (std::uint32_t i = 0; i < count_; ++i)
        ++column_begin_[unsorted_column_[i] + 1];
    for (std::size_t c = 1; c < column_begin_.size(); ++c)
        column_begin_[c] += column_begin_[c - 1];
    for (std::uint32_t i = 0; i < count_; ++i) {
        // column_begin_[c] runs ahead as c's returns are placed, then is moved back below
        const std::uint32_t at = column_begin_[unsorted_column_[i]]++;
        returns_[at] = unsorted_[i];
        labels_[at] = unsorted_labels_[i];
    }
    for (std::size_t c = column_begin_.size() - 1; c > 0; --c)
        column_begin_[c] = column_begin_[c - 1];
    column_begin_[0] = 0;
}

std::size_t SubpixelReturns::buffer_bytes(const Plan& plan) {
    if (plan.subpixel_capacity == 0) return 16;
    const std::size_t header = (std::size_t(plan.profile_columns) + 2 + 3) & ~std::size_t(3);
    return header * sizeof(std::uint32_t) + std::size_t(plan.subpixel_capacity) * sizeof(shared::SubpixelReturn);
}

std::size_t SubpixelReturns::written_bytes(const Plan& plan) const {
    if (capacity_ == 0) return 0;
    const std::size_t header = (std::size_t(plan.profile_columns) + 2 + 3) & ~std::size_t(3);
    return header * sizeof(std::uint32_t) + std::size_t(count_) * sizeof(shared::SubpixelReturn);
}

void SubpixelReturns::write_buffer(const Plan& plan, void* destination) const {
    if (capacity_ == 0) return;
    auto* bytes = static_cast<char*>(destination);
    std::memcpy(bytes, column_begin_.data(), column_begin_.size() * sizeof(std::uint32_t));
    std::memcpy(bytes + column_begin_.size() * sizeof(std::uint32_t), &plan.subpixel_silent_material,
                sizeof(std::uint32_t));
    const std::size_t header = (std::size_t(plan.profile_columns) + 2 + 3) & ~std::size_t(3);
    std::memcpy(bytes + header * sizeof(std::uint32_t), returns_.data(), count_ * sizeof(shared::SubpixelReturn));
}

} // namespace vksonar
