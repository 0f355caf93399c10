// Counter-based RNG core, inline so the per-cell loop of the noise stage pays no call and hashes the
// (seed, frame) prefix once per frame instead of once per draw. host_stages.h has the plain API;
// both give identical draws.
#pragma once

#include <cmath>
#include <cstdint>

namespace vksonar::host::rng {

// Stafford's "Mix13" variant of the splitmix64 finalizer: a bijection of 64-bit words with full
// avalanche (every input bit flips every output bit with probability ~1/2).
inline std::uint64_t mix64(std::uint64_t z) {
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

// The key words are absorbed one at a time: h <- mix64((h ^ word) + k_i). For the other words fixed,
// each step is a bijection of the word being absorbed, so two keys that differ in exactly one
// component always give different 64-bit hashes. The distinct odd constants keep all-zero keys away
// from the fixed point of the mixer. FrameKey holds the state after (seed, frame).
struct FrameKey {
    std::uint64_t state;
};

inline FrameKey frame_key(std::uint64_t seed, std::uint64_t frame) {
    const std::uint64_t h = mix64(seed + 0x9e3779b97f4a7c15ull);
    return FrameKey{mix64((h ^ frame) + 0xd1b54a32d192ed03ull)};
}

inline std::uint64_t hash_cell(FrameKey key, std::uint32_t beam, std::uint32_t bin, std::uint32_t stream) {
    std::uint64_t h = mix64((key.state ^ ((static_cast<std::uint64_t>(beam) << 32) | bin)) + 0x8cb92ba72f3d8dd7ull);
    h = mix64((h ^ stream) + 0xaef17502108ef2d9ull);
    return mix64(h + 0xf1357aea2e62a9c5ull); // one more round so the last word is fully mixed too
}

// Top 53 bits, centred in their 2^-53 cell: the result lies in [2^-54, 1 - 2^-54], never 0 or 1,
// so -log(u) and log(1 - u) are always finite.
inline double uniform01(FrameKey key, std::uint32_t beam, std::uint32_t bin, std::uint32_t stream) {
    const std::uint64_t bits = hash_cell(key, beam, bin, stream) >> 11;
    return (static_cast<double>(bits) + 0.5) * (1.0 / 9007199254740992.0);
}

inline double exp1(FrameKey key, std::uint32_t beam, std::uint32_t bin, std::uint32_t stream) {
    return -std::log(uniform01(key, beam, bin, stream));
}

// Exp(1) in float, for the per-cell loop of the noise stage (a float log costs a third of a double
// one there): the top 24 bits, centred in their cell, so u lies in [2^-25, 1 - 2^-25] and the draw
// in (3e-8, 17.3]. The cut tail (P = 3e-8) shifts the mean by < 1e-6.
inline float exp1f(FrameKey key, std::uint32_t beam, std::uint32_t bin, std::uint32_t stream) {
    const auto bits = static_cast<std::uint32_t>(hash_cell(key, beam, bin, stream) >> 40);
    const float u = (static_cast<float>(bits) + 0.5f) * (1.0f / 16777216.0f);
    return -std::log(u);
}

} // namespace vksonar::host::rng
