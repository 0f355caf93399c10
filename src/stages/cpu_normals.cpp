// CPU reference of the normals stage (docs/pipeline.md §2): Sobel 3x3 (or 5x5 with normal_method =
// sobel5, where the whole 5x5 window is one surface) on reconstructed sonar-frame positions in smooth
// regions, one-sided differences towards the neighbour of closest range near depth edges, and a
// sonar-facing fallback where no tangent can be formed. Sums run in the order pipeline.md §2 states,
// the order shaders/normals.comp uses, so float results agree with the GPU to rounding.
//
// normal_method = geometric (geometric_normals): no stencil; the depth pass recorded each pixel's face
// normal, which is mapped to the sonar frame, turned to face the sonar and given its cos incidence.
//
// Constants: in float the stage reads the same float values the shaders get (SonarParams, SliceInfo);
// in double it reads the Plan's double values, the views' geometry as compose_depth_draws does.
// Neighbours across a seam that does not join (a tier view's edges: view_group) read as no sample.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>
#include <vector>

#include <emmintrin.h>
#include <xmmintrin.h>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include "core/pixel_views.h"
#include "core/sonar_math.hpp"
#include "stages/cpu_simd.h"
#include "stages/cpu_stages.h"

namespace vksonar::cpu {
namespace {

constexpr std::int64_t kRingRows = 5; // rows j-2 .. j+2 of reconstructed positions

// The depth constants in the working precision: the float path uses the GPU's (already rounded)
// parameters, the double path the plan's doubles (each view's half extents: pixel_view).
template <class Real> struct PixelGeometry { Real depth_a, depth_b; };
template <class Real> PixelGeometry<Real> pixel_geometry(const Plan& plan) {
    if constexpr (std::is_same_v<Real, float>)
        return {plan.params.depth_a, plan.params.depth_b};
    else
        return {static_cast<Real>(plan.depth_a), static_cast<Real>(plan.depth_b)};
}

// sobel3_normal of the four pixels x .. x + 3 of a row (float), as SSE lanes: where a pixel's whole
// 3x3 window is on its surface (the smooth branch) and its normal is not degenerate, the same
// operations as sobel3_normal and oriented_normal, in the same order (glm's cross, dot, length and
// division by the length, std::max/min's choice between equal zeros), are written to out (4 floats per
// pixel) and its bit in the returned mask is set; the other pixels are left to the scalar kernel.
// up, mid, down: column 0 of the ring rows j - 1, j, j + 1 ((x, y, z, range) per column, two columns
// of zeros either side).
int sobel3_smooth4(const float* up, const float* mid, const float* down, std::int64_t x, float jump_rel, float* out) {
    // The (x, y, z, range) of columns x + o .. x + o + 3 of a row, as four vectors of lanes.
    struct Lanes {
        __m128 x, y, z, r;
    };
    auto load = [](const float* row, std::int64_t c) {
        __m128 a = _mm_loadu_ps(row + 4 * c), b = _mm_loadu_ps(row + 4 * c + 4), e = _mm_loadu_ps(row + 4 * c + 8),
               d = _mm_loadu_ps(row + 4 * c + 12);
        _MM_TRANSPOSE4_PS(a, b, e, d);
        return Lanes{a, b, e, d};
    };
    const Lanes lu = load(up, x - 1), cu = load(up, x), ru = load(up, x + 1);
    const Lanes lm = load(mid, x - 1), cm = load(mid, x), rm = load(mid, x + 1);
    const Lanes ld = load(down, x - 1), cd = load(down, x), rd = load(down, x + 1);
    const __m128 zero = _mm_setzero_ps();
    const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
    const __m128 jump = _mm_mul_ps(_mm_set1_ps(jump_rel), cm.r);
    auto same = [&](const Lanes& q) { // same_surface(q, p.range, jump)
        return _mm_and_ps(_mm_cmpgt_ps(q.r, zero), _mm_cmple_ps(_mm_and_ps(_mm_sub_ps(q.r, cm.r), abs_mask), jump));
    };
    __m128 ok = _mm_cmpgt_ps(cm.r, zero);
    ok = _mm_and_ps(ok, _mm_and_ps(_mm_and_ps(same(lu), same(lm)), _mm_and_ps(same(ld), same(cu))));
    ok = _mm_and_ps(ok, _mm_and_ps(_mm_and_ps(same(cd), same(ru)), _mm_and_ps(same(rm), same(rd))));
    if (_mm_movemask_ps(ok) == 0) return 0;
    const __m128 two = _mm_set1_ps(2.0f);
    // (a - b) + 2 (c - d) + (e - f), left to right
    auto tangent = [&](__m128 a, __m128 b, __m128 c, __m128 d, __m128 e, __m128 f) {
        return _mm_add_ps(_mm_add_ps(_mm_sub_ps(a, b), _mm_mul_ps(two, _mm_sub_ps(c, d))), _mm_sub_ps(e, f));
    };
    const __m128 txx = tangent(ru.x, lu.x, rm.x, lm.x, rd.x, ld.x), txy = tangent(ru.y, lu.y, rm.y, lm.y, rd.y, ld.y),
                 txz = tangent(ru.z, lu.z, rm.z, lm.z, rd.z, ld.z);
    const __m128 tyx = tangent(ld.x, lu.x, cd.x, cu.x, rd.x, ru.x), tyy = tangent(ld.y, lu.y, cd.y, cu.y, rd.y, ru.y),
                 tyz = tangent(ld.z, lu.z, cd.z, cu.z, rd.z, ru.z);
    // cross(tx, ty)
    __m128 nx = _mm_sub_ps(_mm_mul_ps(txy, tyz), _mm_mul_ps(tyy, txz));
    __m128 ny = _mm_sub_ps(_mm_mul_ps(txz, tyx), _mm_mul_ps(tyz, txx));
    __m128 nz = _mm_sub_ps(_mm_mul_ps(txx, tyy), _mm_mul_ps(tyx, txy));
    auto dot = [](__m128 ax, __m128 ay, __m128 az, __m128 bx, __m128 by, __m128 bz) {
        return _mm_add_ps(_mm_add_ps(_mm_mul_ps(ax, bx), _mm_mul_ps(ay, by)), _mm_mul_ps(az, bz));
    };
    const __m128 len = _mm_sqrt_ps(dot(nx, ny, nz, nx, ny, nz));
    ok = _mm_and_ps(ok, _mm_and_ps(_mm_cmpgt_ps(len, zero), _mm_cmplt_ps(len, _mm_set1_ps(1e30f))));
    const int mask = _mm_movemask_ps(ok);
    if (mask == 0) return 0;
    nx = _mm_div_ps(nx, len);
    ny = _mm_div_ps(ny, len);
    nz = _mm_div_ps(nz, len);
    const __m128 flip = _mm_and_ps(_mm_cmpgt_ps(dot(nx, ny, nz, cm.x, cm.y, cm.z), zero), _mm_set1_ps(-0.0f));
    nx = _mm_xor_ps(nx, flip);
    ny = _mm_xor_ps(ny, flip);
    nz = _mm_xor_ps(nz, flip);
    // incidence_cos: std::min(std::max(-d / r, 0), 1); std::max(a, b) is _mm_max_ps(b, a), min alike
    const __m128 d = dot(nx, ny, nz, cm.x, cm.y, cm.z);
    const __m128 cosine =
        _mm_min_ps(_mm_set1_ps(1.0f), _mm_max_ps(zero, _mm_div_ps(_mm_xor_ps(d, _mm_set1_ps(-0.0f)), cm.r)));
    __m128 o0 = nx, o1 = ny, o2 = nz, o3 = cosine;
    _MM_TRANSPOSE4_PS(o0, o1, o2, o3);
    _mm_storeu_ps(out, o0);
    _mm_storeu_ps(out + 4, o1);
    _mm_storeu_ps(out + 8, o2);
    _mm_storeu_ps(out + 12, o3);
    return mask;
}

#if defined(__x86_64__) && defined(__GNUC__)
// sobel3_smooth4 for the eight pixels x .. x + 7 in AVX lanes: the same operations lane by lane (helpers
// as functions: a target attribute does not reach a lambda).
#define VKS_AVX2_INLINE __attribute__((target("avx2"), always_inline)) inline
struct Lanes8 {
    __m256 x, y, z, r;
};
// The (x, y, z, range) of columns x + o .. x + o + 7 of a row (lanes in column order).
VKS_AVX2_INLINE Lanes8 load8(const float* row, std::int64_t c) {
    const float* p = row + 4 * c;
    // columns i and i + 4 in the two halves, then the 4 x 4 transpose within each half
    __m256 a = _mm256_loadu2_m128(p + 16, p), b = _mm256_loadu2_m128(p + 20, p + 4),
           e = _mm256_loadu2_m128(p + 24, p + 8), d = _mm256_loadu2_m128(p + 28, p + 12);
    const __m256 t0 = _mm256_unpacklo_ps(a, b), t1 = _mm256_unpackhi_ps(a, b), t2 = _mm256_unpacklo_ps(e, d),
                 t3 = _mm256_unpackhi_ps(e, d);
    a = _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(1, 0, 1, 0));
    b = _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(3, 2, 3, 2));
    e = _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(1, 0, 1, 0));
    d = _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(3, 2, 3, 2));
    return Lanes8{a, b, e, d};
}
// same_surface(q, p.range, jump)
VKS_AVX2_INLINE __m256 same8(const Lanes8& q, __m256 centre_r, __m256 jump) {
    const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
    return _mm256_and_ps(_mm256_cmp_ps(q.r, _mm256_setzero_ps(), _CMP_GT_OQ),
                         _mm256_cmp_ps(_mm256_and_ps(_mm256_sub_ps(q.r, centre_r), abs_mask), jump, _CMP_LE_OQ));
}
// (a - b) + 2 (c - d) + (e - f), left to right
VKS_AVX2_INLINE __m256 tangent8(__m256 a, __m256 b, __m256 c, __m256 d, __m256 e, __m256 f) {
    return _mm256_add_ps(_mm256_add_ps(_mm256_sub_ps(a, b), _mm256_mul_ps(_mm256_set1_ps(2.0f), _mm256_sub_ps(c, d))),
                         _mm256_sub_ps(e, f));
}
VKS_AVX2_INLINE __m256 dot8(__m256 ax, __m256 ay, __m256 az, __m256 bx, __m256 by, __m256 bz) {
    return _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(ax, bx), _mm256_mul_ps(ay, by)), _mm256_mul_ps(az, bz));
}

__attribute__((target("avx2"))) int sobel3_smooth8(const float* up, const float* mid, const float* down, std::int64_t x,
                                                   float jump_rel, float* out) {
    const Lanes8 lu = load8(up, x - 1), cu = load8(up, x), ru = load8(up, x + 1);
    const Lanes8 lm = load8(mid, x - 1), cm = load8(mid, x), rm = load8(mid, x + 1);
    const Lanes8 ld = load8(down, x - 1), cd = load8(down, x), rd = load8(down, x + 1);
    const __m256 zero = _mm256_setzero_ps();
    const __m256 jump = _mm256_mul_ps(_mm256_set1_ps(jump_rel), cm.r);
    __m256 ok = _mm256_cmp_ps(cm.r, zero, _CMP_GT_OQ);
    ok = _mm256_and_ps(ok, _mm256_and_ps(_mm256_and_ps(same8(lu, cm.r, jump), same8(lm, cm.r, jump)),
                                         _mm256_and_ps(same8(ld, cm.r, jump), same8(cu, cm.r, jump))));
    ok = _mm256_and_ps(ok, _mm256_and_ps(_mm256_and_ps(same8(cd, cm.r, jump), same8(ru, cm.r, jump)),
                                         _mm256_and_ps(same8(rm, cm.r, jump), same8(rd, cm.r, jump))));
    if (_mm256_movemask_ps(ok) == 0) return 0;
    const __m256 txx = tangent8(ru.x, lu.x, rm.x, lm.x, rd.x, ld.x), txy = tangent8(ru.y, lu.y, rm.y, lm.y, rd.y, ld.y),
                 txz = tangent8(ru.z, lu.z, rm.z, lm.z, rd.z, ld.z);
    const __m256 tyx = tangent8(ld.x, lu.x, cd.x, cu.x, rd.x, ru.x), tyy = tangent8(ld.y, lu.y, cd.y, cu.y, rd.y, ru.y),
                 tyz = tangent8(ld.z, lu.z, cd.z, cu.z, rd.z, ru.z);
    // cross(tx, ty)
    __m256 nx = _mm256_sub_ps(_mm256_mul_ps(txy, tyz), _mm256_mul_ps(tyy, txz));
    __m256 ny = _mm256_sub_ps(_mm256_mul_ps(txz, tyx), _mm256_mul_ps(tyz, txx));
    __m256 nz = _mm256_sub_ps(_mm256_mul_ps(txx, tyy), _mm256_mul_ps(tyx, txy));
    const __m256 len = _mm256_sqrt_ps(dot8(nx, ny, nz, nx, ny, nz));
    ok = _mm256_and_ps(
        ok, _mm256_and_ps(_mm256_cmp_ps(len, zero, _CMP_GT_OQ), _mm256_cmp_ps(len, _mm256_set1_ps(1e30f), _CMP_LT_OQ)));
    const int mask = _mm256_movemask_ps(ok);
    if (mask == 0) return 0;
    nx = _mm256_div_ps(nx, len);
    ny = _mm256_div_ps(ny, len);
    nz = _mm256_div_ps(nz, len);
    const __m256 flip =
        _mm256_and_ps(_mm256_cmp_ps(dot8(nx, ny, nz, cm.x, cm.y, cm.z), zero, _CMP_GT_OQ), _mm256_set1_ps(-0.0f));
    nx = _mm256_xor_ps(nx, flip);
    ny = _mm256_xor_ps(ny, flip);
    nz = _mm256_xor_ps(nz, flip);
    // incidence_cos: std::min(std::max(-d / r, 0), 1); std::max(a, b) is _mm256_max_ps(b, a), min alike
    const __m256 d = dot8(nx, ny, nz, cm.x, cm.y, cm.z);
    const __m256 cosine = _mm256_min_ps(
        _mm256_set1_ps(1.0f), _mm256_max_ps(zero, _mm256_div_ps(_mm256_xor_ps(d, _mm256_set1_ps(-0.0f)), cm.r)));
    // back to (nx, ny, nz, cos) per pixel: the 4 x 4 transpose within each half, then the halves apart
    const __m256 t0 = _mm256_unpacklo_ps(nx, ny), t1 = _mm256_unpackhi_ps(nx, ny), t2 = _mm256_unpacklo_ps(nz, cosine),
                 t3 = _mm256_unpackhi_ps(nz, cosine);
    const __m256 p0 = _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(1, 0, 1, 0)),
                 p1 = _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(3, 2, 3, 2)),
                 p2 = _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(1, 0, 1, 0)),
                 p3 = _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(3, 2, 3, 2));
    _mm256_storeu2_m128(out + 16, out, p0);
    _mm256_storeu2_m128(out + 20, out + 4, p1);
    _mm256_storeu2_m128(out + 24, out + 8, p2);
    _mm256_storeu2_m128(out + 28, out + 12, p3);
    return mask;
}
#undef VKS_AVX2_INLINE
#else
int sobel3_smooth8(const float*, const float*, const float*, std::int64_t, float, float*) {
    return 0;
}
#endif

} // namespace

std::size_t normals_scratch_count(const Plan& plan) {
    // per column: the ray at v = 0 (x, y, z; each row adds v times its view's down axis); five rows of (Px, Py, Pz, r)
    // (the 5x5 window of sobel5; sobel3 uses 3) and a row of zeros (the rows outside the image), each with two columns
    // of zeros either side (the columns outside the image)
    return static_cast<std::size_t>(plan.columns) * 3 + (kRingRows + 1) * (plan.columns + 4) * 4;
}

// The loops around the kernels of shaders/sonar_kernels.h (sobel3_normal, sobel5_normal) that
// normals.comp calls: positions are reconstructed once per pixel into a ring of five rows, from which
// each hit pixel's window is read. A miss reads as range 0 in the ring, and so does every position
// outside the image (the zero row and columns around it): no_sample(), without a bounds test.
template <class Real>
void normals_rows(const Plan& plan, const float* depth, float* normals4, Real* scratch, std::uint32_t row_begin,
                  std::uint32_t row_end, const std::uint8_t* view_drawn) {
    using M = Math<Real>;
    using Sample = typename M::Sample;
    using Column3 = typename M::Column3;
    using Column5 = typename M::Column5;
    const PixelGeometry<Real> geometry = pixel_geometry<Real>(plan);
    const Real jump_rel = static_cast<Real>(plan.params.edge_relative_jump);
    const std::int64_t C = plan.columns, R = plan.rows;
    const std::int64_t stride = (C + 4) * 4; // a ring row: columns -2 .. C + 1

    // pixel_ray per column at v = 0; a row adds v times its view's down axis (a slice's: (0, 0, -1), so
    // that its rays are (x, y, -v) exactly).
    Real* ray_x = scratch;
    Real* ray_y = scratch + C;
    Real* ray_z = scratch + 2 * C;
    Real* ring = scratch + 3 * C; // rows j % kRingRows, then the zero row
    Real* zero_row = ring + kRingRows * stride;
    std::fill(zero_row, zero_row + stride, Real(0));
    for (std::uint32_t s = 0; s < plan.views; ++s) { // a view's columns, its view looked up once
        const typename M::PixelView view = pixel_view<Real>(plan, s);
        const std::uint32_t first = view_first_column(plan, s), W = view_columns(plan, s);
        for (std::uint32_t x = 0; x < W; ++x) {
            const auto ray = M::pixel_ray(M::pixel_coord(x, W, view.tan_half_h), Real(0), view);
            ray_x[first + x] = ray.x;
            ray_y[first + x] = ray.y;
            ray_z[first + x] = ray.z;
        }
    }
    auto fill_row = [&](std::int64_t j) {
        Real* row = ring + (j % kRingRows) * stride;
        std::fill(row, row + 8, Real(0));
        std::fill(row + stride - 8, row + stride, Real(0));
        row += 8; // column 0
        const float* d = depth + j * C;
        for (std::uint32_t s = 0; s < plan.views; ++s) {
            const std::int64_t first = view_first_column(plan, s), end = first + view_columns(plan, s);
            if (view_drawn != nullptr && view_drawn[s] == 0) { // nothing drawn there: no hits
                std::fill(row + 4 * first, row + 4 * end, Real(0));
                continue;
            }
            const typename M::PixelView view = pixel_view<Real>(plan, s);
            const Real v =
                M::pixel_coord(static_cast<std::uint32_t>(j), static_cast<std::uint32_t>(R), view.tan_half_v);
            const typename M::vec3 step = v * view.down;
            std::int64_t c = first;
            if constexpr (std::is_same_v<Real, float>) {
                // Four pixels at a time: sample_at's operations lane by lane (z = a / (d - b), z times the
                // ray, the range as glm::length: sqrt((x x + y y) + z z)), zeros where there is no hit.
                const __m128 zero = _mm_setzero_ps(), a = _mm_set1_ps(geometry.depth_a),
                             b = _mm_set1_ps(geometry.depth_b);
                const __m128 sx = _mm_set1_ps(step.x), sy = _mm_set1_ps(step.y), sz = _mm_set1_ps(step.z);
                for (; c + 4 <= end; c += 4) {
                    const __m128 dv = _mm_loadu_ps(d + c);
                    const __m128 hit = _mm_cmpgt_ps(dv, zero);
                    __m128 px = zero, py = zero, pz = zero, range = zero;
                    if (_mm_movemask_ps(hit) != 0) {
                        const __m128 z = _mm_div_ps(a, _mm_sub_ps(dv, b));
                        px = _mm_and_ps(hit, _mm_mul_ps(z, _mm_add_ps(_mm_loadu_ps(ray_x + c), sx)));
                        py = _mm_and_ps(hit, _mm_mul_ps(z, _mm_add_ps(_mm_loadu_ps(ray_y + c), sy)));
                        pz = _mm_and_ps(hit, _mm_mul_ps(z, _mm_add_ps(_mm_loadu_ps(ray_z + c), sz)));
                        const __m128 length2 =
                            _mm_add_ps(_mm_add_ps(_mm_mul_ps(px, px), _mm_mul_ps(py, py)), _mm_mul_ps(pz, pz));
                        range = _mm_and_ps(hit, _mm_sqrt_ps(length2));
                    }
                    _MM_TRANSPOSE4_PS(px, py, pz, range);
                    Real* q = row + 4 * c;
                    _mm_storeu_ps(q, px);
                    _mm_storeu_ps(q + 4, py);
                    _mm_storeu_ps(q + 8, pz);
                    _mm_storeu_ps(q + 12, range);
                }
            }
            for (; c < end; ++c) {
                Real* q = row + 4 * c;
                if (d[c] > 0.0f) {
                    const Real z = M::view_z_from_depth(static_cast<Real>(d[c]), geometry.depth_a, geometry.depth_b);
                    const Sample p =
                        M::sample_at(z, typename M::vec3(ray_x[c] + step.x, ray_y[c] + step.y, ray_z[c] + step.z));
                    q[0] = p.pos.x;
                    q[1] = p.pos.y;
                    q[2] = p.pos.z;
                    q[3] = p.range;
                } else {
                    q[0] = q[1] = q[2] = q[3] = Real(0);
                }
            }
        }
    };
    // Column 0 of ring row j (of the zero row outside the image); a hit has a range > 0 (view z > 0).
    auto row_at = [&](std::int64_t j) -> const Real* {
        return (j < 0 || j >= R ? zero_row : ring + (j % kRingRows) * stride) + 8;
    };
    auto sample_at_column = [](const Real* row, std::int64_t c) -> Sample {
        const Real* q = row + 4 * c;
        return Sample{typename M::vec3(q[0], q[1], q[2]), q[3], q[3] > Real(0)};
    };
    auto store = [](float* out, const typename M::vec4& n) {
        out[0] = static_cast<float>(n.x);
        out[1] = static_cast<float>(n.y);
        out[2] = static_cast<float>(n.z);
        out[3] = static_cast<float>(n.w);
    };
    const bool sobel5 = plan.params.normal_method == shared::kNormalsSobel5;
    // With tier views, a window must not reach across a seam that does not join: only columns of the
    // centre's view_group (columns outside the image are zero columns anyway).
    const bool tiers = plan.views > plan.slices;
    const bool avx2 = use_avx2(plan.config); // sobel3_smooth8
    auto group = [&](std::int64_t c) {
        return view_group(plan, static_cast<std::uint32_t>(std::clamp<std::int64_t>(c, 0, C - 1)));
    };

    // The ring holds rows j-2 .. j+2 of the row being computed: those before the first row's j+2 first.
    for (std::int64_t j = std::max<std::int64_t>(std::int64_t(row_begin) - 2, 0);
         j < std::min<std::int64_t>(R, std::int64_t(row_begin) + 2); ++j)
        fill_row(j);
    for (std::int64_t j = row_begin; j < std::int64_t(row_end); ++j) {
        if (j + 2 < R) fill_row(j + 2);
        float* out_row = normals4 + 4 * j * C;
        const Real *up2 = row_at(j - 2), *up = row_at(j - 1), *mid = row_at(j), *down = row_at(j + 1),
                   *down2 = row_at(j + 2);
        auto pixel = [&](std::int64_t x) {
            if (!(mid[4 * x + 3] > Real(0))) { // no hit: no normal
                store(out_row + 4 * x, typename M::vec4(Real(0)));
                return;
            }
            // a neighbour column across a seam that does not join reads as the zero row (no sample)
            auto rows_of = [&](std::int64_t c, const Real* r) {
                return tiers && group(c) != group(x) ? zero_row + 8 : r;
            };
            auto sample = [&](const Real* r, std::int64_t c) { return sample_at_column(rows_of(c, r), c); };
            if (sobel5) {
                auto column5 = [&](std::int64_t c) {
                    return Column5{sample(up2, c), sample(up, c), sample(mid, c), sample(down, c), sample(down2, c)};
                };
                store(out_row + 4 * x, M::sobel5_normal(column5(x - 2), column5(x - 1), column5(x), column5(x + 1),
                                                        column5(x + 2), jump_rel));
            } else {
                auto column3 = [&](std::int64_t c) { return Column3{sample(up, c), sample(mid, c), sample(down, c)}; };
                store(out_row + 4 * x, M::sobel3_normal(column3(x - 1), column3(x), column3(x + 1), jump_rel));
            }
        };
        std::int64_t x = 0;
        std::uint32_t view_at = 0; // the view of column x
        auto first_of = [&](std::uint32_t view) -> std::int64_t {
            return view < plan.views ? view_first_column(plan, view) : C;
        };
        for (; x < C; ++x) {
            while (first_of(view_at + 1) <= x)
                ++view_at;
            if (view_drawn != nullptr && x == first_of(view_at) && view_drawn[view_at] == 0) { // an empty view
                const std::int64_t end = first_of(view_at + 1);
                std::fill(out_row + 4 * x, out_row + 4 * end, 0.0f);
                x = end - 1;
                continue;
            }
            // Four pixels without a hit (water above the seabed, a tier view's empty corner): no normals, and
            // no window to load (a third to a half of the default grid).
            if (x % 4 == 0 && x + 4 <= C && !(mid[4 * x + 3] > Real(0)) && !(mid[4 * x + 7] > Real(0)) &&
                !(mid[4 * x + 11] > Real(0)) && !(mid[4 * x + 15] > Real(0))) {
                std::fill(out_row + 4 * x, out_row + 4 * (x + 4), 0.0f);
                x += 3;
                continue;
            }
            if constexpr (std::is_same_v<Real, float>) {
                // Eight pixels at a time where the CPU has AVX2 and their windows are smooth
                // (sobel3_smooth8), else four (sobel3_smooth4), the others by the scalar kernel; the windows
                // of the last columns reach into the zero columns. True where it took pixels x .. x + lanes - 1
                // (x then stands on the last of them).
                auto smooth_run = [&](auto lanes, auto kernel) {
                    constexpr int kLanes = decltype(lanes)::value;
                    if (sobel5 || x % kLanes != 0 || x + kLanes > C || (tiers && group(x - 1) != group(x + kLanes)))
                        return false;
                    alignas(32) float fast[4 * kLanes];
                    const int done = kernel(up, mid, down, x, jump_rel, fast);
                    if (done == (1 << kLanes) - 1) { // all smooth (most runs)
                        std::memcpy(out_row + 4 * x, fast, sizeof fast);
                        x += kLanes - 1;
                        return true;
                    }
                    for (int i = 0; i < kLanes; ++i) {
                        if (done & (1 << i))
                            std::memcpy(out_row + 4 * (x + i), fast + 4 * i, 4 * sizeof(float));
                        else
                            pixel(x + i);
                    }
                    x += kLanes - 1;
                    return true;
                };
                if (avx2 && smooth_run(std::integral_constant<int, 8>{}, sobel3_smooth8)) continue;
                if (smooth_run(std::integral_constant<int, 4>{}, sobel3_smooth4)) continue;
            }
            pixel(x);
        }
    }
}

template <class Real>
void geometric_normals_rows(const Plan& plan, const float* depth, const float* face4, float* normals4,
                            std::uint32_t row_begin, std::uint32_t row_end) {
    using M = Math<Real>;
    const PixelGeometry<Real> geometry = pixel_geometry<Real>(plan);
    const std::uint32_t C = plan.columns, R = plan.rows;
    for (std::uint32_t j = row_begin; j < row_end; ++j) {
        for (std::uint32_t c = 0; c < C; ++c) {
            const std::size_t i = static_cast<std::size_t>(j) * C + c;
            float* out = normals4 + 4 * i;
            if (!(depth[i] > 0.0f)) {
                out[0] = out[1] = out[2] = out[3] = 0.0f;
                continue;
            }
            const std::uint32_t s = view_of_column(plan, c);
            const typename M::PixelView view = pixel_view<Real>(plan, s);
            const Real u = M::pixel_coord(c - view_first_column(plan, s), view_columns(plan, s), view.tan_half_h);
            const Real v = M::pixel_coord(j, R, view.tan_half_v);
            const Real z = M::view_z_from_depth(static_cast<Real>(depth[i]), geometry.depth_a, geometry.depth_b);
            const auto p = M::sample_at(z, M::pixel_ray(u, v, view));
            const float* q = face4 + 4 * i;
            const auto n = M::geometric_normal(p, typename M::vec3(q[0], q[1], q[2]), view);
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
template void normals_rows<float>(const Plan&, const float*, float*, float*, std::uint32_t, std::uint32_t,
                                  const std::uint8_t*);
template void normals_rows<double>(const Plan&, const float*, float*, double*, std::uint32_t, std::uint32_t,
                                   const std::uint8_t*);
template void geometric_normals<float>(const Plan&, const float*, const float*, float*);
template void geometric_normals<double>(const Plan&, const float*, const float*, float*);
template void normals<float>(const Plan&, const float*, float*);
template void normals<double>(const Plan&, const float*, float*);
template void normals<float>(const Plan&, const float*, float*, float*);
template void normals<double>(const Plan&, const float*, float*, double*);

} // namespace vksonar::cpu
