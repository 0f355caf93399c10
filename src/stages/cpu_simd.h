// What the CPU stages' vector loops share: has_avx2, whether this CPU runs their AVX2 paths, and expf
// of four floats at a time, bit-identical to glibc's (the footprint kernel of beamform, the absorption
// of echo): exp4, and exp4_matches_expf, whether this machine's expf is the one exp4 reproduces; use_avx2
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
        for (int i = 0; i < kChecks; ++i) {
            const float expected = std::exp(x[i]);
            if (std::memcmp(&y[i], &expected, sizeof expected) != 0) return false;
        }
        return true;
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
