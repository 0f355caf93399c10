// Counter-based RNG for the host noise stage: every draw is a pure function of
// (seed, frame, beam, bin, stream), so reruns, the CPU and the Vulkan backends agree exactly and the
// noise of one cell never depends on the order cells are visited.
#include <cmath>
#include <cstdint>

#include "host/host_stages.h"
#include "host/rng.h"

namespace vksonar::host {
namespace {

constexpr double kTwoPi = 6.283185307179586476925286766559;

} // namespace

double uniform01(std::uint64_t seed, std::uint64_t frame, std::uint32_t beam, std::uint32_t bin, std::uint32_t stream) {
    return rng::uniform01(rng::frame_key(seed, frame), beam, bin, stream);
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
