// What the CPU stages' vector loops share: has_avx2, whether this CPU runs their AVX2 paths, and expf
// of four floats at a time, bit-identical to glibc's (the footprint kernel of beamform, the absorption
// of echo): exp4, and exp4_matches_expf, whether this machine's expf is the one exp4 reproduces; log4 and
// log4_matches_logf likewise (the footprint kernel's density slope); use_avx2
// and use_exp4, those with the configuration's cpu.vector_loops.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include "vksonar/config.h"

namespace vksonar::cpu {

// Four values of Real side by side (GCC's vector extension: one SSE register for float, one AVX register
// for double), for the portable loops that work four lanes at a time.
template <class Real> struct Lanes4;
template <> struct Lanes4<float> { typedef float type __attribute__((vector_size(16))); };
template <> struct Lanes4<double> { typedef double type __attribute__((vector_size(32))); };

#if defined(__x86_64__) && defined(__GNUC__)
// A property of the machine, fixed once known.
inline bool has_avx2() {
    static const bool avx2 = __builtin_cpu_supports("avx2");
    return avx2;
}

// exp of four floats, bit-identical to glibc's expf where its ifunc picks __expf_fma (a CPU with FMA
// and AVX2): the same steps in double precision, fused where that build fuses them, with its table of
// 2^(i/32) and its polynomial (glibc 2.36, sysdeps/ieee754/flt-32/e_expf.c). Checked against expf on
// every float below 88 in magnitude; valid there only (range_shares' arguments lie within +-8).
alignas(32) inline constexpr std::uint64_t kExp2Table[32] = {
    0x3ff0000000000000, 0x3fefd9b0d3158574, 0x3fefb5586cf9890f, 0x3fef9301d0125b51, 0x3fef72b83c7d517b,
    0x3fef54873168b9aa, 0x3fef387a6e756238, 0x3fef1e9df51fdee1, 0x3fef06fe0a31b715, 0x3feef1a7373aa9cb,
    0x3feedea64c123422, 0x3feece086061892d, 0x3feebfdad5362a27, 0x3feeb42b569d4f82, 0x3feeab07dd485429,
    0x3feea47eb03a5585, 0x3feea09e667f3bcd, 0x3fee9f75e8ec5f74, 0x3feea11473eb0187, 0x3feea589994cce13,
    0x3feeace5422aa0db, 0x3feeb737b0cdc5e5, 0x3feec49182a3f090, 0x3feed503b23e255d, 0x3feee89f995ad3ad,
    0x3feeff76f2fb5e47, 0x3fef199bdd85529c, 0x3fef3720dcef9069, 0x3fef5818dcfba487, 0x3fef7c97337b9b5f,
    0x3fefa4afa2a490da, 0x3fefd0765b6e4540};

inline double double_from_bits(std::uint64_t u) {
    double d;
    std::memcpy(&d, &u, sizeof d);
    return d;
}

// expf of four floats (as doubles: xd), as glibc's __expf_fma computes it.
__attribute__((target("avx2,fma"), always_inline)) inline __m128 exp4(__m256d xd) {
    const __m256d invln2 = _mm256_set1_pd(double_from_bits(0x40471547652b82fe)); // 32 / ln 2
    const __m256d shift = _mm256_set1_pd(double_from_bits(0x4338000000000000));  // 0x1.8p52
    const __m256d kd = _mm256_fmadd_pd(invln2, xd, shift); // k = round(x 32 / ln 2) in the low bits
    const __m256i ki = _mm256_castpd_si256(kd);
    const __m256d r = _mm256_fmsub_pd(invln2, xd, _mm256_sub_pd(kd, shift));
    // the table entries by scalar loads: a gather is slow where microcode mitigates Downfall
    alignas(32) std::uint64_t k[4];
    _mm256_store_si256(reinterpret_cast<__m256i*>(k), ki);
    const __m256i table =
        _mm256_set_epi64x(static_cast<long long>(kExp2Table[k[3] & 31]), static_cast<long long>(kExp2Table[k[2] & 31]),
                          static_cast<long long>(kExp2Table[k[1] & 31]), static_cast<long long>(kExp2Table[k[0] & 31]));
    const __m256d scale = _mm256_castsi256_pd(_mm256_add_epi64(table, _mm256_slli_epi64(ki, 47)));
    const __m256d z = _mm256_fmadd_pd(r, _mm256_set1_pd(double_from_bits(0x3ebc6af84b912394)),
                                      _mm256_set1_pd(double_from_bits(0x3f2ebfce50fac4f3)));
    const __m256d r2 = _mm256_mul_pd(r, r);
    __m256d p = _mm256_fmadd_pd(r, _mm256_set1_pd(double_from_bits(0x3f962e42ff0c52d6)), _mm256_set1_pd(1.0));
    p = _mm256_fmadd_pd(z, r2, p);
    return _mm256_cvtpd_ps(_mm256_mul_pd(p, scale));
}

// y[i] = expf(x[i]) for i < n, n a multiple of 4 (exp4_matches_expf's check).
__attribute__((target("avx2,fma"))) inline void exp4_blocks(const float* x, float* y, int n) {
    for (int i = 0; i < n; i += 4)
        _mm_storeu_ps(y + i, exp4(_mm256_cvtps_pd(_mm_loadu_ps(x + i))));
}

// Whether y[i] is libm(x[i]) bit for bit for every i < n (the checks below).
template <class Libm> bool same_floats(const float* x, const float* y, int n, Libm libm) {
    for (int i = 0; i < n; ++i) {
        const float expected = libm(x[i]);
        if (std::memcmp(&y[i], &expected, sizeof expected) != 0) return false;
    }
    return true;
}

// Whether exp4_blocks gives std::exp's floats here: glibc's ifunc condition, and a check on a spread of
// arguments in case this glibc's expf is another one. A property of the machine, fixed once known.
inline bool exp4_matches_expf() {
    static const bool matches = [] {
        if (!__builtin_cpu_supports("fma") || !__builtin_cpu_supports("avx2")) return false;
        constexpr int kChecks = 1024;
        float x[kChecks], y[kChecks];
        for (int i = 0; i < kChecks; ++i)
            x[i] = -9.0f + 18.0f * static_cast<float>(i) / kChecks + 1e-4f * static_cast<float>(i % 7);
        exp4_blocks(x, y, kChecks);
        return same_floats(x, y, kChecks, [](float v) { return std::exp(v); });
    }();
    return matches;
}
// logf of four positive normal floats, bit-identical to glibc's logf where its ifunc picks __logf_fma:
// the same steps in double precision (x = 2^k z, z near c_i of 16 subintervals, log1p(z / c_i - 1) by a
// cubic), fused where that build fuses them, with its table of 1 / c_i and log c_i and its polynomial
// (glibc 2.36, sysdeps/ieee754/flt-32/e_logf.c and e_logf_data.c). Checked against logf on every positive
// normal float (2^31 - 2^24 of them: no difference); the caller keeps zero, subnormals, infinities, NaN and
// negative values away (positive_normal4).
alignas(32) inline constexpr double kLogInvC[16] = {
    0x1.661ec79f8f3bep+0, 0x1.571ed4aaf883dp+0, 0x1.49539f0f010bp+0,  0x1.3c995b0b80385p+0, 0x1.30d190c8864a5p+0,
    0x1.25e227b0b8eap+0,  0x1.1bb4a4a1a343fp+0, 0x1.12358f08ae5bap+0, 0x1.0953f419900a7p+0, 0x1p+0,
    0x1.e608cfd9a47acp-1, 0x1.ca4b31f026aap-1,  0x1.b2036576afce6p-1, 0x1.9c2d163a1aa2dp-1, 0x1.886e6037841edp-1,
    0x1.767dcf5534862p-1};
alignas(32) inline constexpr double kLogC[16] = {
    -0x1.57bf7808caadep-2, -0x1.2bef0a7c06ddbp-2, -0x1.01eae7f513a67p-2, -0x1.b31d8a68224e9p-3, -0x1.6574f0ac07758p-3,
    -0x1.1aa2bc79c81p-3,   -0x1.a4e76ce8c0e5ep-4, -0x1.1973c5a611cccp-4, -0x1.252f438e10c1ep-5, 0x0p+0,
    0x1.aa5aa5df25984p-5,  0x1.c5e53aa362eb4p-4,  0x1.526e57720db08p-3,  0x1.bc2860d22477p-3,   0x1.1058bc8a07ee1p-2,
    0x1.4043057b6ee09p-2};

__attribute__((target("avx2,fma"), always_inline)) inline __m128 log4(__m128 x) {
    const __m128i ix = _mm_castps_si128(x);
    const __m128i tmp = _mm_sub_epi32(ix, _mm_set1_epi32(0x3f330000)); // z's interval starts at 0x1.66p-1
    const __m128i i = _mm_and_si128(_mm_srli_epi32(tmp, 19), _mm_set1_epi32(15));
    const __m128i k = _mm_srai_epi32(tmp, 23);
    const __m128i iz = _mm_sub_epi32(ix, _mm_and_si128(tmp, _mm_set1_epi32(static_cast<int>(0xff800000u))));
    // the table entries by scalar loads (as exp4)
    alignas(16) std::int32_t n[4];
    _mm_store_si128(reinterpret_cast<__m128i*>(n), i);
    const __m256d invc = _mm256_setr_pd(kLogInvC[n[0]], kLogInvC[n[1]], kLogInvC[n[2]], kLogInvC[n[3]]);
    const __m256d logc = _mm256_setr_pd(kLogC[n[0]], kLogC[n[1]], kLogC[n[2]], kLogC[n[3]]);
    const __m256d z = _mm256_cvtps_pd(_mm_castsi128_ps(iz));
    const __m256d r = _mm256_fmsub_pd(z, invc, _mm256_set1_pd(1.0));
    const __m256d y0 = _mm256_fmadd_pd(_mm256_cvtepi32_pd(k), _mm256_set1_pd(0x1.62e42fefa39efp-1), logc);
    const __m256d r2 = _mm256_mul_pd(r, r);
    __m256d y = _mm256_fmadd_pd(_mm256_set1_pd(0x1.5575b0be00b6ap-2), r, _mm256_set1_pd(-0x1.ffffef20a4123p-2));
    y = _mm256_fmadd_pd(_mm256_set1_pd(-0x1.00ea348b88334p-2), r2, y);
    y = _mm256_fmadd_pd(y, r2, _mm256_add_pd(y0, r));
    return _mm256_cvtpd_ps(y);
}

// Lanes of x that are positive normal floats (log4's domain), as a mask.
inline __m128 positive_normal4(__m128 x) { // SSE2 only
    const __m128i t = _mm_sub_epi32(_mm_castps_si128(x), _mm_set1_epi32(0x00800000));
    return _mm_castsi128_ps(
        _mm_and_si128(_mm_cmpgt_epi32(t, _mm_set1_epi32(-1)), _mm_cmpgt_epi32(_mm_set1_epi32(0x7f000000), t)));
}

// y[i] = logf(x[i]) for i < n, n a multiple of 4, x[i] positive normal (log4_matches_logf's check).
__attribute__((target("avx2,fma"))) inline void log4_blocks(const float* x, float* y, int n) {
    for (int i = 0; i < n; i += 4)
        _mm_storeu_ps(y + i, log4(_mm_loadu_ps(x + i)));
}

// Whether log4 gives std::log's floats here: glibc's ifunc condition, and a check on a spread of
// arguments in case this glibc's logf is another one. A property of the machine, fixed once known.
inline bool log4_matches_logf() {
    static const bool matches = [] {
        if (!__builtin_cpu_supports("fma") || !__builtin_cpu_supports("avx2")) return false;
        // 4096 arguments spread over every binade, each a few ulps off a round number
        constexpr int kChecks = 4096;
        float x[kChecks], y[kChecks];
        for (int i = 0; i < kChecks; ++i) {
            const std::uint32_t bits = 0x00800000u + static_cast<std::uint32_t>(i) * 0x7f000u + 0x2f1u * (i % 5);
            std::memcpy(&x[i], &bits, sizeof bits);
        }
        log4_blocks(x, y, kChecks);
        return same_floats(x, y, kChecks, [](float v) { return std::log(v); });
    }();
    return matches;
}
#else
inline bool has_avx2() {
    return false;
}
inline bool exp4_matches_expf() {
    return false;
}
inline bool log4_matches_logf() {
    return false;
}
#endif

// The configuration's choice (SonarConfig::cpu_vector_loops: off forces the portable loops) and the
// machine's: whether a CPU stage takes its AVX2 loops, and expf four at a time.
inline bool use_avx2(const SonarConfig& config) {
    return config.cpu_vector_loops != CpuVectorLoops::off && has_avx2();
}
inline bool use_exp4(const SonarConfig& config) {
    return config.cpu_vector_loops != CpuVectorLoops::off && exp4_matches_expf();
}

} // namespace vksonar::cpu
