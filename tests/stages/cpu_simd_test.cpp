// The CPU stages' vector math (src/stages/cpu_simd.h): exp4 and log4 give the floats of this machine's
// expf and logf, the libm the scalar loops call, so that a vector loop and its scalar twin write the same
// bytes. Sampled far more densely than the checks the stages run once per process.
#include <gtest/gtest.h>

#include <gnu/libc-version.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "stages/cpu_simd.h"

namespace vksonar::testing {
namespace {

// Where exp4 and log4 must be taken: a CPU with glibc's FMA paths and the glibc (Debian 12's) whose
// steps and tables they reproduce. Elsewhere the stages check at run time and may take the scalar loops.
bool libm_reproduced() {
    return __builtin_cpu_supports("fma") && __builtin_cpu_supports("avx2") &&
           std::string(gnu_get_libc_version()) == "2.36";
}

float float_from_bits(std::uint32_t bits) {
    float f;
    std::memcpy(&f, &bits, sizeof f);
    return f;
}

// blocks(x) against libm(x) bit for bit, x padded to a multiple of 4 with 1: the number of floats that
// differ (the first five reported by name).
template <class Blocks, class Libm>
std::size_t differences(std::vector<float> x, Blocks blocks, Libm libm, const char* name) {
    while (x.size() % 4 != 0)
        x.push_back(1.0f);
    std::vector<float> y(x.size());
    blocks(x.data(), y.data(), static_cast<int>(x.size()));
    std::size_t differ = 0;
    for (std::size_t i = 0; i < x.size(); ++i) {
        const float expected = libm(x[i]);
        if (std::memcmp(&y[i], &expected, sizeof expected) != 0 && ++differ <= 5)
            ADD_FAILURE() << name << "(" << x[i] << ") = " << y[i] << ", libm gives " << expected;
    }
    return differ;
}

// Every 61st float of |x| < 80 (the range the footprint shares and the echo's absorption feed exp4).
TEST(CpuSimd, Exp4GivesExpfsFloats) {
    if (!libm_reproduced()) GTEST_SKIP() << "not glibc 2.36 on a CPU with FMA and AVX2: exp4 may not apply";
    ASSERT_TRUE(cpu::exp4_matches_expf());
    std::vector<float> x;
    for (std::uint32_t bits = 0; bits < 0x42a00000u; bits += 61) { // 80.0f
        x.push_back(float_from_bits(bits));
        x.push_back(-float_from_bits(bits));
    }
    EXPECT_EQ(differences(
                  x, cpu::exp4_blocks, [](float v) { return std::exp(v); }, "exp4"),
              0u)
        << "of " << x.size();
}

// Every 61st positive normal float, and the edges of its domain; positive_normal4 says which lanes those are.
TEST(CpuSimd, Log4GivesLogfsFloatsOnPositiveNormals) {
    if (!libm_reproduced()) GTEST_SKIP() << "not glibc 2.36 on a CPU with FMA and AVX2: log4 may not apply";
    ASSERT_TRUE(cpu::log4_matches_logf());
    std::vector<float> x;
    for (std::uint32_t bits = 0x00800000u; bits < 0x7f800000u; bits += 61)
        x.push_back(float_from_bits(bits));
    for (std::uint32_t bits : {0x00800000u, 0x00800001u, 0x3f7fffffu, 0x3f800000u, 0x3f800001u, 0x7f7fffffu})
        x.push_back(float_from_bits(bits));
    EXPECT_EQ(differences(
                  x, cpu::log4_blocks, [](float v) { return std::log(v); }, "log4"),
              0u)
        << "of " << x.size();

    const float lanes[4] = {1.0f, float_from_bits(0x00800000u), float_from_bits(0x7f7fffffu), 3.5f};
    EXPECT_EQ(_mm_movemask_ps(cpu::positive_normal4(_mm_loadu_ps(lanes))), 15);
    for (float outside : {0.0f, -0.0f, float_from_bits(0x007fffffu), -1.0f, INFINITY, NAN}) {
        const float with[4] = {1.0f, outside, 2.0f, 3.0f};
        EXPECT_EQ(_mm_movemask_ps(cpu::positive_normal4(_mm_loadu_ps(with))), 0b1101) << outside;
    }
}

} // namespace
} // namespace vksonar::testing
