// CPU reference of the beamform stage (docs/pipeline.md §4): per-column range profiles (nearest,
// tent or footprint kernel), resampling of pixel columns onto the beam table, side-lobe convolution along beams.
// Every output cell is computed by one loop iteration with sums in increasing index order, so the
// result is deterministic (bit-identical run to run). Sums accumulate in Real; storage is float.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif
#include <type_traits>
#include <utility>
#include <vector>

#include "core/sonar_math.hpp"
#include "stages/cpu_simd.h"
#include "stages/cpu_stages.h"
#include "stages/pixel_spread.h"

namespace vksonar::cpu {

namespace {

// The accumulators of profile column c start at c * column_stride: its bins, then 16 values of padding,
// so that neighbouring columns' bins do not fall into the same cache sets (512 bins of floats are 2 KiB)
// and add_shares's four lanes past a column's last bin stay inside the column.
std::size_t column_stride(const Plan& plan) {
    return plan.bins + 16u;
}

// Four values of Real side by side (GCC's vector extension: one SSE register for float).
template <class Real> struct Lanes;
template <> struct Lanes<float> { typedef float type __attribute__((vector_size(16))); };
template <> struct Lanes<double> { typedef double type __attribute__((vector_size(32))); };

// column[i] += shares[i] * weighted for i < n, each the scalar loop's product and sum: four at a time
// where `weighted` is finite, the lanes past n adding +0 (for_each_spread_pixel pads shares with zeros;
// +0 leaves an accumulator as it is, since accumulators are sums of terms >= 0 and never -0; the
// column's padding takes what runs past its last bin), else one at a time.
template <class Real> inline void add_shares(Real* column, const Real* shares, int n, Real weighted) {
    if (std::isfinite(weighted)) {
        using V = typename Lanes<Real>::type;
        const V w = V{} + weighted;
        for (int i = 0; i < n; i += 4) {
            V share, sum;
            std::memcpy(&share, shares + i, sizeof share);
            std::memcpy(&sum, column + i, sizeof sum);
            sum += share * w;
            std::memcpy(column + i, &sum, sizeof sum);
        }
        return;
    }
    for (int i = 0; i < n; ++i)
        column[i] += shares[i] * weighted;
}

#if defined(__x86_64__) && defined(__GNUC__)
// The AVX2 helpers of this file's vector loops (functions, not lambdas: a target attribute does not reach
// a lambda).
#define VKS_AVX2_INLINE __attribute__((target("avx2,fma"), always_inline)) inline

// expf of eight floats: exp4 on either half.
VKS_AVX2_INLINE __m256 exp8(__m256 x) {
    return _mm256_set_m128(exp4(_mm256_cvtps_pd(_mm256_extractf128_ps(x, 1))),
                           exp4(_mm256_cvtps_pd(_mm256_castps256_ps128(x))));
}

// (low, low, low, low, high, high, high, high)
VKS_AVX2_INLINE __m256 halves8(float low, float high) {
    return _mm256_set_m128(_mm_set1_ps(high), _mm_set1_ps(low));
}

// footprint_share(lo, hi, centre, g, inv_norm, k) of eight lanes: the same operations lane by lane (no
// fused multiply-add), sinhc_of's series where |g half_len| < 0.5; 0 where bin k lies outside [lo, hi].
// False where a lane needs sinhc_of's other branch or an exponent outside exp4's range (share unset; the
// caller then computes the shares one by one).
VKS_AVX2_INLINE bool footprint_share8(__m256 lo, __m256 hi, __m256 centre, __m256 g, __m256 inv_norm, __m256i k,
                                      __m256& share) {
    const __m256 half = _mm256_set1_ps(0.5f), one = _mm256_set1_ps(1.0f);
    const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
    // max(lo, k), min(hi, k + 1): lo, hi are not NaN (range_spread); a signed zero changes no share
    const __m256 a = _mm256_max_ps(lo, _mm256_cvtepi32_ps(k));
    const __m256 b = _mm256_min_ps(hi, _mm256_cvtepi32_ps(_mm256_add_epi32(k, _mm256_set1_epi32(1))));
    const __m256 live = _mm256_cmp_ps(b, a, _CMP_GT_OQ);
    const __m256 len = _mm256_sub_ps(b, a);
    const __m256 half_len = _mm256_mul_ps(half, len);
    const __m256 arg = _mm256_and_ps(live, _mm256_mul_ps(g, _mm256_sub_ps(_mm256_add_ps(a, half_len), centre)));
    const __m256 y = _mm256_mul_ps(g, half_len);
    __m256 bad = _mm256_and_ps(live, _mm256_cmp_ps(_mm256_and_ps(y, abs_mask), half, _CMP_GE_OQ));
    bad = _mm256_or_ps(bad, _mm256_cmp_ps(_mm256_and_ps(arg, abs_mask), _mm256_set1_ps(80.0f), _CMP_GE_OQ));
    if (_mm256_movemask_ps(bad) != 0) return false;
    const __m256 e = exp8(arg);
    const __m256 y2 = _mm256_mul_ps(y, y);
    // 1 + y2 / 6 * (1 + y2 / 20 * (1 + y2 / 42)), as sinhc_of
    const __m256 inner = _mm256_add_ps(one, _mm256_div_ps(y2, _mm256_set1_ps(42.0f)));
    const __m256 middle = _mm256_add_ps(one, _mm256_mul_ps(_mm256_div_ps(y2, _mm256_set1_ps(20.0f)), inner));
    const __m256 sinhc = _mm256_add_ps(one, _mm256_mul_ps(_mm256_div_ps(y2, _mm256_set1_ps(6.0f)), middle));
    share = _mm256_and_ps(live, _mm256_mul_ps(_mm256_mul_ps(_mm256_mul_ps(len, e), sinhc), inv_norm));
    return true;
}

// The footprint shares of one spread's bins k_first + i, i < n, eight at a time (footprint_share8);
// shares has room for n rounded up to 8. False as footprint_share8.
__attribute__((target("avx2,fma"))) bool footprint_shares8(const Math<float>::RangeSpread& s, int n, float* shares) {
    const __m256 lo = halves8(s.lo, s.lo), hi = halves8(s.hi, s.hi), centre = halves8(s.centre, s.centre),
                 g = halves8(s.g, s.g), inv_norm = halves8(s.inv_norm, s.inv_norm);
    for (int i = 0; i < n; i += 8) {
        const __m256i k = _mm256_add_epi32(_mm256_set1_epi32(s.k_first + i), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
        __m256 share;
        if (!footprint_share8(lo, hi, centre, g, inv_norm, k, share)) return false;
        _mm256_storeu_ps(shares + i, share);
    }
    return true;
}

// The footprint shares of two spreads of at most four bins each (most pixels) in one pass: a's in the low
// four lanes, b's in the high four. shares_a and shares_b receive four values each (zeros past a
// spread's bins: there k + 1 > hi, so the lane is not live). False as footprint_share8.
__attribute__((target("avx2,fma"))) bool footprint_shares4x2(const Math<float>::RangeSpread& sa,
                                                             const Math<float>::RangeSpread& sb, float* shares_a,
                                                             float* shares_b) {
    const __m256i k = _mm256_add_epi32(_mm256_set_m128i(_mm_set1_epi32(sb.k_first), _mm_set1_epi32(sa.k_first)),
                                       _mm256_setr_epi32(0, 1, 2, 3, 0, 1, 2, 3));
    __m256 share;
    if (!footprint_share8(halves8(sa.lo, sb.lo), halves8(sa.hi, sb.hi), halves8(sa.centre, sb.centre),
                          halves8(sa.g, sb.g), halves8(sa.inv_norm, sb.inv_norm), k, share))
        return false;
    _mm_storeu_ps(shares_a, _mm256_castps256_ps128(share));
    _mm_storeu_ps(shares_b, _mm256_extractf128_ps(share, 1));
    return true;
}

// The five-row windows of eight pixels for footprint_spread8, lane by lane: each pixel's (energy, range)
// and those of the rows above (up2, up) and below (down, down2); (0, 0) outside the image.
constexpr int kSpreadLanes = 8;
struct SpreadLanes {
    alignas(32) float e[8], r[8], up2_e[8], up2_r[8], up_e[8], up_r[8], down_e[8], down_r[8], down2_e[8], down2_r[8],
        left_r[8], right_r[8];
};

// footprint_spread8's lane-wise helpers
VKS_AVX2_INLINE __m256 abs8(__m256 v) {
    return _mm256_andnot_ps(_mm256_set1_ps(-0.0f), v);
}
VKS_AVX2_INLINE __m256 neg8(__m256 v) {
    return _mm256_xor_ps(v, _mm256_set1_ps(-0.0f));
}
VKS_AVX2_INLINE __m256 select8(__m256 mask, __m256 a, __m256 b) {
    return _mm256_or_ps(_mm256_and_ps(mask, a), _mm256_andnot_ps(mask, b));
}
// std::min(p, q) = (q < p) ? q : p = _mm256_min_ps(q, p); std::max(p, q) = (p < q) ? q : p = _mm256_max_ps(q, p)
VKS_AVX2_INLINE __m256 min8(__m256 p, __m256 q) {
    return _mm256_min_ps(q, p);
}
VKS_AVX2_INLINE __m256 max8(__m256 p, __m256 q) {
    return _mm256_max_ps(q, p);
}
VKS_AVX2_INLINE __m256 steps_agree8(__m256 s, __m256 t) {
    const __m256 zero = _mm256_setzero_ps(), two = _mm256_set1_ps(2.0f);
    const __m256 as = abs8(s), at = abs8(t);
    return _mm256_and_ps(_mm256_and_ps(_mm256_cmp_ps(_mm256_mul_ps(s, t), zero, _CMP_GT_OQ),
                                       _mm256_cmp_ps(as, _mm256_mul_ps(two, at), _CMP_LE_OQ)),
                         _mm256_cmp_ps(at, _mm256_mul_ps(two, as), _CMP_LE_OQ));
}
// footprint_edge_offset of the pixels at ranges r
VKS_AVX2_INLINE __m256 edge_offset8(__m256 r, float jump_rel, __m256 r_q, __m256 r_beyond, __m256 r_opposite) {
    const __m256 zero = _mm256_setzero_ps();
    const __m256 s = _mm256_sub_ps(r_q, r);
    const __m256 same = _mm256_or_ps(
        _mm256_or_ps(
            _mm256_cmp_ps(abs8(s), _mm256_mul_ps(_mm256_set1_ps(jump_rel), r), _CMP_LE_OQ),
            _mm256_and_ps(_mm256_cmp_ps(r_beyond, zero, _CMP_GT_OQ), steps_agree8(s, _mm256_sub_ps(r_beyond, r_q)))),
        _mm256_and_ps(_mm256_cmp_ps(r_opposite, zero, _CMP_GT_OQ), steps_agree8(s, _mm256_sub_ps(r, r_opposite))));
    return _mm256_and_ps(_mm256_and_ps(_mm256_cmp_ps(r_q, zero, _CMP_GT_OQ), same),
                         _mm256_mul_ps(_mm256_set1_ps(0.5f), s));
}
// footprint_missing_edge of the pixels at ranges r
VKS_AVX2_INLINE __m256 missing_edge8(__m256 r, __m256 other, __m256 r_near, __m256 r_beyond) {
    const __m256 zero = _mm256_setzero_ps();
    const __m256 s = _mm256_sub_ps(r_near, r), t = _mm256_sub_ps(r_beyond, r_near);
    const __m256 scaled =
        _mm256_and_ps(_mm256_and_ps(_mm256_cmp_ps(other, zero, _CMP_NEQ_UQ), _mm256_cmp_ps(r_beyond, zero, _CMP_GT_OQ)),
                      steps_agree8(s, t));
    return select8(scaled, _mm256_mul_ps(neg8(other), _mm256_div_ps(s, t)), neg8(other));
}

// range_spread with the footprint kernel (float) for eight pixels as AVX lanes: the same operations in
// the same order (std::min/max's choices between equal values kept, logf per lane, exp as exp4, which
// matches expf here), into out[0..7]. False where a pixel's bin coordinate is NaN (the caller then uses
// the scalar kernel).
__attribute__((target("avx2,fma"))) bool footprint_spread8(const SpreadLanes& in, float range_min, float ibw,
                                                           float jump_rel, int bins, Math<float>::RangeSpread* out) {
    const __m256 zero = _mm256_setzero_ps(), half = _mm256_set1_ps(0.5f), one = _mm256_set1_ps(1.0f),
                 two = _mm256_set1_ps(2.0f);
    const __m256 vibw = _mm256_set1_ps(ibw);
    const __m256 r = _mm256_load_ps(in.r), up2_r = _mm256_load_ps(in.up2_r), up_r = _mm256_load_ps(in.up_r),
                 down_r = _mm256_load_ps(in.down_r), down2_r = _mm256_load_ps(in.down2_r);
    const __m256 x = _mm256_mul_ps(_mm256_sub_ps(r, _mm256_set1_ps(range_min)), vibw); // range_bin_coord
    if (_mm256_movemask_ps(_mm256_cmp_ps(x, x, _CMP_UNORD_Q)) != 0) return false;
    const __m256 a = edge_offset8(r, jump_rel, up_r, up2_r, down_r),
                 b = edge_offset8(r, jump_rel, down_r, down2_r, up_r);
    // (only where a lane lacks a side: inside a surface every pixel has both, and the division is not free)
    __m256 a2 = a, b2 = b;
    if (_mm256_movemask_ps(_mm256_or_ps(_mm256_cmp_ps(a, zero, _CMP_EQ_OQ), _mm256_cmp_ps(b, zero, _CMP_EQ_OQ))) != 0) {
        a2 = select8(_mm256_cmp_ps(a, zero, _CMP_NEQ_UQ), a, missing_edge8(r, b, down_r, down2_r));
        b2 = select8(_mm256_cmp_ps(b, zero, _CMP_NEQ_UQ), b, missing_edge8(r, a, up_r, up2_r));
    }
    const __m256 xl = _mm256_add_ps(x, _mm256_mul_ps(min8(min8(a2, b2), zero), vibw)); // footprint_lo
    const __m256 xh = _mm256_add_ps(x, _mm256_mul_ps(max8(max8(a2, b2), zero), vibw)); // footprint_hi
    // footprint_across: the extent along the row, from the left and right neighbours (none beyond them)
    const __m256 left_r = _mm256_load_ps(in.left_r), right_r = _mm256_load_ps(in.right_r);
    const __m256 al = edge_offset8(r, jump_rel, left_r, zero, right_r),
                 ar = edge_offset8(r, jump_rel, right_r, zero, left_r);
    const __m256 al2 = select8(_mm256_cmp_ps(al, zero, _CMP_NEQ_UQ), al, neg8(ar)),
                 ar2 = select8(_mm256_cmp_ps(ar, zero, _CMP_NEQ_UQ), ar, neg8(al));
    const __m256 cl = _mm256_mul_ps(min8(min8(al2, ar2), zero), vibw),
                 ch = _mm256_mul_ps(max8(max8(al2, ar2), zero), vibw);
    const __m256 column_centre = _mm256_mul_ps(half, _mm256_add_ps(xl, xh));
    const __m256 centre = _mm256_add_ps(column_centre, _mm256_mul_ps(half, _mm256_add_ps(cl, ch)));
    const __m256 w_down_column = _mm256_sub_ps(xh, xl), w_across = _mm256_sub_ps(ch, cl);
    const __m256 extent =
        _mm256_sqrt_ps(_mm256_add_ps(_mm256_mul_ps(w_down_column, w_down_column), _mm256_mul_ps(w_across, w_across)));
    const __m256 width = min8(
        select8(_mm256_cmp_ps(extent, zero, _CMP_GT_OQ), max8(extent, _mm256_set1_ps(shared::kMinFootprintBins)), one),
        _mm256_set1_ps(shared::kMaxFootprintBins));
    const __m256 lo = _mm256_sub_ps(centre, _mm256_mul_ps(half, width)),
                 hi = _mm256_add_ps(centre, _mm256_mul_ps(half, width));
    // the density's slope (footprint_log_slope) where both neighbours' footprints are on this surface
    const __m256 w_up = _mm256_mul_ps(_mm256_mul_ps(half, abs8(_mm256_sub_ps(up2_r, r))), vibw);
    const __m256 w_down = _mm256_mul_ps(_mm256_mul_ps(half, abs8(_mm256_sub_ps(r, down2_r))), vibw);
    const __m256 span =
        _mm256_mul_ps(_mm256_add_ps(_mm256_mul_ps(two, _mm256_sub_ps(up_r, down_r)), _mm256_sub_ps(up2_r, down2_r)),
                      _mm256_set1_ps(0.25f * ibw));
    const __m256 e_up = _mm256_load_ps(in.up_e), e_down = _mm256_load_ps(in.down_e);
    // footprint_log_slope's arguments: both sides (up against down), or with one side only that side's
    // neighbour q against this pixel's own footprint
    const __m256 up_side = _mm256_and_ps(_mm256_cmp_ps(a, zero, _CMP_NEQ_UQ), _mm256_cmp_ps(up2_r, zero, _CMP_GT_OQ));
    const __m256 down_side =
        _mm256_and_ps(_mm256_cmp_ps(b, zero, _CMP_NEQ_UQ), _mm256_cmp_ps(down2_r, zero, _CMP_GT_OQ));
    const __m256 both = _mm256_and_ps(up_side, down_side);
    const __m256 r_q = select8(up_side, up_r, down_r), r_q2 = select8(up_side, up2_r, down2_r);
    const __m256 e_q = select8(up_side, e_up, e_down);
    const __m256 w_q = _mm256_mul_ps(_mm256_mul_ps(half, abs8(_mm256_sub_ps(r_q2, r))), vibw);
    const __m256 span_q = _mm256_sub_ps(
        _mm256_mul_ps(_mm256_sub_ps(_mm256_mul_ps(_mm256_add_ps(_mm256_add_ps(r, _mm256_mul_ps(two, r_q)), r_q2),
                                                  _mm256_set1_ps(0.25f)),
                                    r),
                      vibw),
        _mm256_sub_ps(column_centre, x));
    const __m256 e_self = _mm256_load_ps(in.e), w_self = _mm256_sub_ps(xh, xl);
    const __m256 e1 = select8(both, e_up, e_q), w1 = select8(both, w_up, w_q);
    const __m256 e2 = select8(both, e_down, e_self), w2 = select8(both, w_down, w_self);
    const __m256 slope_span = select8(both, span, span_q);
    __m256 has_g = _mm256_or_ps(up_side, down_side);
    has_g = _mm256_and_ps(
        has_g, _mm256_and_ps(_mm256_and_ps(_mm256_cmp_ps(e1, zero, _CMP_GT_OQ), _mm256_cmp_ps(e2, zero, _CMP_GT_OQ)),
                             _mm256_and_ps(_mm256_cmp_ps(w1, zero, _CMP_GT_OQ), _mm256_cmp_ps(w2, zero, _CMP_GT_OQ))));
    has_g = _mm256_and_ps(has_g, _mm256_cmp_ps(abs8(slope_span), zero, _CMP_GT_OQ));
    const int g_mask = _mm256_movemask_ps(has_g);
    __m256 g = zero;
    if (g_mask != 0) {
        // logf of the density ratio where there is a slope (of 1 elsewhere: 0, where the scalar kernel
        // leaves g 0): log4 where every lane is in its domain and this libm's logf is log4's, else per lane
        const __m256 ratio = select8(has_g, _mm256_div_ps(_mm256_mul_ps(e1, w2), _mm256_mul_ps(e2, w1)), one);
        const __m128 ratio_lo = _mm256_castps256_ps128(ratio), ratio_hi = _mm256_extractf128_ps(ratio, 1);
        __m256 log_ratio;
        if (_mm_movemask_ps(_mm_and_ps(positive_normal4(ratio_lo), positive_normal4(ratio_hi))) == 15 &&
            log4_matches_logf()) {
            log_ratio = _mm256_set_m128(log4(ratio_hi), log4(ratio_lo));
        } else {
            alignas(32) float lanes[8];
            _mm256_store_ps(lanes, ratio);
            for (int l = 0; l < 8; ++l)
                lanes[l] = (g_mask & (1 << l)) ? std::log(lanes[l]) : 0.0f;
            log_ratio = _mm256_load_ps(lanes);
        }
        const __m256 slope = _mm256_div_ps(_mm256_and_ps(has_g, log_ratio), slope_span);
        const __m256 cap = min8(one, _mm256_div_ps(_mm256_set1_ps(8.0f), width));
        g = _mm256_and_ps(has_g, min8(max8(slope, neg8(cap)), cap));
    }
    // inv_norm = 1 / (width sinhc_of(0.5 g width))
    const __m256 y = _mm256_mul_ps(_mm256_mul_ps(half, g), width);
    const __m256 y2 = _mm256_mul_ps(y, y);
    const __m256 inner = _mm256_add_ps(one, _mm256_div_ps(y2, _mm256_set1_ps(42.0f)));
    const __m256 middle = _mm256_add_ps(one, _mm256_mul_ps(_mm256_div_ps(y2, _mm256_set1_ps(20.0f)), inner));
    __m256 sinhc = _mm256_add_ps(one, _mm256_mul_ps(_mm256_div_ps(y2, _mm256_set1_ps(6.0f)), middle));
    const __m256 wide = _mm256_cmp_ps(abs8(y), half, _CMP_GE_OQ); // NaN-free: g and width are finite
    if (_mm256_movemask_ps(wide) != 0) {
        const __m256 ey = exp8(y), e_minus = exp8(neg8(y));
        sinhc = select8(wide, _mm256_div_ps(_mm256_sub_ps(ey, e_minus), _mm256_mul_ps(two, y)), sinhc);
    }
    const __m256 inv_norm = _mm256_div_ps(one, _mm256_mul_ps(width, sinhc));
    alignas(32) float lo_l[8], hi_l[8], centre_l[8], g_l[8], inv_l[8];
    alignas(32) std::int32_t first_l[8], last_l[8];
    _mm256_store_ps(lo_l, lo);
    _mm256_store_ps(hi_l, hi);
    _mm256_store_ps(centre_l, centre);
    _mm256_store_ps(g_l, g);
    _mm256_store_ps(inv_l, inv_norm);
    _mm256_store_si256(reinterpret_cast<__m256i*>(first_l), _mm256_cvttps_epi32(_mm256_floor_ps(lo)));
    _mm256_store_si256(reinterpret_cast<__m256i*>(last_l), _mm256_cvttps_epi32(_mm256_floor_ps(hi)));
    for (int l = 0; l < 8; ++l) {
        Math<float>::RangeSpread& o = out[l];
        o.kernel = shared::kRangeKernelFootprint;
        o.k_first = std::max(first_l[l], 0);
        o.k_last = std::min(last_l[l], bins - 1);
        o.tent_k0 = 0;
        o.tent_w1 = 0.0f;
        o.lo = lo_l[l];
        o.hi = hi_l[l];
        o.centre = centre_l[l];
        o.g = g_l[l];
        o.inv_norm = inv_l[l];
    }
    return true;
}
#undef VKS_AVX2_INLINE

#else
constexpr int kSpreadLanes = 8;
struct SpreadLanes {
    float e[8], r[8], up2_e[8], up2_r[8], up_e[8], up_r[8], down_e[8], down_r[8], down2_e[8], down2_r[8], left_r[8],
        right_r[8];
};
bool footprint_spread8(const SpreadLanes&, float, float, float, int, Math<float>::RangeSpread*) {
    return false;
}
bool footprint_shares8(const Math<float>::RangeSpread&, int, float*) {
    return false;
}
bool footprint_shares4x2(const Math<float>::RangeSpread&, const Math<float>::RangeSpread&, float*, float*) {
    return false;
}
#endif

// The shares of bins k_first + i, i < n (<= kMaxSpreadBins), as range_share gives them; shares has room
// for kMaxSpreadBins rounded up to 8 (kSharesRoom). The footprint kernel's in float go eight at a time
// through footprint_shares8 where exp4 matches expf: the same values, computed as footprint_share does.
constexpr int kMaxSpreadBins = static_cast<int>(shared::kMaxFootprintBins) + 2;
constexpr int kSharesRoom = (kMaxSpreadBins + 7) / 8 * 8;

template <class Real>
[[gnu::always_inline]] inline void range_shares(const typename Math<Real>::RangeSpread& s, int n, bool exp4,
                                                Real* shares) {
    using M = Math<Real>;
    if constexpr (std::is_same_v<Real, float>) {
        if (exp4 && s.kernel == shared::kRangeKernelFootprint && footprint_shares8(s, n, shares)) return;
    }
    for (int i = 0; i < n; ++i)
        shares[i] = M::range_share(s, s.k_first + i);
}

// The spreads of up to kSpreadLanes (8) hit pixels (row j, columns c[0 .. n)) into out: eight at a time
// through footprint_spread8 where the kernel is the footprint in float and exp4 matches expf (a batch of
// fewer than eight repeats its last pixel), else pixel_spread one by one. The same spreads either way. The pixels
// lie in one view, columns [view.first, view.end), where the caller knows it (view.end > 0); else each
// pixel's view is looked up.
struct ViewColumns {
    std::uint32_t first = 0, end = 0;
};
template <class Real>
void pixel_spreads(const Plan& plan, const float* echo2, std::uint32_t j, const std::uint32_t* c, int n, bool exp4,
                   Real range_min, Real inv_bin_width, ViewColumns view, typename Math<Real>::RangeSpread* out) {
    auto across_of = [&](std::uint32_t col) {
        return view.end > 0 ? row_neighbours_within(plan, echo2, j, col, view.first, view.end)
                            : row_neighbours(plan, echo2, j, col);
    };
    if constexpr (std::is_same_v<Real, float>) {
        if (exp4 && plan.params.range_kernel == shared::kRangeKernelFootprint) {
            const std::uint32_t C = plan.columns, R = plan.rows;
            SpreadLanes in;
#if defined(__x86_64__) && defined(__GNUC__)
            if (n == kSpreadLanes && c[7] == c[0] + 7 && view.end > 0) {
                // Eight neighbouring pixels (most batches): each row's (e, r) pairs by four vector loads,
                // and the row neighbours from the centre row's ranges; the same values as the loop below.
                const std::int64_t jj = j;
                auto row_lanes = [&](std::int64_t row, float* e, float* r) {
                    if (row < 0 || row >= static_cast<std::int64_t>(R)) {
                        std::fill(e, e + kSpreadLanes, 0.0f);
                        std::fill(r, r + kSpreadLanes, 0.0f);
                        return;
                    }
                    const float* q = echo2 + 2 * (static_cast<std::size_t>(row) * C + c[0]);
                    for (int half = 0; half < 2; ++half, q += 8) {
                        const __m128 a = _mm_loadu_ps(q), b = _mm_loadu_ps(q + 4);
                        _mm_store_ps(e + 4 * half, _mm_shuffle_ps(a, b, _MM_SHUFFLE(2, 0, 2, 0)));
                        _mm_store_ps(r + 4 * half, _mm_shuffle_ps(a, b, _MM_SHUFFLE(3, 1, 3, 1)));
                    }
                };
                row_lanes(jj, in.e, in.r);
                row_lanes(jj - 2, in.up2_e, in.up2_r);
                row_lanes(jj - 1, in.up_e, in.up_r);
                row_lanes(jj + 1, in.down_e, in.down_r);
                row_lanes(jj + 2, in.down2_e, in.down2_r);
                const float* p = echo2 + 2 * (static_cast<std::size_t>(j) * C + c[0]);
                in.left_r[0] = c[0] > view.first ? p[-1] : 0.0f;
                in.right_r[7] = c[7] + 1 < view.end ? p[17] : 0.0f;
                for (int l = 0; l < 7; ++l) {
                    in.left_r[l + 1] = in.r[l];
                    in.right_r[l] = in.r[l + 1];
                }
                if (footprint_spread8(in, range_min, inv_bin_width, static_cast<float>(plan.params.edge_relative_jump),
                                      static_cast<int>(plan.bins), out))
                    return;
            }
#endif
            for (int l = 0; l < kSpreadLanes; ++l) {
                const std::uint32_t col = c[std::min(l, n - 1)];
                auto row = [&](std::int64_t jj, float* e, float* r) {
                    const bool inside = jj >= 0 && jj < static_cast<std::int64_t>(R);
                    const float* q = echo2 + 2 * (static_cast<std::size_t>(inside ? jj : 0) * C + col);
                    e[l] = inside ? q[0] : 0.0f;
                    r[l] = inside ? q[1] : 0.0f;
                };
                const std::int64_t jj = j;
                row(jj, in.e, in.r);
                row(jj - 2, in.up2_e, in.up2_r);
                row(jj - 1, in.up_e, in.up_r);
                row(jj + 1, in.down_e, in.down_r);
                row(jj + 2, in.down2_e, in.down2_r);
                const RowNeighbours across = across_of(col);
                in.left_r[l] = across.left_r;
                in.right_r[l] = across.right_r;
            }
            if (footprint_spread8(in, range_min, inv_bin_width, static_cast<float>(plan.params.edge_relative_jump),
                                  static_cast<int>(plan.bins), out))
                return;
        }
    }
    for (int l = 0; l < n; ++l) {
        const Real e = static_cast<Real>(echo2[2 * (static_cast<std::size_t>(j) * plan.columns + c[l])]);
        out[l] = pixel_spread<Real>(plan, echo2, j, c[l], e, across_of(c[l]), range_min, inv_bin_width);
    }
}

// Every hit pixel of row j in columns [column_begin, column_end), in increasing column order, with its
// range shares: sink(c, e, spread, spread_bins, shares; zeros past spread_bins up to a multiple of 4),
// the spreads made eight pixels at a time (pixel_spreads) and their shares by range_shares. Both profile
// layouts (planar and cone columns) add through it; `view`: the one view the columns lie in, if known
// (pixel_spreads).
template <class Real, class Sink>
void for_each_spread_pixel(const Plan& plan, const float* echo2, std::uint32_t j, std::uint32_t column_begin,
                           std::uint32_t column_end, bool exp4, Real range_min, Real inv_bin_width, ViewColumns view,
                           const Sink& sink) {
    const float* e2 = echo2 + 2 * static_cast<std::size_t>(j) * plan.columns;
    std::uint32_t batch[kSpreadLanes];
    int batched = 0;
    auto flush = [&] {
        typename Math<Real>::RangeSpread spreads[kSpreadLanes];
        pixel_spreads<Real>(plan, echo2, j, batch, batched, exp4, range_min, inv_bin_width, view, spreads);
        auto bins_of = [&](int b) { return std::min(spreads[b].k_last - spreads[b].k_first + 1, kMaxSpreadBins); };
        for (int b = 0; b < batched; ++b) {
            const typename Math<Real>::RangeSpread& spread = spreads[b];
            const int spread_bins = bins_of(b);
            if constexpr (std::is_same_v<Real, float>) {
                // two neighbours of one to four footprint bins each (most pixels): their shares in one pass
                if (exp4 && b + 1 < batched && spread.kernel == shared::kRangeKernelFootprint &&
                    spreads[b + 1].kernel == shared::kRangeKernelFootprint && spread_bins >= 1 && spread_bins <= 4 &&
                    bins_of(b + 1) >= 1 && bins_of(b + 1) <= 4) {
                    float shares_a[4], shares_b[4];
                    if (footprint_shares4x2(spread, spreads[b + 1], shares_a, shares_b)) {
                        sink(batch[b], e2[2 * batch[b]], spread, spread_bins, shares_a);
                        sink(batch[b + 1], e2[2 * batch[b + 1]], spreads[b + 1], bins_of(b + 1), shares_b);
                        ++b;
                        continue;
                    }
                }
            }
            Real shares[kSharesRoom];
            range_shares<Real>(spread, spread_bins, exp4, shares);
            for (int i = std::max(spread_bins, 0); i % 4 != 0; ++i) // zeros up to a multiple of 4 (add_shares)
                shares[i] = Real(0);
            sink(batch[b], static_cast<Real>(e2[2 * batch[b]]), spread, spread_bins, shares);
        }
        batched = 0;
    };
    for (std::uint32_t c = column_begin; c < column_end; ++c) {
        if (!(static_cast<Real>(e2[2 * c]) > Real(0))) continue;
        batch[batched++] = c;
        if (batched == kSpreadLanes) flush();
    }
    if (batched > 0) flush();
}

// line_array: the pixel columns [first, second) of row j and view `view` that feed cone columns
// [cone_begin, cone_end): those within one column of them, x in (cone_begin - 1, cone_end). Along a
// view's row the cone coordinate increases with the column (plan_cone_table).
std::pair<std::uint32_t, std::uint32_t> cone_span(const Plan& plan, std::uint32_t j, std::uint32_t view,
                                                  std::uint32_t cone_begin, std::uint32_t cone_end) {
    const float* cone_x = plan.pixel_cone_coord.data() + static_cast<std::size_t>(j) * plan.columns;
    const float lo = static_cast<float>(cone_begin) - 1.0f, hi = static_cast<float>(cone_end);
    const float* first = cone_x + view_first_column(plan, view);
    const float* last = first + view_columns(plan, view);
    const std::uint32_t c_begin = static_cast<std::uint32_t>(std::upper_bound(first, last, lo) - cone_x);
    const std::uint32_t c_end =
        static_cast<std::uint32_t>(std::find_if(cone_x + c_begin, last, [hi](float x) { return !(x < hi); }) - cone_x);
    return {c_begin, c_end};
}

// line_array: the profiles of cone columns [cone_begin, cone_end) (acc: column_stride per column).
// Each pixel goes to the cone columns its cone coordinate falls between (plan.pixel_cone_coord), by
// cone_share, its range spread as in the planar profile. Every accumulator receives its additions rows
// first, then by increasing pixel column, then bin: the order of profile.comp's gather. spans: the
// block's cone_spans (cone_column_spans), or null to search each row for them.
template <class Real>
void cone_profiles(const Plan& plan, const float* echo2, Real* acc, std::uint32_t cone_begin, std::uint32_t cone_end,
                   Real range_min, Real inv_bin_width, const std::uint8_t* view_drawn, const std::uint32_t* spans) {
    using M = Math<Real>;
    const std::uint32_t C = plan.columns, R = plan.rows, bins = plan.bins;
    const std::size_t T = column_stride(plan);
    const int count = static_cast<int>(plan.profile_columns);
    const bool exp4 = use_exp4(plan.config);
    for (std::uint32_t j = 0; j < R && bins > 0; ++j) {
        const float* cone_x = plan.pixel_cone_coord.data() + static_cast<std::size_t>(j) * C;
        // each view's pixels that feed these cone columns (the views follow each other in column order,
        // as profile.comp gathers them)
        for (std::uint32_t view = 0; view < plan.views; ++view) {
            if (view_drawn != nullptr && view_drawn[view] == 0) continue; // nothing drawn there
            const std::uint32_t view_first = view_first_column(plan, view);
            const ViewColumns columns{view_first, view_first + view_columns(plan, view)};
            const std::size_t at = 2 * (static_cast<std::size_t>(j) * plan.views + view);
            const auto [c_begin, c_end] =
                spans != nullptr ? std::pair{spans[at], spans[at + 1]} : cone_span(plan, j, view, cone_begin, cone_end);
            for_each_spread_pixel<Real>(
                plan, echo2, j, c_begin, c_end, exp4, range_min, inv_bin_width, columns,
                [&](std::uint32_t pc, Real e, const typename M::RangeSpread& spread, int spread_bins,
                    const Real* shares) {
                    const int k_first = spread.k_first;
                    const Real x = static_cast<Real>(cone_x[pc]);
                    const int first_cone = std::max(static_cast<int>(std::floor(x)), static_cast<int>(cone_begin));
                    const int last_cone = std::min(static_cast<int>(std::floor(x)) + 1, static_cast<int>(cone_end) - 1);
                    // The range shares once for both cone columns (a footprint spans <= kMaxFootprintBins + 1 bins).
                    for (int cone = first_cone; cone <= last_cone; ++cone) {
                        const Real weight = M::cone_share(x, cone, count);
                        if (!(weight > Real(0))) continue;
                        add_shares(acc + static_cast<std::size_t>(cone) * T + k_first, shares, spread_bins, weight * e);
                    }
                });
        }
    }
}

} // namespace

void spread_row_pixels(const Plan& plan, const float* echo2, std::uint32_t row, std::uint32_t column_begin,
                       std::uint32_t column_end, std::uint32_t view_first, std::uint32_t view_end, SpreadPixelFn fn,
                       void* context) {
    if (plan.bins == 0) return;
    for_each_spread_pixel<float>(plan, echo2, row, column_begin, column_end, use_exp4(plan.config),
                                 plan.params.range_min_m, plan.params.inv_bin_width_m,
                                 ViewColumns{view_first, view_end},
                                 [&](std::uint32_t c, float, const Math<float>::RangeSpread& spread, int spread_bins,
                                     const float* shares) { fn(context, c, spread, spread_bins, shares); });
}

namespace {

// The weight beam j gives column c in the resample (resample_share of shaders/sonar_math.h).
template <class Real> Real resample_weight(const Plan& plan, std::uint32_t j, std::uint32_t c) {
    const std::uint32_t share = Math<Real>::resample_share(plan.column_beam[c], j, plan.beams, plan.circular);
    const Real cw = static_cast<Real>(plan.column_weight[c]);
    return share == 1 ? cw : (share == 2 ? Real(1) - cw : Real(0));
}

#if defined(__x86_64__) && defined(__GNUC__)
// Eight registers of eight lanes, s[b] lane l, as eight rows of eight: out[l * stride + b] = s[b][l].
__attribute__((target("avx2"), always_inline)) inline void store_transposed8(const __m256 (&s)[8], float* out,
                                                                             std::size_t stride) {
    const __m256 a0 = _mm256_unpacklo_ps(s[0], s[1]), a1 = _mm256_unpackhi_ps(s[0], s[1]);
    const __m256 a2 = _mm256_unpacklo_ps(s[2], s[3]), a3 = _mm256_unpackhi_ps(s[2], s[3]);
    const __m256 a4 = _mm256_unpacklo_ps(s[4], s[5]), a5 = _mm256_unpackhi_ps(s[4], s[5]);
    const __m256 a6 = _mm256_unpacklo_ps(s[6], s[7]), a7 = _mm256_unpackhi_ps(s[6], s[7]);
    const __m256 b0 = _mm256_shuffle_ps(a0, a2, _MM_SHUFFLE(1, 0, 1, 0));
    const __m256 b1 = _mm256_shuffle_ps(a0, a2, _MM_SHUFFLE(3, 2, 3, 2));
    const __m256 b2 = _mm256_shuffle_ps(a1, a3, _MM_SHUFFLE(1, 0, 1, 0));
    const __m256 b3 = _mm256_shuffle_ps(a1, a3, _MM_SHUFFLE(3, 2, 3, 2));
    const __m256 b4 = _mm256_shuffle_ps(a4, a6, _MM_SHUFFLE(1, 0, 1, 0));
    const __m256 b5 = _mm256_shuffle_ps(a4, a6, _MM_SHUFFLE(3, 2, 3, 2));
    const __m256 b6 = _mm256_shuffle_ps(a5, a7, _MM_SHUFFLE(1, 0, 1, 0));
    const __m256 b7 = _mm256_shuffle_ps(a5, a7, _MM_SHUFFLE(3, 2, 3, 2));
    _mm256_storeu_ps(out, _mm256_permute2f128_ps(b0, b4, 0x20));
    _mm256_storeu_ps(out + stride, _mm256_permute2f128_ps(b1, b5, 0x20));
    _mm256_storeu_ps(out + 2 * stride, _mm256_permute2f128_ps(b2, b6, 0x20));
    _mm256_storeu_ps(out + 3 * stride, _mm256_permute2f128_ps(b3, b7, 0x20));
    _mm256_storeu_ps(out + 4 * stride, _mm256_permute2f128_ps(b0, b4, 0x31));
    _mm256_storeu_ps(out + 5 * stride, _mm256_permute2f128_ps(b1, b5, 0x31));
    _mm256_storeu_ps(out + 6 * stride, _mm256_permute2f128_ps(b2, b6, 0x31));
    _mm256_storeu_ps(out + 7 * stride, _mm256_permute2f128_ps(b3, b7, 0x31));
}

// Beam j's eight sums: its columns' weights from w on (w then moves past them).
__attribute__((target("avx2"), always_inline)) inline __m256
resample_sum8(const Plan& plan, const float* acc_k0, std::size_t T, std::uint32_t j, const float*& w) {
    __m256 sum = _mm256_setzero_ps();
    const std::uint32_t c_begin = plan.beam_column_begin[j], c_end = plan.beam_column_end[j];
    for (std::uint32_t c = c_begin; c < c_end; ++c)
        sum = _mm256_add_ps(sum, _mm256_mul_ps(_mm256_set1_ps(w[c - c_begin]),
                                               _mm256_loadu_ps(acc_k0 + static_cast<std::size_t>(c) * T)));
    w += c_end - c_begin;
    return sum;
}
// resample_bins's block of eight bins k0 .. k0 + 7 in float, eight beams at a time: each beam's eight sums
// as the lanes of one AVX register (the same products added in the same order; no FMA, -ffp-contract=off:
// the same floats), the eight beams' registers transposed so that each bin row takes eight beams in
// one store. Beams past the last multiple of eight are stored lane by lane.
__attribute__((target("avx2"))) void resample_block8(const Plan& plan, const float* acc, const float* weights,
                                                     float* beam_profiles, std::uint32_t k0) {
    const std::uint32_t beams = plan.beams;
    const std::size_t T = column_stride(plan);
    const float* w = weights;
    const float* acc_k0 = acc + k0;
    std::uint32_t j = 0;
    for (; j + 8 <= beams; j += 8) {
        __m256 s[8];
        for (std::uint32_t b = 0; b < 8; ++b)
            s[b] = resample_sum8(plan, acc_k0, T, j + b, w);
        store_transposed8(s, beam_profiles + static_cast<std::size_t>(k0) * beams + j, beams);
    }
    for (; j < beams; ++j) {
        float lanes[8];
        _mm256_storeu_ps(lanes, resample_sum8(plan, acc_k0, T, j, w));
        for (std::uint32_t l = 0; l < 8; ++l)
            beam_profiles[static_cast<std::size_t>(k0 + l) * beams + j] = lanes[l];
    }
}
#else
void resample_block8(const Plan&, const float*, const float*, float*, std::uint32_t) {}
#endif

// resample: one cell per (beam j, bin k), columns in increasing order, from the accumulators (rounded
// to float first: the values the profiles hold). Beam j's weights are weights[offset_j + c -
// beam_column_begin[j]], offset_j the sum of the earlier beams' column counts (resample_weights). Eight
// bins are summed side by side, each its own sum in the same order (eight independent chains).
template <class Real>
void resample_bins(const Plan& plan, const Real* acc, const Real* weights, float* beam_profiles,
                   std::uint32_t bin_begin, std::uint32_t bin_end) {
    constexpr std::uint32_t kBlock = 8;
    const std::uint32_t beams = plan.beams;
    const std::size_t T = column_stride(plan);
    std::uint32_t k0 = bin_begin;
    auto block = [&](auto n_constant) {
        constexpr std::uint32_t n = decltype(n_constant)::value;
        const Real* w = weights;
        for (std::uint32_t j = 0; j < beams; ++j) {
            Real sum[n];
            for (std::uint32_t l = 0; l < n; ++l)
                sum[l] = Real(0);
            const std::uint32_t c_begin = plan.beam_column_begin[j], c_end = plan.beam_column_end[j];
            for (std::uint32_t c = c_begin; c < c_end; ++c) {
                const Real wc = w[c - c_begin];
                const Real* column = acc + static_cast<std::size_t>(c) * T + k0;
                for (std::uint32_t l = 0; l < n; ++l)
                    sum[l] += wc * static_cast<Real>(static_cast<float>(column[l]));
            }
            w += c_end - c_begin;
            for (std::uint32_t l = 0; l < n; ++l)
                beam_profiles[static_cast<std::size_t>(k0 + l) * beams + j] = static_cast<float>(sum[l]);
        }
    };
    const bool avx2 = std::is_same_v<Real, float> && use_avx2(plan.config);
    for (; k0 + kBlock <= bin_end; k0 += kBlock) {
        if constexpr (std::is_same_v<Real, float>) {
            if (avx2) {
                resample_block8(plan, acc, weights, beam_profiles, k0);
                continue;
            }
        }
        block(std::integral_constant<std::uint32_t, kBlock>());
    }
    for (; k0 < bin_end; ++k0)
        block(std::integral_constant<std::uint32_t, 1>());
}

// Far side lobes (plan.h far_cells), for kFarRows range bins at a time: each beam's energy into its
// two cells per channel (far_deposit_weight), rounded to float as far_sidelobe.comp stores it, then
// the cells convolved with far_weight. Every (channel, cell, bin) sum runs over beams, then cells, in
// increasing order, as the shader's; the bins side by side are independent sums (vectorized).
constexpr std::uint32_t kFarRows = 8;

template <class Real> struct FarRows {
    std::array<Real, 3 * shared::kMaxFarCells * kFarRows> energy; // [(m * cells + c) * kFarRows + row]
    std::array<float, 3 * shared::kMaxFarCells * kFarRows> level; // the convolved cells, same layout
};

template <class Real> typename Math<Real>::vec4 far_table_vec4(const Plan& plan, std::int64_t j, std::size_t offset) {
    const float* b = plan.far_beam_cell.data() + 8 * j + offset;
    return typename Math<Real>::vec4(b[0], b[1], b[2], b[3]);
}

// A beam's far side-lobe values, as the kernels compute them from Plan::far_beam_cell, made once per plan
// (after the resample weights): its two cells c0, c1, their shares s0, s1 (far_cell_share), its phase
// (cos, sin), and per channel m its deposit weights into c0 and c1 (far_deposit_weight).
constexpr std::size_t kFarBeamValues = 12;
enum FarBeam : std::size_t { kFarC0, kFarC1, kFarS0, kFarS1, kFarCos, kFarSin, kFarDeposit };

// kFarRows values of Real side by side, one per bin row of a batch (GCC's vector extension).
template <class Real> struct FarLanes { typedef Real type __attribute__((vector_size(kFarRows * sizeof(Real)))); };

// One channel's cells convolved with the far weights (w[a - b]: cell b into cell a), four cells a at a
// time, the batch's rows side by side: 4 x kFarRows independent sums, each over the live cells b
// (live[0, n), offset by `base` in energy's channel order) in increasing order. level: the channel's cells.
template <class Real>
[[gnu::always_inline]] inline void far_convolve_cells(const float* w, const Real* energy, const std::uint16_t* live,
                                                      std::size_t n, std::uint32_t base, std::uint32_t cells,
                                                      float* level) {
    using V = typename FarLanes<Real>::type;
    for (std::uint32_t a = 0; a < cells; a += 4) {
        V sum[4] = {};
        for (std::size_t i = 0; i < n; ++i) {
            const std::uint32_t b = live[i] - base;
            V e;
            std::memcpy(&e, energy + std::size_t(live[i]) * kFarRows, sizeof e);
            for (std::uint32_t q = 0; q < 4; ++q)
                sum[q] += static_cast<Real>(*(w + std::min(a + q, cells - 1) - b)) * e;
        }
        for (std::uint32_t q = 0; q < 4 && a + q < cells; ++q)
            for (std::uint32_t r = 0; r < kFarRows; ++r)
                level[(a + q) * kFarRows + r] = static_cast<float>(sum[q][r]);
    }
}
// In float also as an AVX2 build (a batch's eight rows in one register): the same operations.
__attribute__((target_clones("avx2", "default"))) void far_convolve(const float* w, const float* energy,
                                                                    const std::uint16_t* live, std::size_t n,
                                                                    std::uint32_t base, std::uint32_t cells,
                                                                    float* level) {
    far_convolve_cells<float>(w, energy, live, n, base, cells, level);
}
void far_convolve(const float* w, const double* energy, const std::uint16_t* live, std::size_t n, std::uint32_t base,
                  std::uint32_t cells, float* level) {
    far_convolve_cells<double>(w, energy, live, n, base, cells, level);
}

// far_sidelobe_rows's deposit: each beam's energy in the batch's rows (bins k0 + r, r < rows) into its two
// cells per channel, scattered per beam with the rows side by side: each cell still takes its beams in
// increasing order in every row (the shader gathers per cell). A beam of zero energy in a row adds exactly
// +-0 there, which leaves the sum as it is (a sum that starts at +0 is never -0). The sums of the two
// cells the last beam fed are held in registers (per channel) and written back when a beam feeds another
// cell: the same additions in the same order, without a load and store per addition (consecutive beams
// share cells). The channel count is a constant, so that they stay in registers. energy: FarRows::energy,
// zeroed.
template <class Real, std::uint32_t kChannels>
[[gnu::always_inline]] inline void far_deposit_rows(const Real* far_beam, const float* beam_profiles, std::uint32_t k0,
                                                    std::uint32_t rows, std::uint32_t beams, std::uint32_t cells,
                                                    Real* energy_cells) {
    using V = typename FarLanes<Real>::type; // the batch's rows, lane r: bin k0 + r
    constexpr std::uint32_t kNone = ~0u;
    auto cell_at = [&](std::uint32_t m, std::uint32_t c) { return energy_cells + (m * cells + c) * kFarRows; };
    // (out parameters: a V is a value wider than the default build's registers, which a lambda must not return)
    auto load = [](V& v, const Real* p) { std::memcpy(&v, p, sizeof v); };
    auto store = [](Real* p, const V& v) { std::memcpy(p, &v, sizeof v); };
    std::uint32_t ca = kNone, cb = kNone; // the cells held: ca in sa, cb in sb
    V sa[kChannels] = {}, sb[kChannels] = {};
    for (std::uint32_t i = 0; i < beams; ++i) {
        V energy = {};
        bool any = false;
        for (std::uint32_t r = 0; r < rows; ++r) {
            energy[r] = static_cast<Real>(beam_profiles[static_cast<std::size_t>(k0 + r) * beams + i]);
            any = any || energy[r] != Real(0);
        }
        if (!any) continue;
        const Real* f = far_beam + std::size_t(i) * kFarBeamValues;
        const auto c0 = static_cast<std::uint32_t>(f[kFarC0]), c1 = static_cast<std::uint32_t>(f[kFarC1]);
        if (c0 != ca || c1 != cb) { // c0 != c1 (plan_far_sidelobes)
            V na[kChannels], nb[kChannels];
            for (std::uint32_t m = 0; m < kChannels; ++m) {
                if (ca != kNone && ca != c0 && ca != c1) store(cell_at(m, ca), sa[m]);
                if (cb != kNone && cb != c0 && cb != c1) store(cell_at(m, cb), sb[m]);
            }
            for (std::uint32_t m = 0; m < kChannels; ++m) {
                if (c0 == ca || c0 == cb)
                    na[m] = c0 == ca ? sa[m] : sb[m];
                else
                    load(na[m], cell_at(m, c0));
                if (c1 == ca || c1 == cb)
                    nb[m] = c1 == ca ? sa[m] : sb[m];
                else
                    load(nb[m], cell_at(m, c1));
            }
            for (std::uint32_t m = 0; m < kChannels; ++m) {
                sa[m] = na[m];
                sb[m] = nb[m];
            }
            ca = c0;
            cb = c1;
        }
        for (std::uint32_t m = 0; m < kChannels; ++m) {
            sa[m] += f[kFarDeposit + 2 * m] * energy;
            sb[m] += f[kFarDeposit + 2 * m + 1] * energy;
        }
    }
    for (std::uint32_t m = 0; m < kChannels && ca != kNone; ++m) {
        store(cell_at(m, ca), sa[m]);
        store(cell_at(m, cb), sb[m]);
    }
}
// far_deposit_rows with the plan's channel count (3 or 1) as the constant.
template <class Real>
[[gnu::always_inline]] inline void
far_deposit_channels(const Real* far_beam, const float* beam_profiles, std::uint32_t k0, std::uint32_t rows,
                     std::uint32_t beams, std::uint32_t cells, std::uint32_t channels, Real* energy_cells) {
    if (channels == 3)
        far_deposit_rows<Real, 3>(far_beam, beam_profiles, k0, rows, beams, cells, energy_cells);
    else
        far_deposit_rows<Real, 1>(far_beam, beam_profiles, k0, rows, beams, cells, energy_cells);
}
// In float also as an AVX2 build, where a batch's eight rows are one register and the six sums held
// (three channels) no longer spill: the same operations.
__attribute__((target_clones("avx2", "default"))) void far_deposit(const float* far_beam, const float* beam_profiles,
                                                                   std::uint32_t k0, std::uint32_t rows,
                                                                   std::uint32_t beams, std::uint32_t cells,
                                                                   std::uint32_t channels, float* energy_cells) {
    far_deposit_channels<float>(far_beam, beam_profiles, k0, rows, beams, cells, channels, energy_cells);
}
void far_deposit(const double* far_beam, const float* beam_profiles, std::uint32_t k0, std::uint32_t rows,
                 std::uint32_t beams, std::uint32_t cells, std::uint32_t channels, double* energy_cells) {
    far_deposit_channels<double>(far_beam, beam_profiles, k0, rows, beams, cells, channels, energy_cells);
}

template <class Real>
void far_sidelobe_rows(const Plan& plan, const Real* far_beam, const float* beam_profiles, std::uint32_t k0,
                       std::uint32_t rows, FarRows<Real>& far) {
    const std::uint32_t cells = plan.far_cells, channels = plan.far_channels, beams = plan.beams;
    const std::size_t used = std::size_t(channels) * cells * kFarRows;
    std::fill(far.energy.begin(), far.energy.begin() + used, Real(0));
    far_deposit(far_beam, beam_profiles, k0, rows, beams, cells, channels, far.energy.data());
    // Cells with no energy in any of the rows are left out of the convolution: each would add exactly
    // +-0 to sums that start at +0 (the weights are finite).
    std::array<std::uint16_t, 3 * shared::kMaxFarCells> live;
    std::size_t live_count = 0;
    for (std::size_t mb = 0; mb < std::size_t(channels) * cells; ++mb) {
        bool any = false;
        for (std::uint32_t r = 0; r < kFarRows; ++r) {
            Real& e = far.energy[mb * kFarRows + r];
            e = static_cast<Real>(static_cast<float>(e));
            any = any || e != Real(0);
        }
        if (any) live[live_count++] = static_cast<std::uint16_t>(mb);
    }
    const float* w = plan.far_weight.data() + (cells - 1); // w[a - b]: cell b into cell a
    for (std::uint32_t m = 0; m < channels; ++m) {
        std::size_t first = 0, end = 0; // the live cells of channel m: live[first, end)
        while (first < live_count && live[first] < m * cells)
            ++first;
        end = first;
        while (end < live_count && live[end] < (m + 1) * cells)
            ++end;
        far_convolve(w, far.energy.data(), live.data() + first, end - first, m * cells, cells,
                     far.level.data() + std::size_t(m) * cells * kFarRows);
    }
}
// The far side lobes of a batch's rows k0 + r, r < rows, for beamform_beams's float group loop:
// far_sidelobe_level of every beam written into polar's rows (polar_k0: row k0), to which the loop then
// adds the convolution's sums. A beam's batch rows lie side by side in FarRows::level, so a beam is one
// vector of kFarRows lanes, and each lane takes far_at's operations in its order (per channel s0 level(c0)
// + s1 level(c1), then l0 - cos l1 - sin l2, then max(x, 0) as (x < 0) ? 0 : x): the same floats. Also
// as an AVX2 build (a beam's eight rows in one register).
__attribute__((target_clones("avx2", "default"))) void far_values_into_rows(const float* far_beam, const float* level,
                                                                            std::uint32_t channels, std::uint32_t cells,
                                                                            std::uint32_t beams, std::uint32_t rows,
                                                                            float* polar_k0) {
    using V = FarLanes<float>::type;
    for (std::uint32_t j = 0; j < beams; ++j) {
        const float* f = far_beam + std::size_t(j) * kFarBeamValues;
        const auto c0 = static_cast<std::uint32_t>(f[kFarC0]), c1 = static_cast<std::uint32_t>(f[kFarC1]);
        V l[3] = {};
        for (std::uint32_t m = 0; m < channels; ++m) {
            V v0, v1;
            std::memcpy(&v0, level + (std::size_t(m) * cells + c0) * kFarRows, sizeof v0);
            std::memcpy(&v1, level + (std::size_t(m) * cells + c1) * kFarRows, sizeof v1);
            l[m] = f[kFarS0] * v0 + f[kFarS1] * v1;
        }
        const V x = l[0] - f[kFarCos] * l[1] - f[kFarSin] * l[2];
        const V value = x < V{} ? V{} : x;
        for (std::uint32_t r = 0; r < rows; ++r)
            polar_k0[std::size_t(r) * beams + j] = value[r];
    }
}

} // namespace

namespace {

std::size_t column_weight_count(const Plan& plan) {
    std::size_t n = 0;
    for (std::uint32_t j = 0; j < plan.beams; ++j)
        n += plan.beam_column_end[j] - plan.beam_column_begin[j];
    return n;
}

std::size_t far_beam_count(const Plan& plan) {
    return plan.far_cells > 0 ? std::size_t(plan.beams) * kFarBeamValues : 0;
}

// The side-lobe convolution's beams in groups of four, j = 4 q + lane: beamform_beams sums a group's
// four beams as the lanes of one vector, from a copy of the bin row padded by K beams either side (zeros,
// or the wrapped beams with plan.circular) so that every tap reads inside it. Their weights, made once
// per plan, are stored per group tap by tap, the four beams' weights of tap t side by side:
// [q][t][lane] (0 for the lanes past the last beam). Not made for a row of more than kMaxPaddedRow beams
// with its padding, nor with cpu.vector_loops off: those take the scalar loop.
constexpr std::size_t kMaxPaddedRow = 8192;

std::size_t sidelobe_group_count(const Plan& plan) {
    if (!plan.effects.horizontal_pattern || plan.config.cpu_vector_loops == CpuVectorLoops::off) return 0;
    const std::size_t K = (plan.sidelobe_taps - 1) / 2;
    if (plan.beams + 2 * K + 4 > kMaxPaddedRow) return 0;
    return (plan.beams + 3) / 4;
}

} // namespace

std::size_t resample_weight_count(const Plan& plan) {
    return column_weight_count(plan) + far_beam_count(plan) + sidelobe_group_count(plan) * 4 * plan.sidelobe_taps;
}

template <class Real> void resample_weights(const Plan& plan, Real* weights) {
    using M = Math<Real>;
    for (std::uint32_t j = 0; j < plan.beams; ++j)
        for (std::uint32_t c = plan.beam_column_begin[j]; c < plan.beam_column_end[j]; ++c)
            *weights++ = resample_weight<Real>(plan, j, c);
    for (std::uint32_t j = 0; j < plan.beams && plan.far_cells > 0; ++j) { // FarBeam, the values the kernels give
        const typename M::vec4 bc = far_table_vec4<Real>(plan, j, 0), phase = far_table_vec4<Real>(plan, j, 4);
        const auto c0 = static_cast<std::uint32_t>(bc.x), c1 = static_cast<std::uint32_t>(bc.y);
        Real* f = weights + std::size_t(j) * kFarBeamValues;
        f[0] = static_cast<Real>(c0);
        f[1] = static_cast<Real>(c1);
        f[2] = M::far_cell_share(bc, c0);
        f[3] = M::far_cell_share(bc, c1);
        f[4] = phase.x;
        f[5] = phase.y;
        for (std::uint32_t m = 0; m < 3; ++m) {
            f[6 + 2 * m] = M::far_deposit_weight(bc, phase, c0, m);
            f[7 + 2 * m] = M::far_deposit_weight(bc, phase, c1, m);
        }
    }
    weights += far_beam_count(plan);
    const std::uint32_t taps = plan.sidelobe_taps;
    for (std::size_t q = 0; q < sidelobe_group_count(plan); ++q)
        for (std::uint32_t t = 0; t < taps; ++t)
            for (std::uint32_t l = 0; l < 4; ++l) {
                const std::size_t j = 4 * q + l;
                *weights++ = j < plan.beams ? static_cast<Real>(plan.sidelobe_weight[j * taps + t]) : Real(0);
            }
}

namespace {

// The sub-pixel returns of profile columns [column_begin, column_end) that the depth image does not hide,
// each into the two bins of the tent kernel at its range (sonar_kernels.h; profile.comp's add_subpixel):
// per column in list order, after the column's pixels.
template <class Real>
void add_subpixel_returns(const Plan& plan, const SubpixelInput& in, Real* acc, std::uint32_t column_begin,
                          std::uint32_t column_end, Real range_min, Real inv_bin_width) {
    using M = Math<Real>;
    const std::size_t T = column_stride(plan);
    Real depth_a, depth_b;
    if constexpr (std::is_same_v<Real, float>) {
        depth_a = plan.params.depth_a;
        depth_b = plan.params.depth_b;
    } else {
        depth_a = plan.depth_a;
        depth_b = plan.depth_b;
    }
    const std::uint32_t* begin = in.returns.column_begin();
    const shared::SubpixelReturn* returns = in.returns.returns();
    const typename M::vec2 none(Real(0), Real(0));
    for (std::uint32_t c = column_begin; c < column_end; ++c) {
        for (std::uint32_t i = begin[c]; i < begin[c + 1]; ++i) {
            const shared::SubpixelReturn& r = returns[i];
            if (!M::subpixel_visible(static_cast<Real>(in.depth[r.pixel]), in.material[r.pixel],
                                     plan.subpixel_silent_material, static_cast<Real>(r.view_z), depth_a, depth_b))
                continue;
            const Real e = static_cast<Real>(r.energy);
            const typename M::RangeSpread spread =
                M::range_spread(shared::kRangeKernelTent, none, none, typename M::vec2(e, static_cast<Real>(r.range_m)),
                                none, none, Real(0), Real(0), range_min, inv_bin_width, Real(0), plan.bins);
            for (int k = spread.k_first; k <= spread.k_last; ++k)
                acc[static_cast<std::size_t>(c) * T + k] += M::range_share(spread, k) * e;
        }
    }
}

} // namespace

template <class Real>
void beamform_profiles(const Plan& plan, const float* echo2, float* profiles, Real* acc, std::uint32_t column_begin,
                       std::uint32_t column_end, const SubpixelInput* subpixel, const std::uint8_t* view_drawn,
                       const std::uint32_t* cone_spans) {
    const std::uint32_t C = plan.profile_columns, R = plan.rows, bins = plan.bins;
    const std::size_t T = column_stride(plan);
    Real range_min, inv_bin_width;
    if constexpr (std::is_same_v<Real, float>) {
        range_min = plan.params.range_min_m;
        inv_bin_width = plan.params.inv_bin_width_m;
    } else {
        range_min = plan.config.range_min_m;
        inv_bin_width = Real(1) / plan.bin_width_m;
    }

    // profile: per column, rows in increasing order, each pixel spread by range_spread / range_share
    // (shaders/sonar_kernels.h, as profile.comp). The loops run row-major for locality; every
    // accumulator (bin k, column c) still receives its additions in increasing row order (and, within
    // a row, in increasing bin order), so the sums are the per-column sums of the contract.
    std::fill(acc + column_begin * T, acc + column_end * T, Real(0));
    const bool exp4 = use_exp4(plan.config);
    if (plan.line_array) {
        cone_profiles<Real>(plan, echo2, acc, column_begin, column_end, range_min, inv_bin_width, view_drawn,
                            cone_spans);
    } else {
        for (std::uint32_t j = 0; j < R && bins > 0; ++j)
            for_each_spread_pixel<Real>(
                plan, echo2, j, column_begin, column_end, exp4, range_min, inv_bin_width, ViewColumns{},
                [&](std::uint32_t c, Real e, const typename Math<Real>::RangeSpread& spread, int spread_bins,
                    const Real* shares) {
                    add_shares(acc + static_cast<std::size_t>(c) * T + spread.k_first, shares, spread_bins, e);
                });
    }
    if (subpixel != nullptr && subpixel->returns.count() > 0)
        add_subpixel_returns<Real>(plan, *subpixel, acc, column_begin, column_end, range_min, inv_bin_width);
    if (profiles == nullptr) return;
    for (std::uint32_t c = column_begin; c < column_end; ++c)
        for (std::size_t k = 0; k < bins; ++k)
            profiles[k * C + c] = static_cast<float>(acc[c * T + k]);
}

namespace {

#if defined(__x86_64__) && defined(__GNUC__)
// The side-lobe sums of one run of four groups (16 beams) for one or two bin rows (row1 null: one), as
// beamform_beams's float loop makes them, two groups per AVX register: lanes 0-3 group g, 4-7 group
// g + 1, each lane the same products added in the same (increasing t) order, no FMA in this target, so
// the same floats. sums[r][4 g + l]: row r, beam j0 + 4 g + l; row0, row1 at the run's first beam
// (padded rows: beam j0 + 4 g + l takes row[t + 4 g + l]).
__attribute__((target("avx2"))) void sidelobe_run8(const float* wq, std::uint32_t taps, const float* row0,
                                                   const float* row1, std::uint32_t t_begin, std::uint32_t t_end,
                                                   float (&sums)[2][16]) {
    __m256 s0a = _mm256_setzero_ps(), s0b = s0a, s1a = s0a, s1b = s0a; // row r, groups 0-1 (a) and 2-3 (b)
    // group g's weights at tap t: w[g][t]; groups g and g + 1 side by side in one register
    const float* w0 = wq + std::size_t(t_begin) * 4;
    const std::size_t group = std::size_t(taps) * 4;
    for (std::uint32_t t = t_begin; t < t_end; ++t, w0 += 4) {
        const __m256 wa = _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(w0)), _mm_loadu_ps(w0 + group), 1);
        const __m256 wb =
            _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(w0 + 2 * group)), _mm_loadu_ps(w0 + 3 * group), 1);
        s0a = _mm256_add_ps(s0a, _mm256_mul_ps(wa, _mm256_loadu_ps(row0 + t)));
        s0b = _mm256_add_ps(s0b, _mm256_mul_ps(wb, _mm256_loadu_ps(row0 + t + 8)));
        if (row1 != nullptr) { // the same in every iteration: the compiler unswitches the loop
            s1a = _mm256_add_ps(s1a, _mm256_mul_ps(wa, _mm256_loadu_ps(row1 + t)));
            s1b = _mm256_add_ps(s1b, _mm256_mul_ps(wb, _mm256_loadu_ps(row1 + t + 8)));
        }
    }
    _mm256_storeu_ps(sums[0], s0a);
    _mm256_storeu_ps(sums[0] + 8, s0b);
    _mm256_storeu_ps(sums[1], s1a);
    _mm256_storeu_ps(sums[1] + 8, s1b);
}
#else
void sidelobe_run8(const float*, std::uint32_t, const float*, const float*, std::uint32_t, std::uint32_t,
                   float (&)[2][16]) {}
#endif

} // namespace

template <class Real>
void beamform_beams(const Plan& plan, const Real* acc, const Real* resample_w, float* beam_profiles, float* polar,
                    std::uint32_t bin_begin, std::uint32_t bin_end) {
    using M = Math<Real>;
    const std::uint32_t beams = plan.beams;
    resample_bins<Real>(plan, acc, resample_w, beam_profiles, bin_begin, bin_end);

    // sidelobe: polar(j) = sum_t weight[j][t] B(j - K + t), or a copy when the pattern is off.
    if (!plan.effects.horizontal_pattern) {
        std::copy(beam_profiles + std::size_t(bin_begin) * beams, beam_profiles + std::size_t(bin_end) * beams,
                  polar + std::size_t(bin_begin) * beams);
        return;
    }
    const std::uint32_t taps = plan.sidelobe_taps;
    const std::int64_t K = (static_cast<std::int64_t>(taps) - 1) / 2;
    const std::int64_t nb = beams;
    const float* weights = plan.sidelobe_weight.data();
    const std::uint32_t* tap_begin = plan.sidelobe_tap_begin.data();
    const std::uint32_t* tap_end = plan.sidelobe_tap_end.data();
    // Far side lobes (plan.h far_cells), kFarRows bins at a time (far_sidelobe_rows); each output adds
    // far_sidelobe_level of its two cells (sidelobe.comp).
    const std::uint32_t cells = plan.far_cells, channels = plan.far_channels;
    FarRows<Real> far;
    std::uint32_t far_first = bin_begin;                           // the first bin of the batch `far` holds
    const Real* far_beam = resample_w + column_weight_count(plan); // FarBeam values per beam
    const Real* group_weights = far_beam + far_beam_count(plan);   // sidelobe_group_count's weights
    const std::size_t groups = sidelobe_group_count(plan);
    auto far_at = [&](std::int64_t j, std::uint32_t k) -> Real {
        if (cells == 0) return Real(0);
        const Real* f = far_beam + std::size_t(j) * kFarBeamValues;
        const auto c0 = static_cast<std::uint32_t>(f[kFarC0]), c1 = static_cast<std::uint32_t>(f[kFarC1]);
        const std::uint32_t r = k - far_first;
        Real l[3] = {Real(0), Real(0), Real(0)};
        for (std::uint32_t m = 0; m < channels; ++m)
            l[m] = f[kFarS0] * static_cast<Real>(far.level[(m * cells + c0) * kFarRows + r]) +
                   f[kFarS1] * static_cast<Real>(far.level[(m * cells + c1) * kFarRows + r]);
        return M::far_sidelobe_level(typename M::vec4(f[kFarCos], f[kFarSin], Real(0), Real(0)), l[0], l[1], l[2]);
    };
    auto empty_row = [&](const float* row) { return std::all_of(row, row + beams, [](float b) { return b == 0.0f; }); };
    using V = typename Lanes<Real>::type;
    float padded[2][kMaxPaddedRow]; // padded[r][i]: beam i - K of the r-th row of a pair
    const bool avx2 = use_avx2(plan.config);
    for (std::uint32_t k = bin_begin; k < bin_end;) {
        if (cells > 0 && (k == bin_begin || k - far_first == kFarRows)) {
            far_first = k;
            const std::uint32_t rows = std::min(kFarRows, bin_end - k);
            far_sidelobe_rows<Real>(plan, far_beam, beam_profiles, k, rows, far);
            if constexpr (std::is_same_v<Real, float>) {
                if (groups > 0) // the group loop below adds its sums to these
                    far_values_into_rows(far_beam, far.level.data(), channels, cells, beams, rows,
                                         polar + std::size_t(k) * beams);
            }
        }
        const float* B = beam_profiles + static_cast<std::size_t>(k) * beams;
        // An empty bin row stays exactly 0 (every term would add +0 to a +0 sum).
        if (empty_row(B)) {
            std::fill(polar + static_cast<std::size_t>(k) * beams, polar + static_cast<std::size_t>(k + 1) * beams,
                      0.0f);
            ++k;
            continue;
        }
        if (groups > 0) {
            // Two bin rows at a time where the next one has energy too (and its far side lobes are in the
            // same batch): each weight is read once for both rows, and the eight sums in flight hide the
            // adds' latency. Every beam, four groups (16 beams) at a time: each beam's sum is one lane,
            // still in increasing t, over the taps where any beam of the groups has a weight, from the
            // padded row (a zero weight, or a zero beyond the fan's edge, adds exactly +0: the same sums
            // as the scalar loop below, which leaves those terms out). Rows never mix: the same sums as
            // one row at a time.
            const bool pair = k + 1 < bin_end && (cells == 0 || k + 1 - far_first < kFarRows) && !empty_row(B + beams);
            const std::uint32_t rows = pair ? 2 : 1;
            for (std::uint32_t r = 0; r < rows; ++r) {
                // padded[r][K + b] = beam b for b in [-K, nb + K + 4): the beams themselves, then the
                // padding either side (the wrapped beams with plan.circular, where K < nb / 2, else zeros)
                const float* row = B + std::size_t(r) * beams;
                float* out = padded[r] + K;
                std::memcpy(out, row, sizeof(float) * beams);
                for (std::int64_t b = -K; b < 0; ++b)
                    out[b] = plan.circular ? row[b + nb] : 0.0f;
                for (std::int64_t b = nb; b < nb + K + 4; ++b)
                    out[b] = plan.circular ? row[(b + nb) % nb] : 0.0f;
            }
            for (std::size_t q0 = 0; q0 < groups; q0 += 4) {
                const std::size_t n = std::min<std::size_t>(4, groups - q0);
                const std::size_t j0 = 4 * q0, j_end = std::min<std::size_t>(j0 + 4 * n, beams);
                std::uint32_t t_begin = taps, t_end = 0;
                for (std::size_t i = j0; i < j_end; ++i) {
                    t_begin = std::min(t_begin, tap_begin[i]);
                    t_end = std::max(t_end, tap_end[i]);
                }
                const Real* wq = group_weights + q0 * 4 * taps;
                V s[2][4] = {};
                // s[r][g] += w(g, t) * row r's beams j0 + 4 g + t - K .. + 3 (out parameters: a double V is
                // an AVX-sized value)
                auto load = [&](V& x, std::uint32_t r, std::size_t g, std::uint32_t t) {
                    const float* src = padded[r] + j0 + t + 4 * g; // beam j0 + 4 g + l takes src[l]
                    if constexpr (std::is_same_v<Real, float>) {
                        std::memcpy(&x, src, sizeof x);
                    } else {
                        for (std::uint32_t l = 0; l < 4; ++l)
                            x[l] = static_cast<Real>(src[l]);
                    }
                };
                auto mac = [&](std::uint32_t rows_used, std::size_t g, std::uint32_t t) {
                    V w, x;
                    std::memcpy(&w, wq + (g * taps + t) * 4, sizeof w);
                    load(x, 0, g, t);
                    s[0][g] += w * x;
                    if (rows_used == 2) {
                        load(x, 1, g, t);
                        s[1][g] += w * x;
                    }
                };
                if (std::is_same_v<Real, float> && n == 4 && avx2) {
                    if constexpr (std::is_same_v<Real, float>) {
                        float sums[2][16];
                        sidelobe_run8(wq, taps, padded[0] + j0, rows == 2 ? padded[1] + j0 : nullptr, t_begin, t_end,
                                      sums);
                        std::memcpy(s, sums, sizeof sums);
                    }
                } else if (n == 4 && rows == 2) {
                    for (std::uint32_t t = t_begin; t < t_end; ++t) {
                        mac(2, 0, t);
                        mac(2, 1, t);
                        mac(2, 2, t);
                        mac(2, 3, t);
                    }
                } else if (n == 4) {
                    for (std::uint32_t t = t_begin; t < t_end; ++t) {
                        mac(1, 0, t);
                        mac(1, 1, t);
                        mac(1, 2, t);
                        mac(1, 3, t);
                    }
                } else {
                    for (std::uint32_t t = t_begin; t < t_end; ++t)
                        for (std::size_t g = 0; g < n; ++g)
                            mac(rows, g, t);
                }
                for (std::uint32_t r = 0; r < rows; ++r) {
                    float* out = polar + static_cast<std::size_t>(k + r) * beams;
                    if constexpr (std::is_same_v<Real, float>) {
                        if (cells > 0) { // the far side lobes are in out already (far_values_into_rows)
                            for (std::size_t jj = j0; jj < j_end; ++jj)
                                out[jj] = s[r][(jj - j0) / 4][(jj - j0) % 4] + out[jj];
                            continue;
                        }
                    }
                    for (std::size_t jj = j0; jj < j_end; ++jj) {
                        const std::size_t g = (jj - j0) / 4, l = (jj - j0) % 4;
                        out[jj] = static_cast<float>(s[r][g][l] + far_at(static_cast<std::int64_t>(jj), k + r));
                    }
                }
            }
            k += rows;
            continue;
        }
        float* out = polar + static_cast<std::size_t>(k) * beams;
        std::int64_t j = 0;
        while (j < nb) {
            const float* w = weights + static_cast<std::size_t>(j) * taps;
            if (plan.circular) { // source j - K + t modulo beams (plan.circular: K < beams / 2)
                Real sum = Real(0);
                for (std::int64_t t = 0; t < static_cast<std::int64_t>(taps); ++t)
                    sum += static_cast<Real>(w[t]) * static_cast<Real>(B[(j - K + t + nb) % nb]);
                out[j] = static_cast<float>(sum + far_at(j, k));
                ++j;
                continue;
            }
            // Taps whose source beam j - K + t lies in [0, beams) and whose weight is not 0, in increasing t.
            const std::int64_t first = std::max<std::int64_t>(std::max<std::int64_t>(0, K - j), tap_begin[j]);
            const std::int64_t end = std::min<std::int64_t>(std::min<std::int64_t>(taps, nb + K - j), tap_end[j]);
            const float* src = B + (j - K);
            Real sum = Real(0);
            for (std::int64_t t = first; t < end; ++t)
                sum += static_cast<Real>(w[t]) * static_cast<Real>(src[t]);
            out[j] = static_cast<float>(sum + far_at(j, k));
            ++j;
        }
        ++k;
    }
}

template <class Real>
void beamform(const Plan& plan, const float* echo2, float* profiles, float* beam_profiles, float* polar,
              Real* scratch) {
    Real* resample_w = scratch + beamform_accumulator_count(plan);
    resample_weights<Real>(plan, resample_w);
    beamform_profiles<Real>(plan, echo2, profiles, scratch, 0, plan.profile_columns);
    beamform_beams<Real>(plan, scratch, resample_w, beam_profiles, polar, 0, plan.bins);
}

std::size_t beamform_accumulator_count(const Plan& plan) {
    return plan.profile_columns * column_stride(plan); // one accumulator per profile cell, and the padding
}

std::size_t cone_span_count(const Plan& plan) {
    return plan.line_array ? 2 * static_cast<std::size_t>(plan.rows) * plan.views : 0;
}

void cone_column_spans(const Plan& plan, std::uint32_t cone_begin, std::uint32_t cone_end, std::uint32_t* spans) {
    for (std::uint32_t j = 0; j < plan.rows && plan.line_array; ++j) {
        for (std::uint32_t view = 0; view < plan.views; ++view) {
            const auto [c_begin, c_end] = cone_span(plan, j, view, cone_begin, cone_end);
            spans[2 * (static_cast<std::size_t>(j) * plan.views + view)] = c_begin;
            spans[2 * (static_cast<std::size_t>(j) * plan.views + view) + 1] = c_end;
        }
    }
}

std::size_t beamform_scratch_count(const Plan& plan) {
    return beamform_accumulator_count(plan) + resample_weight_count(plan);
}

template <class Real>
void beamform(const Plan& plan, const float* echo2, float* profiles, float* beam_profiles, float* polar) {
    std::vector<Real> scratch(std::max<std::size_t>(beamform_scratch_count(plan), 1));
    beamform<Real>(plan, echo2, profiles, beam_profiles, polar, scratch.data());
}

template void resample_weights<float>(const Plan&, float*);
template void resample_weights<double>(const Plan&, double*);
template void beamform_profiles<float>(const Plan&, const float*, float*, float*, std::uint32_t, std::uint32_t,
                                       const SubpixelInput*, const std::uint8_t*, const std::uint32_t*);
template void beamform_profiles<double>(const Plan&, const float*, float*, double*, std::uint32_t, std::uint32_t,
                                        const SubpixelInput*, const std::uint8_t*, const std::uint32_t*);
template void beamform_beams<float>(const Plan&, const float*, const float*, float*, float*, std::uint32_t,
                                    std::uint32_t);
template void beamform_beams<double>(const Plan&, const double*, const double*, float*, float*, std::uint32_t,
                                     std::uint32_t);
template void beamform<float>(const Plan&, const float*, float*, float*, float*, float*);
template void beamform<double>(const Plan&, const float*, float*, float*, float*, double*);
template void beamform<float>(const Plan&, const float*, float*, float*, float*);
template void beamform<double>(const Plan&, const float*, float*, float*, float*);

} // namespace vksonar::cpu
