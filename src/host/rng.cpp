// Counter-based RNG for the host noise stage: every draw is a pure function of
// (seed, frame, beam, bin, stream), so reruns, the CPU and the Vulkan backends agree exactly and the
// noise of one cell never depends on the order cells are visited.
#include <cmath>
#include <cstdint>

#include "host/host_stages.h"

namespace vksonar::host {
namespace {

// Stafford's "Mix13" variant of the splitmix64 finalizer: a bijection of 64-bit words with full
// avalanche (every input bit flips every output bit with probability ~1/2).
inline std::uint64_t mix64(std::uint64_t z) {
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

// Absorbs the key words one at a time: h <- mix64((h ^ word) + k_i). For the other words fixed,
// each step is a bijection of the word being absorbed, so two keys that differ in exactly one
// component always give different 64-bit hashes. The distinct odd constants keep all-zero keys away
// from the fixed point of the mixer.
inline std::uint64_t hash_key(std::uint64_t seed, std::uint64_t frame, std::uint32_t beam, std::uint32_t bin,
                              std::uint32_t stream) {
    std::uint64_t h = mix64(seed + 0x9e3779b97f4a7c15ull);
    h = mix64((h ^ frame) + 0xd1b54a32d192ed03ull);
    h = mix64((h ^ ((static_cast<std::uint64_t>(beam) << 32) | bin)) + 0x8cb92ba72f3d8dd7ull);
    h = mix64((h ^ stream) + 0xaef17502108ef2d9ull);
    return mix64(h + 0xf1357aea2e62a9c5ull); // one more round so the last word is fully mixed too
}

constexpr double kTwoPi = 6.283185307179586476925286766559;

} // namespace

double uniform01(std::uint64_t seed, std::uint64_t frame, std::uint32_t beam, std::uint32_t bin,
                 std::uint32_t stream) {
    // Top 53 bits, centred in their 2^-53 cell: the result lies in [2^-54, 1 - 2^-54], never 0 or 1,
    // so -log(u) and log(1 - u) are always finite.
    const std::uint64_t bits = hash_key(seed, frame, beam, bin, stream) >> 11;
    return (static_cast<double>(bits) + 0.5) * (1.0 / 9007199254740992.0);
}

double sample_exp1(std::uint64_t seed, std::uint64_t frame, std::uint32_t beam, std::uint32_t bin,
                   std::uint32_t stream) {
    return -std::log(uniform01(seed, frame, beam, bin, stream));
}

double sample_normal01(std::uint64_t seed, std::uint64_t frame, std::uint32_t beam, std::uint32_t bin,
                       std::uint32_t stream) {
    // Box-Muller (cosine branch) from streams `stream` and `stream + 1`.
    const double u1 = uniform01(seed, frame, beam, bin, stream);
    const double u2 = uniform01(seed, frame, beam, bin, stream + 1);
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(kTwoPi * u2);
}

double sample_gamma_unit_mean(double looks, std::uint64_t seed, std::uint64_t frame, std::uint32_t beam,
                              std::uint32_t bin, std::uint32_t stream) {
    if (!(looks > 0.0) || !std::isfinite(looks)) return 1.0;
    // Marsaglia & Tsang (2000) for shape a >= 1; for a < 1 draw Gamma(a + 1) and scale by U^(1/a).
    const bool boost = looks < 1.0;
    const double a = boost ? looks + 1.0 : looks;
    const double d = a - 1.0 / 3.0;
    const double c = 1.0 / std::sqrt(9.0 * d);
    double g = a; // fallback: the mean of Gamma(a, 1) (acceptance is > 95 % per try, so 16 misses ~ 1e-21)
    for (std::uint32_t attempt = 0; attempt < kGammaAttempts; ++attempt) {
        const std::uint32_t s = stream + 3 * attempt;
        const double x = sample_normal01(seed, frame, beam, bin, s);
        const double t = 1.0 + c * x;
        if (t <= 0.0) continue;
        const double v = t * t * t;
        const double u = uniform01(seed, frame, beam, bin, s + 2);
        const double x2 = x * x;
        if (u < 1.0 - 0.0331 * x2 * x2 || std::log(u) < 0.5 * x2 + d * (1.0 - v + std::log(v))) {
            g = d * v;
            break;
        }
    }
    if (boost) {
        const double u = uniform01(seed, frame, beam, bin, stream + 3 * kGammaAttempts);
        g *= std::pow(u, 1.0 / looks);
    }
    return g / looks; // Gamma(L, 1) / L = Gamma(L, 1/L)
}

} // namespace vksonar::host
