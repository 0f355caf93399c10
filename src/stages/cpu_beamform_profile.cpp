// CPU reference of the beamform stage's first pass (docs/pipeline.md §4): per-column range profiles.
// Each hit pixel is spread over the range bins by the range kernel (nearest, tent or footprint) and added
// into its pixel column (planar) or the two cone columns its direction falls between (line_array; a tier
// view's pixel: those its cone extent touches);
// the sub-pixel returns follow. Every accumulator receives its additions in one fixed order, so the
// result is deterministic (bit-identical run to run). Sums accumulate in Real. The second pass, the
// beams, is in cpu_beamform.cpp.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif
#include <type_traits>
#include <utility>

#include "core/sonar_math.hpp"
#include "core/tier_extent.h"
#include "stages/cpu_simd.h"
#include "stages/cpu_stages.h"
#include "stages/pixel_spread.h"

namespace vksonar::cpu {

namespace {

// column[i] += shares[i] * weighted for i < n, each the scalar loop's product and sum: four at a time
// where `weighted` is finite, the lanes past n adding +0 (for_each_spread_pixel pads shares with zeros;
// +0 leaves an accumulator as it is, since accumulators are sums of terms >= 0 and never -0; the
// column's padding takes what runs past its last bin), else one at a time.
template <class Real> inline void add_shares(Real* column, const Real* shares, int n, Real weighted) {
    if (std::isfinite(weighted)) {
        using V = typename Lanes4<Real>::type;
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
    for (int i = 0; i < n; i += 8) { // bins from the spread's origin
        const __m256i k =
            _mm256_add_epi32(_mm256_set1_epi32(s.k_first - s.origin + i), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
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
    const __m256i k = _mm256_add_epi32( // bins from each spread's origin
        _mm256_set_m128i(_mm_set1_epi32(sb.k_first - sb.origin), _mm_set1_epi32(sa.k_first - sa.origin)),
        _mm256_setr_epi32(0, 1, 2, 3, 0, 1, 2, 3));
    __m256 share;
    if (!footprint_share8(halves8(sa.lo, sb.lo), halves8(sa.hi, sb.hi), halves8(sa.centre, sb.centre),
                          halves8(sa.g, sb.g), halves8(sa.inv_norm, sb.inv_norm), k, share))
        return false;
    _mm_storeu_ps(shares_a, _mm256_castps256_ps128(share));
    _mm_storeu_ps(shares_b, _mm256_extractf128_ps(share, 1));
    return true;
}

// The five-row windows of eight pixels for footprint_spread8, lane by lane: each pixel's (energy, range),
// those of the rows above and below (up, down) and the ranges of the rows two away (up2, down2); 0
// outside the image.
constexpr int kSpreadLanes = 8;
struct SpreadLanes {
    alignas(32) float e[8], r[8], up2_r[8], up_e[8], up_r[8], down_e[8], down_r[8], down2_r[8], left_r[8], right_r[8];
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

// The lanes footprint_spread8 reads, in registers.
struct SpreadVectors {
    __m256 e, r, up2_r, up_r, up_e, down_r, down2_r, down_e, left_r, right_r;
};

// range_spread with the footprint kernel (float) for eight pixels as AVX lanes: the same operations in
// the same order (std::min/max's choices between equal values kept, logf per lane, exp as exp4, which
// matches expf here), into out[0..7]. False where a pixel's bin coordinate is NaN (the caller then uses
// the scalar kernel).
VKS_AVX2_INLINE bool footprint_spread8_of(const SpreadVectors& in, float range_min, float ibw, float jump_rel, int bins,
                                          float absorption_per_bin, Math<float>::RangeSpread* out) {
    const __m256 zero = _mm256_setzero_ps(), half = _mm256_set1_ps(0.5f), one = _mm256_set1_ps(1.0f),
                 two = _mm256_set1_ps(2.0f);
    const __m256 vibw = _mm256_set1_ps(ibw);
    const __m256 r = in.r, up2_r = in.up2_r, up_r = in.up_r, down_r = in.down_r, down2_r = in.down2_r;
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
    // bin coordinates from the pixel's own bin (range_spread): f = x - floor(x), exact
    const __m256 base = _mm256_floor_ps(x);
    const __m256 f = _mm256_sub_ps(x, base);
    const __m256 xl = _mm256_add_ps(f, _mm256_mul_ps(min8(min8(a2, b2), zero), vibw)); // footprint_lo
    const __m256 xh = _mm256_add_ps(f, _mm256_mul_ps(max8(max8(a2, b2), zero), vibw)); // footprint_hi
    // footprint_across: the extent along the row, from the left and right neighbours (none beyond them)
    const __m256 left_r = in.left_r, right_r = in.right_r;
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
    const __m256 e_up = in.up_e, e_down = in.down_e;
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
        _mm256_sub_ps(column_centre, f));
    const __m256 e_self = in.e, w_self = _mm256_sub_ps(xh, xl);
    const __m256 e1 = select8(both, e_up, e_q), w1 = select8(both, w_up, w_q);
    const __m256 e2 = select8(both, e_down, e_self), w2 = select8(both, w_down, w_self);
    const __m256 slope_span = select8(both, span, span_q);
    __m256 has_g = _mm256_or_ps(up_side, down_side);
    has_g = _mm256_and_ps(
        has_g, _mm256_and_ps(_mm256_and_ps(_mm256_cmp_ps(e1, zero, _CMP_GT_OQ), _mm256_cmp_ps(e2, zero, _CMP_GT_OQ)),
                             _mm256_and_ps(_mm256_cmp_ps(w1, zero, _CMP_GT_OQ), _mm256_cmp_ps(w2, zero, _CMP_GT_OQ))));
    has_g = _mm256_and_ps(has_g, _mm256_cmp_ps(abs8(slope_span), zero, _CMP_GT_OQ));
    // (and neither product of the ratio underflowed: footprint_slope_known)
    has_g = _mm256_and_ps(has_g, _mm256_and_ps(_mm256_cmp_ps(_mm256_mul_ps(e1, w2), zero, _CMP_GT_OQ),
                                               _mm256_cmp_ps(_mm256_mul_ps(e2, w1), zero, _CMP_GT_OQ)));
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
    // without a slope from the neighbours, absorption's (range_spread: g = -b, b = absorption_per_bin)
    const __m256 vb = _mm256_set1_ps(absorption_per_bin);
    g = select8(has_g, g, neg8(vb));
    // inv_norm: range_spread's, with absorption averaged over the footprint
    const __m256 y = _mm256_mul_ps(_mm256_mul_ps(half, _mm256_add_ps(g, vb)), width);
    const __m256 y2 = _mm256_mul_ps(y, y);
    const __m256 inner = _mm256_add_ps(one, _mm256_div_ps(y2, _mm256_set1_ps(42.0f)));
    const __m256 middle = _mm256_add_ps(one, _mm256_mul_ps(_mm256_div_ps(y2, _mm256_set1_ps(20.0f)), inner));
    __m256 sinhc = _mm256_add_ps(one, _mm256_mul_ps(_mm256_div_ps(y2, _mm256_set1_ps(6.0f)), middle));
    const __m256 wide = _mm256_cmp_ps(abs8(y), half, _CMP_GE_OQ); // NaN-free: g and width are finite
    if (_mm256_movemask_ps(wide) != 0) {
        const __m256 ey = exp8(y), e_minus = exp8(neg8(y));
        sinhc = select8(wide, _mm256_div_ps(_mm256_sub_ps(ey, e_minus), _mm256_mul_ps(two, y)), sinhc);
    }
    const __m256 tilt_arg = _mm256_mul_ps(neg8(vb), _mm256_sub_ps(centre, f));
    const __m256 tilt = exp8(min8(max8(tilt_arg, _mm256_set1_ps(-60.0f)), _mm256_set1_ps(60.0f)));
    const __m256 inv_norm = _mm256_div_ps(tilt, _mm256_mul_ps(width, sinhc));
    alignas(32) float lo_l[8], hi_l[8], centre_l[8], g_l[8], inv_l[8];
    alignas(32) std::int32_t first_l[8], last_l[8], origin_l[8];
    _mm256_store_ps(lo_l, lo);
    _mm256_store_ps(hi_l, hi);
    _mm256_store_ps(centre_l, centre);
    _mm256_store_ps(g_l, g);
    _mm256_store_ps(inv_l, inv_norm);
    _mm256_store_si256(reinterpret_cast<__m256i*>(first_l), _mm256_cvttps_epi32(_mm256_floor_ps(lo)));
    _mm256_store_si256(reinterpret_cast<__m256i*>(last_l), _mm256_cvttps_epi32(_mm256_floor_ps(hi)));
    _mm256_store_si256(reinterpret_cast<__m256i*>(origin_l), _mm256_cvttps_epi32(base));
    for (int l = 0; l < 8; ++l) {
        Math<float>::RangeSpread& o = out[l];
        o.kernel = shared::kRangeKernelFootprint;
        o.origin = origin_l[l];
        o.k_first = std::max(origin_l[l] + first_l[l], 0);
        o.k_last = std::min(origin_l[l] + last_l[l], bins - 1);
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

// footprint_spread8 of lanes the caller filled one by one.
__attribute__((target("avx2,fma"))) bool footprint_spread8(const SpreadLanes& in, float range_min, float ibw,
                                                           float jump_rel, int bins, float absorption_per_bin,
                                                           Math<float>::RangeSpread* out) {
    const SpreadVectors v{_mm256_load_ps(in.e),       _mm256_load_ps(in.r),      _mm256_load_ps(in.up2_r),
                          _mm256_load_ps(in.up_r),    _mm256_load_ps(in.up_e),   _mm256_load_ps(in.down_r),
                          _mm256_load_ps(in.down2_r), _mm256_load_ps(in.down_e), _mm256_load_ps(in.left_r),
                          _mm256_load_ps(in.right_r)};
    return footprint_spread8_of(v, range_min, ibw, jump_rel, bins, absorption_per_bin, out);
}

// The (e, r) pairs of the eight pixels of row `row` from column c0 as two registers (zeros for a row
// outside [0, R)): two loads; per 128-bit half a shuffle gives (e0 e1 e4 e5 | e2 e3 e6 e7), then the
// halves' pairs in order.
VKS_AVX2_INLINE void spread_row_lanes(const float* echo2, std::uint32_t C, std::uint32_t R, std::int64_t row,
                                      std::uint32_t c0, __m256& e, __m256& r) {
    if (row < 0 || row >= static_cast<std::int64_t>(R)) {
        e = r = _mm256_setzero_ps();
        return;
    }
    const __m256i order = _mm256_setr_epi32(0, 1, 4, 5, 2, 3, 6, 7);
    const float* q = echo2 + 2 * (static_cast<std::size_t>(row) * C + c0);
    const __m256 a = _mm256_loadu_ps(q), b = _mm256_loadu_ps(q + 8); // (e0 r0 .. e3 r3), (e4 r4 .. e7 r7)
    e = _mm256_permutevar8x32_ps(_mm256_shuffle_ps(a, b, _MM_SHUFFLE(2, 0, 2, 0)), order);
    r = _mm256_permutevar8x32_ps(_mm256_shuffle_ps(a, b, _MM_SHUFFLE(3, 1, 3, 1)), order);
}

// footprint_spread8 of the eight neighbouring pixels of row j from column c0 (c0 + 8 <= C), straight from
// echo2 into registers (lanes stored one by one and read back as a vector stall on store forwarding): each
// row's (e, r) pairs by two loads and a shuffle, zeros for rows outside [0, R); the row neighbours from the
// centre row's ranges, left_range and right_range beyond the eight (0 past the view's edge).
__attribute__((target("avx2,fma"))) bool footprint_spread8_run(const float* echo2, std::uint32_t C, std::uint32_t R,
                                                               std::uint32_t j, std::uint32_t c0, float left_range,
                                                               float right_range, float range_min, float ibw,
                                                               float jump_rel, int bins, float absorption_per_bin,
                                                               Math<float>::RangeSpread* out) {
    SpreadVectors v;
    __m256 unused_e;
    const std::int64_t jj = j;
    spread_row_lanes(echo2, C, R, jj, c0, v.e, v.r);
    spread_row_lanes(echo2, C, R, jj - 2, c0, unused_e, v.up2_r);
    spread_row_lanes(echo2, C, R, jj - 1, c0, v.up_e, v.up_r);
    spread_row_lanes(echo2, C, R, jj + 1, c0, v.down_e, v.down_r);
    spread_row_lanes(echo2, C, R, jj + 2, c0, unused_e, v.down2_r);
    // left: (left_range, r0 .. r6); right: (r1 .. r7, right_range)
    v.left_r = _mm256_blend_ps(_mm256_permutevar8x32_ps(v.r, _mm256_setr_epi32(0, 0, 1, 2, 3, 4, 5, 6)),
                               _mm256_set1_ps(left_range), 0x01);
    v.right_r = _mm256_blend_ps(_mm256_permutevar8x32_ps(v.r, _mm256_setr_epi32(1, 2, 3, 4, 5, 6, 7, 7)),
                                _mm256_set1_ps(right_range), 0x80);
    return footprint_spread8_of(v, range_min, ibw, jump_rel, bins, absorption_per_bin, out);
}
#undef VKS_AVX2_INLINE

#else
constexpr int kSpreadLanes = 8;
struct SpreadLanes {
    float e[8], r[8], up2_r[8], up_e[8], up_r[8], down_e[8], down_r[8], down2_r[8], left_r[8], right_r[8];
};
bool footprint_spread8(const SpreadLanes&, float, float, float, int, float, Math<float>::RangeSpread*) {
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
#if defined(__x86_64__) && defined(__GNUC__)
            if (n == kSpreadLanes && c[7] == c[0] + 7 && view.end > 0) {
                // Eight neighbouring pixels (most batches): their windows straight into registers, the row
                // neighbours from the centre row's ranges; the same values as the loop below.
                const float* p = echo2 + 2 * (static_cast<std::size_t>(j) * C + c[0]);
                if (footprint_spread8_run(echo2, C, R, j, c[0], c[0] > view.first ? p[-1] : 0.0f,
                                          c[7] + 1 < view.end ? p[17] : 0.0f, range_min, inv_bin_width,
                                          static_cast<float>(plan.params.edge_relative_jump),
                                          static_cast<int>(plan.bins), plan.params.absorption_per_bin, out))
                    return;
            }
#endif
            SpreadLanes in;
            for (int l = 0; l < kSpreadLanes; ++l) {
                const std::uint32_t col = c[std::min(l, n - 1)];
                // (the rows two away give their range only: the kernel reads no energy there)
                auto row = [&](std::int64_t jj, float* e, float* r) {
                    const bool inside = jj >= 0 && jj < static_cast<std::int64_t>(R);
                    const float* q = echo2 + 2 * (static_cast<std::size_t>(inside ? jj : 0) * C + col);
                    if (e != nullptr) e[l] = inside ? q[0] : 0.0f;
                    r[l] = inside ? q[1] : 0.0f;
                };
                const std::int64_t jj = j;
                row(jj, in.e, in.r);
                row(jj - 2, nullptr, in.up2_r);
                row(jj - 1, in.up_e, in.up_r);
                row(jj + 1, in.down_e, in.down_r);
                row(jj + 2, nullptr, in.down2_r);
                const RowNeighbours across = across_of(col);
                in.left_r[l] = across.left_r;
                in.right_r[l] = across.right_r;
            }
            if (footprint_spread8(in, range_min, inv_bin_width, static_cast<float>(plan.params.edge_relative_jump),
                                  static_cast<int>(plan.bins), plan.params.absorption_per_bin, out))
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
// [cone_begin, cone_end): those within one column of them, x in (cone_begin - 1, cone_end), a tier view's
// within one column and its pixels' reach (Plan::tier_cone_reach). Along a view's row the cone
// coordinate increases with the column (plan_cone_table).
std::pair<std::uint32_t, std::uint32_t> cone_span(const Plan& plan, std::uint32_t j, std::uint32_t view,
                                                  std::uint32_t cone_begin, std::uint32_t cone_end) {
    const float* cone_x = plan.pixel_cone_coord.data() + static_cast<std::size_t>(j) * plan.columns;
    const float reach = view >= plan.slices ? plan.tier_cone_reach : 0.0f;
    const float lo = static_cast<float>(cone_begin) - 1.0f - reach, hi = static_cast<float>(cone_end) + reach;
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
    const std::size_t T = profile_column_stride(plan);
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
            // each pixel into the cone columns floor(x) and floor(x) + 1 of this block (a tier view's pixel: those
            // its cone extent touches), the range shares once for all (a footprint spans <= kMaxFootprintBins + 1
            // bins)
            const bool tier = view >= plan.slices;
            const auto add_to_cones = [&](std::uint32_t pc, Real e, const typename M::RangeSpread& spread,
                                          int spread_bins, const Real* shares) {
                const Real x = static_cast<Real>(cone_x[pc]);
                ConeExtent extent{cone_x[pc], cone_x[pc]};
                if (tier) extent = tier_cone_extent(cone_x, pc, columns.first, columns.end);
                const ConeColumns fed = cone_columns_fed(cone_x[pc], extent);
                const int first_cone = std::max(fed.first, static_cast<int>(cone_begin));
                const int last_cone = std::min(fed.last, static_cast<int>(cone_end) - 1);
                for (int cone = first_cone; cone <= last_cone; ++cone) {
                    const Real weight = tier ? M::cone_extent_share(x, static_cast<Real>(extent.lo),
                                                                    static_cast<Real>(extent.hi), cone, count)
                                             : M::cone_share(x, cone, count);
                    if (!(weight > Real(0))) continue;
                    add_shares(acc + static_cast<std::size_t>(cone) * T + spread.k_first, shares, spread_bins,
                               weight * e);
                }
            };
            for_each_spread_pixel<Real>(plan, echo2, j, c_begin, c_end, exp4, range_min, inv_bin_width, columns,
                                        add_to_cones);
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

// The sub-pixel returns of profile columns [column_begin, column_end) that the depth image does not hide,
// each into the two bins of the tent kernel at its range (sonar_kernels.h; profile.comp's add_subpixel):
// per column in list order, after the column's pixels.
template <class Real>
void add_subpixel_returns(const Plan& plan, const SubpixelInput& in, Real* acc, std::uint32_t column_begin,
                          std::uint32_t column_end, Real range_min, Real inv_bin_width) {
    using M = Math<Real>;
    const std::size_t T = profile_column_stride(plan);
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
                                none, none, Real(0), Real(0), range_min, inv_bin_width, Real(0), plan.bins, Real(0));
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
    const std::size_t T = profile_column_stride(plan);
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

std::size_t beamform_accumulator_count(const Plan& plan) {
    return plan.profile_columns * profile_column_stride(plan); // one accumulator per profile cell, and the padding
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

template void beamform_profiles<float>(const Plan&, const float*, float*, float*, std::uint32_t, std::uint32_t,
                                       const SubpixelInput*, const std::uint8_t*, const std::uint32_t*);
template void beamform_profiles<double>(const Plan&, const float*, float*, double*, std::uint32_t, std::uint32_t,
                                        const SubpixelInput*, const std::uint8_t*, const std::uint32_t*);

} // namespace vksonar::cpu
