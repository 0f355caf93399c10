// CPU reference of the normals stage (docs/pipeline.md §2): Sobel 3x3 (or 5x5 with normal_method =
// sobel5, where the whole 5x5 window is one surface) on reconstructed sonar-frame positions in smooth
// regions, one-sided differences towards the neighbour of closest range near depth edges, and a
// sonar-facing fallback where no tangent can be formed. Sums run in the order pipeline.md §2 states,
// the order shaders/normals.comp uses, so float results agree with the GPU to rounding.
//
// normal_method = geometric (geometric_normals): no stencil; the depth pass recorded each pixel's face
// normal, which is mapped to the sonar frame, turned to face the sonar and given its cos incidence.
//
// Constants: in float the stage reads the same float values the shaders get (SonarParams,
// SliceInfo.cos/sin_center); in double it reads the Plan's double values and recomputes the slice
// rotation in double from the slice azimuth, exactly as compose_depth_draws does.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "core/sonar_math.hpp"
#include "stages/cpu_stages.h"

namespace vksonar::cpu {
namespace {

template <class Real> struct Vec3 { Real x, y, z; };
template <class Real> Vec3<Real> operator-(const Vec3<Real>& a, const Vec3<Real>& b) {
    return {a.x - b.x, a.y - b.y, a.z - b.z};
}
template <class Real> Real dot(const Vec3<Real>& a, const Vec3<Real>& b) {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}
template <class Real> Vec3<Real> cross(const Vec3<Real>& a, const Vec3<Real>& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

template <class Real> Real length(const Vec3<Real>& a) {
    return std::sqrt(dot(a, a));
}
template <class Real> Vec3<Real> axpy(Real w, const Vec3<Real>& d, const Vec3<Real>& acc) {
    return {acc.x + w * d.x, acc.y + w * d.y, acc.z + w * d.z};
}

constexpr std::int64_t kRingRows = 5; // rows j-2 .. j+2 of reconstructed positions

// The pixel grid's frustum and depth constants in the working precision: the float path uses the
// GPU's (already rounded) parameters, the double path the plan's doubles.
template <class Real> struct PixelGeometry { Real tan_half_h, tan_half_v, depth_a, depth_b; };
template <class Real> PixelGeometry<Real> pixel_geometry(const Plan& plan) {
    if constexpr (std::is_same_v<Real, float>)
        return {plan.params.tan_half_h, plan.params.tan_half_v, plan.params.depth_a, plan.params.depth_b};
    else
        return {static_cast<Real>(plan.tan_half_h), static_cast<Real>(plan.tan_half_v), static_cast<Real>(plan.depth_a),
                static_cast<Real>(plan.depth_b)};
}

} // namespace

std::size_t normals_scratch_count(const Plan& plan) {
    // per column: ray x, y; five rows of (Px, Py, Pz, r) (the 5x5 window of sobel5; sobel3 uses 3)
    return static_cast<std::size_t>(plan.columns) * (2 + kRingRows * 4);
}

template <class Real> void normals(const Plan& plan, const float* depth, float* normals4, Real* scratch) {
    using M = Math<Real>;
    // Plain locals, not a structured binding: the lambdas below capture them (C++17 lets no lambda
    // capture a structured binding; clang rejects it).
    const PixelGeometry<Real> geometry = pixel_geometry<Real>(plan);
    const Real tan_half_h = geometry.tan_half_h, tan_half_v = geometry.tan_half_v;
    const Real depth_a = geometry.depth_a, depth_b = geometry.depth_b;
    const Real jump = static_cast<Real>(plan.params.edge_relative_jump);
    const std::int64_t C = plan.columns, R = plan.rows;
    const std::uint32_t W = plan.slice_columns;

    // Ray of each column in its own slice frame: f_s + u r_s = (cos + u sin, sin - u cos); the z
    // component is -v per row. P = z * ray, so per pixel only z changes.
    Real* ray_x = scratch;
    Real* ray_y = scratch + C;
    Real* ring = scratch + 2 * C; // rows j % kRingRows: (Px, Py, Pz, r) per column
    for (std::int64_t c = 0; c < C; ++c) {
        const std::uint32_t col = static_cast<std::uint32_t>(c), s = col / W;
        const Real u = M::pixel_coord(col - s * W, W, tan_half_h);
        Real cs, sn;
        if constexpr (std::is_same_v<Real, float>) {
            cs = plan.slice_info[s].cos_center;
            sn = plan.slice_info[s].sin_center;
        } else { // the rotation compose_depth_draws uses: cos/sin in double of the slice azimuth
            const double phi = plan.slice_info[s].center_azimuth_rad;
            cs = std::cos(phi);
            sn = std::sin(phi);
        }
        ray_x[c] = cs + u * sn;
        ray_y[c] = sn - u * cs;
    }
    auto fill_row = [&](std::int64_t j) {
        Real* row = ring + (j % kRingRows) * C * 4;
        const Real minus_v = -M::pixel_coord(static_cast<std::uint32_t>(j), static_cast<std::uint32_t>(R), tan_half_v);
        const float* d = depth + j * C;
        for (std::int64_t c = 0; c < C; ++c) {
            Real* q = row + 4 * c;
            if (d[c] > 0.0f) {
                const Real z = M::view_z_from_depth(static_cast<Real>(d[c]), depth_a, depth_b);
                const Vec3<Real> P{z * ray_x[c], z * ray_y[c], z * minus_v};
                q[0] = P.x;
                q[1] = P.y;
                q[2] = P.z;
                q[3] = length(P);
            } else {
                q[0] = q[1] = q[2] = q[3] = Real(0);
            }
        }
    };
    auto valid = [&](std::int64_t c, std::int64_t j) {
        return c >= 0 && j >= 0 && c < C && j < R && depth[j * C + c] > 0.0f;
    };
    auto at = [&](std::int64_t c, std::int64_t j) -> const Real* { return ring + ((j % kRingRows) * C + c) * 4; };
    auto pos = [&](std::int64_t c, std::int64_t j) -> Vec3<Real> {
        const Real* q = at(c, j);
        return {q[0], q[1], q[2]};
    };
    const bool sobel5 = plan.params.normal_method == shared::kNormalsSobel5;

    for (std::int64_t j = 0; j < std::min<std::int64_t>(R, 2); ++j)
        fill_row(j);
    for (std::int64_t j = 0; j < R; ++j) {
        if (j + 2 < R) fill_row(j + 2);
        for (std::int64_t c = 0; c < C; ++c) {
            float* out = normals4 + 4 * (j * C + c);
            if (!valid(c, j)) {
                out[0] = out[1] = out[2] = out[3] = 0.0f;
                continue;
            }
            const Real* pp = at(c, j);
            const Vec3<Real> P{pp[0], pp[1], pp[2]};
            const Real r = pp[3];

            // sobel5 needs all 24 neighbours of the 5x5 window valid and on the pixel's surface;
            // anywhere else it is exactly the sobel3 path below.
            bool smooth5 = sobel5;
            for (int dy = -2; dy <= 2 && smooth5; ++dy) {
                for (int dx = -2; dx <= 2 && smooth5; ++dx) {
                    if (!valid(c + dx, j + dy)) {
                        smooth5 = false;
                    } else if (!(std::abs(at(c + dx, j + dy)[3] - r) <= jump * r)) {
                        smooth5 = false;
                    }
                }
            }

            Vec3<Real> tx{0, 0, 0}, ty{0, 0, 0};
            bool facing = false;
            if (smooth5) {
                // Smoothing (1 4 6 4 1) x derivative (-1 -2 0 2 1), the derivative taken as differences
                // of symmetric pairs, 2 (P+1 - P-1) + (P+2 - P-2), so large positions cancel before
                // weighting; outer sum from the -2 side. Same order as normals.comp (pipeline.md §2).
                const Real s[5] = {Real(1), Real(4), Real(6), Real(4), Real(1)};
                for (int k = 0; k < 5; ++k) { // dy = -2 .. 2
                    const std::int64_t y = j + k - 2;
                    const Vec3<Real> d1 = pos(c + 1, y) - pos(c - 1, y), d2 = pos(c + 2, y) - pos(c - 2, y);
                    const Vec3<Real> g{Real(2) * d1.x + d2.x, Real(2) * d1.y + d2.y, Real(2) * d1.z + d2.z};
                    tx = axpy(s[k], g, tx);
                }
                for (int k = 0; k < 5; ++k) { // dx = -2 .. 2
                    const std::int64_t x = c + k - 2;
                    const Vec3<Real> d1 = pos(x, j + 1) - pos(x, j - 1), d2 = pos(x, j + 2) - pos(x, j - 2);
                    const Vec3<Real> g{Real(2) * d1.x + d2.x, Real(2) * d1.y + d2.y, Real(2) * d1.z + d2.z};
                    ty = axpy(s[k], g, ty);
                }
            } else {
                // 3x3 neighbourhood: positions and ranges of the valid neighbours.
                Vec3<Real> N[3][3];
                Real rn[3][3];
                bool ok[3][3];
                bool smooth = true;
                for (int dy = -1; dy <= 1; ++dy) {
                    for (int dx = -1; dx <= 1; ++dx) {
                        const bool v = valid(c + dx, j + dy);
                        ok[dy + 1][dx + 1] = v;
                        if (v) {
                            const Real* q = at(c + dx, j + dy);
                            N[dy + 1][dx + 1] = {q[0], q[1], q[2]};
                            rn[dy + 1][dx + 1] = q[3];
                            if (!(std::abs(q[3] - r) <= jump * r)) smooth = false;
                        } else {
                            smooth = false;
                        }
                    }
                }

                if (smooth) {
                    const Real w[3] = {Real(1), Real(2), Real(1)};
                    for (int k = 0; k < 3; ++k) { // dy = -1, 0, 1
                        const Vec3<Real> d = N[k][2] - N[k][0];
                        tx = {tx.x + w[k] * d.x, tx.y + w[k] * d.y, tx.z + w[k] * d.z};
                    }
                    for (int k = 0; k < 3; ++k) { // dx = -1, 0, 1
                        const Vec3<Real> d = N[2][k] - N[0][k];
                        ty = {ty.x + w[k] * d.x, ty.y + w[k] * d.y, ty.z + w[k] * d.z};
                    }
                } else {
                    // One-sided differences towards the valid neighbour of closer range (ties: +1 side).
                    const bool xp = ok[1][2], xm = ok[1][0], yp = ok[2][1], ym = ok[0][1];
                    if ((!xp && !xm) || (!yp && !ym)) {
                        facing = true;
                    } else {
                        const bool use_xp = xp && (!xm || std::abs(rn[1][2] - r) <= std::abs(rn[1][0] - r));
                        tx = use_xp ? N[1][2] - P : P - N[1][0];
                        const bool use_yp = yp && (!ym || std::abs(rn[2][1] - r) <= std::abs(rn[0][1] - r));
                        ty = use_yp ? N[2][1] - P : P - N[0][1];
                    }
                }
            }

            Vec3<Real> n{0, 0, 0};
            Real cos_inc = Real(1);
            if (!facing) {
                const Vec3<Real> cr = cross(tx, ty);
                const Real len = length(cr);
                if (len > Real(0) && std::isfinite(len)) {
                    n = {cr.x / len, cr.y / len, cr.z / len};
                    if (dot(n, P) > Real(0)) n = {-n.x, -n.y, -n.z};
                    cos_inc = M::incidence_cos(dot(n, P), r);
                } else {
                    facing = true;
                }
            }
            if (facing) { // faces the sonar: never brighter than a facing surface
                n = {-P.x / r, -P.y / r, -P.z / r};
                cos_inc = Real(1);
            }
            out[0] = static_cast<float>(n.x);
            out[1] = static_cast<float>(n.y);
            out[2] = static_cast<float>(n.z);
            out[3] = static_cast<float>(cos_inc);
        }
    }
}

template <class Real>
void geometric_normals(const Plan& plan, const float* depth, const float* face4, float* normals4) {
    using M = Math<Real>;
    // Plain locals, not a structured binding: the lambdas below capture them (C++17 lets no lambda
    // capture a structured binding; clang rejects it).
    const PixelGeometry<Real> geometry = pixel_geometry<Real>(plan);
    const Real tan_half_h = geometry.tan_half_h, tan_half_v = geometry.tan_half_v;
    const Real depth_a = geometry.depth_a, depth_b = geometry.depth_b;
    const std::uint32_t C = plan.columns, R = plan.rows, W = plan.slice_columns;
    for (std::uint32_t j = 0; j < R; ++j) {
        const Real v = M::pixel_coord(j, R, tan_half_v);
        for (std::uint32_t c = 0; c < C; ++c) {
            const std::size_t i = static_cast<std::size_t>(j) * C + c;
            float* out = normals4 + 4 * i;
            if (!(depth[i] > 0.0f)) {
                out[0] = out[1] = out[2] = out[3] = 0.0f;
                continue;
            }
            const std::uint32_t s = c / W;
            const Real u = M::pixel_coord(c - s * W, W, tan_half_h);
            Real cs, sn;
            if constexpr (std::is_same_v<Real, float>) {
                cs = plan.slice_info[s].cos_center;
                sn = plan.slice_info[s].sin_center;
            } else {
                const double phi = plan.slice_info[s].center_azimuth_rad;
                cs = std::cos(phi);
                sn = std::sin(phi);
            }
            // The same reconstruction as normals.comp's load(): P = z (f_s + u r_s + v d).
            const Real z = M::view_z_from_depth(static_cast<Real>(depth[i]), depth_a, depth_b);
            const Vec3<Real> P{z * (cs + u * sn), z * (sn - u * cs), z * -v};
            const Real r = length(P);
            const float* q = face4 + 4 * i;
            const Real qx = q[0], qy = q[1], qz = q[2];
            Vec3<Real> n{M::face_normal_sonar_x(qx, qz, tan_half_h, cs, sn),
                         M::face_normal_sonar_y(qx, qz, tan_half_h, cs, sn), M::face_normal_sonar_z(qy, tan_half_v)};
            const Real len = length(n);
            Real cos_inc = Real(1);
            if (len > Real(0) && std::isfinite(len)) {
                n = {n.x / len, n.y / len, n.z / len};
                if (dot(n, P) > Real(0)) n = {-n.x, -n.y, -n.z};
                cos_inc = M::incidence_cos(dot(n, P), r);
            } else { // no face normal (degenerate): faces the sonar, as the Sobel fallback
                n = {-P.x / r, -P.y / r, -P.z / r};
            }
            out[0] = static_cast<float>(n.x);
            out[1] = static_cast<float>(n.y);
            out[2] = static_cast<float>(n.z);
            out[3] = static_cast<float>(cos_inc);
        }
    }
}

template <class Real> void normals(const Plan& plan, const float* depth, float* normals4) {
    std::vector<Real> scratch(std::max<std::size_t>(normals_scratch_count(plan), 1));
    normals<Real>(plan, depth, normals4, scratch.data());
}

template void geometric_normals<float>(const Plan&, const float*, const float*, float*);
template void geometric_normals<double>(const Plan&, const float*, const float*, float*);
template void normals<float>(const Plan&, const float*, float*);
template void normals<double>(const Plan&, const float*, float*);
template void normals<float>(const Plan&, const float*, float*, float*);
template void normals<double>(const Plan&, const float*, float*, double*);

} // namespace vksonar::cpu
