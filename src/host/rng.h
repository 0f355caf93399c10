// Counter-based RNG core, inline so the per-cell loop of the noise stage pays no call and hashes the
// (seed, frame) prefix once per frame instead of once per draw. host_stages.h has the plain API;
// both give identical draws.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>

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

// ---- The per-cell draws of the noise stage: 32-bit and branch-free, so the compiler vectorizes a
// row of them. Keyed like the rest: a pure function of (seed, frame, beam, bin, stream).

// murmur3's 32-bit finalizer: a bijection with full avalanche.
inline std::uint32_t fmix32(std::uint32_t h) {
    h ^= h >> 16;
    h *= 0x85ebca6bu;
    h ^= h >> 13;
    h *= 0xc2b2ae35u;
    h ^= h >> 16;
    return h;
}

// (beam, bin) packed into one word is injective for beam, bin < 2^16 (the caller checks), and each
// fmix32 step is a bijection of its input: within one (seed, frame, stream) no two cells share a draw.
inline std::uint32_t hash_cell32(FrameKey key, std::uint32_t beam, std::uint32_t bin, std::uint32_t stream) {
    const auto key_lo = static_cast<std::uint32_t>(key.state), key_hi = static_cast<std::uint32_t>(key.state >> 32);
    const std::uint32_t h = fmix32(((beam << 16) | bin) ^ key_lo);
    return fmix32((h + stream * 0x9e3779b9u) ^ key_hi);
}
constexpr std::uint32_t kMaxCell32 = 1u << 16; // beams and bins below this use hash_cell32

// ln x for finite x > 0 (normal floats), branch-free (Cephes logf: x = m 2^e with m in [sqrt(1/2),
// sqrt(2)), a degree-9 polynomial in m - 1); relative error ~1e-7.
inline float fast_logf(float x) {
    std::uint32_t bits;
    std::memcpy(&bits, &x, sizeof bits);
    float e = static_cast<float>(static_cast<std::int32_t>((bits >> 23) & 0xffu) - 126);
    bits = (bits & 0x007fffffu) | 0x3f000000u; // m in [0.5, 1)
    float m;
    std::memcpy(&m, &bits, sizeof m);
    // m < sqrt(1/2): use 2m - 1 and e - 1. Arithmetic on an integer flag instead of a branch or a
    // float comparison, so the compiler vectorizes it (m > 0: its bits compare like the floats).
    const auto low = static_cast<float>(static_cast<std::int32_t>((bits - 0x3f3504f3u) >> 31)); // 1 if below
    e -= low;
    m = (m - 1.0f) + low * m;
    const float z = m * m;
    float y = 7.0376836292e-2f;
    y = y * m - 1.1514610310e-1f;
    y = y * m + 1.1676998740e-1f;
    y = y * m - 1.2420140846e-1f;
    y = y * m + 1.4249322787e-1f;
    y = y * m - 1.6668057665e-1f;
    y = y * m + 2.0000714765e-1f;
    y = y * m - 2.4999993993e-1f;
    y = y * m + 3.3333331174e-1f;
    y = y * m * z;
    y += -2.12194440e-4f * e;
    y += -0.5f * z;
    return m + y + 0.693359375f * e;
}

// Exp(1) from the top 24 bits of hash_cell32, centred in their cell: u in [2^-25, 1 - 2^-25], the
// draw in (3e-8, 17.3]. The cut tail (P = 3e-8) shifts the mean by < 1e-6.
inline float exp1_cell32(FrameKey key, std::uint32_t beam, std::uint32_t bin, std::uint32_t stream) {
    const float u = (static_cast<float>(hash_cell32(key, beam, bin, stream) >> 8) + 0.5f) * (1.0f / 16777216.0f);
    return -fast_logf(u);
}

} // namespace vksonar::host::rng
