// IEEE binary16 conversions for the fp16 echo storage (accuracy.intermediates = fp16): the CPU
// reference rounds exactly as the GPU's packHalf2x16 (round to nearest, ties to even; subnormals
// kept; overflow to infinity), so both backends store the same halves.
#pragma once

#include <cstdint>
#include <cstring>

namespace vksonar {

inline std::uint16_t float_to_half(float f) {
    std::uint32_t x;
    std::memcpy(&x, &f, sizeof x);
    const std::uint32_t sign = (x >> 16) & 0x8000u;
    const std::uint32_t mag = x & 0x7fffffffu;
    if (mag >= 0x7f800000u) return static_cast<std::uint16_t>(sign | (mag > 0x7f800000u ? 0x7e00u : 0x7c00u));
    if (mag >= 0x477ff000u) return static_cast<std::uint16_t>(sign | 0x7c00u); // >= 65520: infinity
    if (mag < 0x38800000u) {                                                   // below 2^-14: subnormal or 0
        const int exponent = static_cast<int>(mag >> 23);
        const int shift = 126 - exponent; // value / 2^-24 = mantissa >> shift
        if (exponent == 0 || shift > 24) return static_cast<std::uint16_t>(sign);
        const std::uint32_t mantissa = (mag & 0x7fffffu) | 0x800000u;
        std::uint32_t q = mantissa >> shift;
        const std::uint32_t rest = mantissa & ((1u << shift) - 1u), half = 1u << (shift - 1);
        if (rest > half || (rest == half && (q & 1u))) ++q;
        return static_cast<std::uint16_t>(sign | q);
    }
    const std::uint32_t rebased = mag - 0x38000000u; // exponent bias 127 -> 15
    std::uint32_t q = rebased >> 13;
    const std::uint32_t rest = rebased & 0x1fffu;
    if (rest > 0x1000u || (rest == 0x1000u && (q & 1u))) ++q;
    return static_cast<std::uint16_t>(sign | q);
}

inline float half_to_float(std::uint16_t h) {
    const std::uint32_t sign = static_cast<std::uint32_t>(h & 0x8000u) << 16;
    const std::uint32_t exponent = (h >> 10) & 0x1fu, mantissa = h & 0x3ffu;
    std::uint32_t x;
    if (exponent == 0) {
        const float value = static_cast<float>(mantissa) * (1.0f / 16777216.0f); // mantissa * 2^-24, exact
        std::memcpy(&x, &value, sizeof x);
        x |= sign;
    } else if (exponent == 31) {
        x = sign | 0x7f800000u | (mantissa << 13);
    } else {
        x = sign | ((exponent + 112u) << 23) | (mantissa << 13);
    }
    float f;
    std::memcpy(&f, &x, sizeof f);
    return f;
}

inline float round_to_half(float f) {
    return half_to_float(float_to_half(f));
}

} // namespace vksonar
