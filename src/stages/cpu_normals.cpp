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

// The rotation of slice s: the float path reads the floats the shaders get (SliceInfo), the double
// path takes cos/sin in double of the slice azimuth, as compose_depth_draws does.
template <class Real> void slice_rotation(const Plan& plan, std::uint32_t s, Real& cs, Real& sn) {
    if constexpr (std::is_same_v<Real, float>) {
        cs = plan.slice_info[s].cos_center;
        sn = plan.slice_info[s].sin_center;
    } else {
        const double phi = plan.slice_info[s].center_azimuth_rad;
        cs = std::cos(phi);
        sn = std::sin(phi);
    }
}

} // namespace

std::size_t normals_scratch_count(const Plan& plan) {
    // per column: the ray (x, y; its z is -v per row); five rows of (Px, Py, Pz, r) (the 5x5 window of
    // sobel5; sobel3 uses 3)
    return static_cast<std::size_t>(plan.columns) * (2 + kRingRows * 4);
}

// The loops around the kernels of shaders/sonar_kernels.h (sobel3_normal, sobel5_normal) that
// normals.comp calls: positions are reconstructed once per pixel into a ring of five rows, and each
// window column is rebuilt from it as the window slides along the row.
template <class Real>
void normals_rows(const Plan& plan, const float* depth, float* normals4, Real* scratch, std::uint32_t row_begin,
                  std::uint32_t row_end) {
    using M = Math<Real>;
    using Sample = typename M::Sample;
    using Column3 = typename M::Column3;
    using Column5 = typename M::Column5;
    const PixelGeometry<Real> geometry = pixel_geometry<Real>(plan);
    const Real jump_rel = static_cast<Real>(plan.params.edge_relative_jump);
    const std::int64_t C = plan.columns, R = plan.rows;
    const std::uint32_t W = plan.slice_columns;

    // pixel_ray per column, without its z (-v, per row): P = z * ray, so per pixel only z changes.
    Real* ray_x = scratch;
    Real* ray_y = scratch + C;
    Real* ring = scratch + 2 * C; // rows j % kRingRows: (Px, Py, Pz, r) per column
    for (std::int64_t c = 0; c < C; ++c) {
        const std::uint32_t col = static_cast<std::uint32_t>(c), s = col / W;
        Real cs, sn;
        slice_rotation(plan, s, cs, sn);
        const auto ray = M::pixel_ray(M::pixel_coord(col - s * W, W, geometry.tan_half_h), Real(0), cs, sn);
        ray_x[c] = ray.x;
        ray_y[c] = ray.y;
    }
    auto fill_row = [&](std::int64_t j) {
        Real* row = ring + (j % kRingRows) * C * 4;
        const Real v =
            M::pixel_coord(static_cast<std::uint32_t>(j), static_cast<std::uint32_t>(R), geometry.tan_half_v);
        const float* d = depth + j * C;
        for (std::int64_t c = 0; c < C; ++c) {
            Real* q = row + 4 * c;
            if (d[c] > 0.0f) {
                const Real z = M::view_z_from_depth(static_cast<Real>(d[c]), geometry.depth_a, geometry.depth_b);
                const Sample p = M::sample_at(z, typename M::vec3(ray_x[c], ray_y[c], -v));
                q[0] = p.pos.x;
                q[1] = p.pos.y;
                q[2] = p.pos.z;
                q[3] = p.range;
            } else {
                q[0] = q[1] = q[2] = q[3] = Real(0);
            }
        }
    };
    // A hit has a range > 0 (view z > 0), a miss 0 in the ring.
    auto sample = [&](std::int64_t c, std::int64_t j) -> Sample {
        if (c < 0 || j < 0 || c >= C || j >= R) return M::no_sample();
        const Real* q = ring + ((j % kRingRows) * C + c) * 4;
        return Sample{typename M::vec3(q[0], q[1], q[2]), q[3], q[3] > Real(0)};
    };
    auto column3 = [&](std::int64_t c, std::int64_t j) {
        return Column3{sample(c, j - 1), sample(c, j), sample(c, j + 1)};
    };
    auto column5 = [&](std::int64_t c, std::int64_t j) {
        return Column5{sample(c, j - 2), sample(c, j - 1), sample(c, j), sample(c, j + 1), sample(c, j + 2)};
    };
    auto store = [](float* out, const typename M::vec4& n) {
        out[0] = static_cast<float>(n.x);
        out[1] = static_cast<float>(n.y);
        out[2] = static_cast<float>(n.z);
        out[3] = static_cast<float>(n.w);
    };
    const bool sobel5 = plan.params.normal_method == shared::kNormalsSobel5;

    // The ring holds rows j-2 .. j+2 of the row being computed: those before the first row's j+2 first.
    for (std::int64_t j = std::max<std::int64_t>(std::int64_t(row_begin) - 2, 0);
         j < std::min<std::int64_t>(R, std::int64_t(row_begin) + 2); ++j)
        fill_row(j);
    for (std::int64_t j = row_begin; j < std::int64_t(row_end); ++j) {
        if (j + 2 < R) fill_row(j + 2);
        float* out_row = normals4 + 4 * j * C;
        if (sobel5) {
            Column5 l2 = column5(-2, j), l1 = column5(-1, j), c = column5(0, j), r1 = column5(1, j);
            for (std::int64_t x = 0; x < C; ++x) {
                const Column5 r2 = column5(x + 2, j);
                store(out_row + 4 * x,
                      c.mid.valid ? M::sobel5_normal(l2, l1, c, r1, r2, jump_rel) : typename M::vec4(Real(0)));
                l2 = l1;
                l1 = c;
                c = r1;
                r1 = r2;
            }
        } else {
            Column3 l = column3(-1, j), c = column3(0, j);
            for (std::int64_t x = 0; x < C; ++x) {
                const Column3 r = column3(x + 1, j);
                store(out_row + 4 * x, c.mid.valid ? M::sobel3_normal(l, c, r, jump_rel) : typename M::vec4(Real(0)));
                l = c;
                c = r;
            }
        }
    }
}

template <class Real>
void geometric_normals_rows(const Plan& plan, const float* depth, const float* face4, float* normals4,
                            std::uint32_t row_begin, std::uint32_t row_end) {
    using M = Math<Real>;
    const PixelGeometry<Real> geometry = pixel_geometry<Real>(plan);
    const std::uint32_t C = plan.columns, R = plan.rows, W = plan.slice_columns;
    for (std::uint32_t j = row_begin; j < row_end; ++j) {
        const Real v = M::pixel_coord(j, R, geometry.tan_half_v);
        for (std::uint32_t c = 0; c < C; ++c) {
            const std::size_t i = static_cast<std::size_t>(j) * C + c;
            float* out = normals4 + 4 * i;
            if (!(depth[i] > 0.0f)) {
                out[0] = out[1] = out[2] = out[3] = 0.0f;
                continue;
            }
            const std::uint32_t s = c / W;
            const Real u = M::pixel_coord(c - s * W, W, geometry.tan_half_h);
            Real cs, sn;
            slice_rotation(plan, s, cs, sn);
            const Real z = M::view_z_from_depth(static_cast<Real>(depth[i]), geometry.depth_a, geometry.depth_b);
            const auto p = M::sample_at(z, M::pixel_ray(u, v, cs, sn));
            const float* q = face4 + 4 * i;
            const auto n = M::geometric_normal(p, typename M::vec3(q[0], q[1], q[2]), geometry.tan_half_h,
                                               geometry.tan_half_v, cs, sn);
            out[0] = static_cast<float>(n.x);
            out[1] = static_cast<float>(n.y);
            out[2] = static_cast<float>(n.z);
            out[3] = static_cast<float>(n.w);
        }
    }
}

template <class Real> void normals(const Plan& plan, const float* depth, float* normals4, Real* scratch) {
    normals_rows<Real>(plan, depth, normals4, scratch, 0, plan.rows);
}

template <class Real> void normals(const Plan& plan, const float* depth, float* normals4) {
    std::vector<Real> scratch(std::max<std::size_t>(normals_scratch_count(plan), 1));
    normals<Real>(plan, depth, normals4, scratch.data());
}

template <class Real>
void geometric_normals(const Plan& plan, const float* depth, const float* face4, float* normals4) {
    geometric_normals_rows<Real>(plan, depth, face4, normals4, 0, plan.rows);
}

template void geometric_normals_rows<float>(const Plan&, const float*, const float*, float*, std::uint32_t,
                                            std::uint32_t);
template void geometric_normals_rows<double>(const Plan&, const float*, const float*, float*, std::uint32_t,
                                             std::uint32_t);
template void normals_rows<float>(const Plan&, const float*, float*, float*, std::uint32_t, std::uint32_t);
template void normals_rows<double>(const Plan&, const float*, float*, double*, std::uint32_t, std::uint32_t);
template void geometric_normals<float>(const Plan&, const float*, const float*, float*);
template void geometric_normals<double>(const Plan&, const float*, const float*, float*);
template void normals<float>(const Plan&, const float*, float*);
template void normals<double>(const Plan&, const float*, float*);
template void normals<float>(const Plan&, const float*, float*, float*);
template void normals<double>(const Plan&, const float*, float*, double*);

} // namespace vksonar::cpu
