// CPU reference of the beamform stage (docs/pipeline.md §4): per-column range profiles (nearest,
// tent or footprint kernel), resampling of pixel columns onto the beam table, side-lobe convolution along beams.
// Every output cell is computed by one loop iteration with sums in increasing index order, so the
// result is deterministic (bit-identical run to run). Sums accumulate in Real; storage is float.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "core/sonar_math.hpp"
#include "stages/cpu_stages.h"

namespace vksonar::cpu {

template <class Real>
void beamform(const Plan& plan, const float* echo2, float* profiles, float* beam_profiles, float* polar, Real* acc) {
    using M = Math<Real>;
    const std::uint32_t C = plan.columns, R = plan.rows, beams = plan.beams, bins = plan.bins;
    Real range_min, inv_bin_width;
    if constexpr (std::is_same_v<Real, float>) {
        range_min = plan.params.range_min_m;
        inv_bin_width = plan.params.inv_bin_width_m;
    } else {
        range_min = plan.config.range_min_m;
        inv_bin_width = Real(1) / plan.bin_width_m;
    }
    const bool tent = plan.params.range_kernel == shared::kRangeKernelTent;
    const bool footprint = plan.params.range_kernel == shared::kRangeKernelFootprint;
    const Real jump_rel = static_cast<Real>(plan.params.edge_relative_jump);
    const std::int64_t last = static_cast<std::int64_t>(bins) - 1;

    // profile: per column, rows in increasing order. The loops run row-major for locality; every
    // accumulator (bin k, column c) still receives its additions in increasing row order (and, within
    // a row, the k0 share before the k0 + 1 share), so the sums are the per-column sums of the contract.
    const std::size_t cells = static_cast<std::size_t>(bins) * C;
    std::fill(acc, acc + cells, Real(0));
    for (std::uint32_t j = 0; j < R && bins > 0; ++j) {
        const float* e2 = echo2 + 2 * static_cast<std::size_t>(j) * C;
        for (std::uint32_t c = 0; c < C; ++c) {
            const Real e = static_cast<Real>(e2[2 * c]);
            if (!(e > Real(0))) continue;
            const Real r = static_cast<Real>(e2[2 * c + 1]);
            const Real x = M::range_bin_coord(r, range_min, inv_bin_width);
            const int nb = static_cast<int>(bins);
            if (footprint) {
                if (std::isnan(x)) continue;
                // the same five-row window as profile.comp (energy, range; 0 = no hit or outside the image)
                const auto row_echo = [&](std::int64_t row, int part) {
                    return row >= 0 && row < static_cast<std::int64_t>(R)
                               ? static_cast<Real>(echo2[2 * (static_cast<std::size_t>(row) * C + c) + part])
                               : Real(0);
                };
                const std::int64_t jj = j;
                const Real r_up2 = row_echo(jj - 2, 1), r_up = row_echo(jj - 1, 1);
                const Real r_down = row_echo(jj + 1, 1), r_down2 = row_echo(jj + 2, 1);
                const Real a = M::footprint_edge_offset(r_up, r_up2, r, r_down, jump_rel);
                const Real b = M::footprint_edge_offset(r_down, r_down2, r, r_up, jump_rel);
                const Real xl = x + M::footprint_lo(a, b) * inv_bin_width;
                const Real xh = x + M::footprint_hi(a, b) * inv_bin_width;
                const Real centre = Real(0.5) * (xl + xh);
                const Real width = std::min(std::max(xh - xl, Real(1)), static_cast<Real>(shared::kMaxFootprintBins));
                const Real lo = centre - Real(0.5) * width, hi = centre + Real(0.5) * width;
                Real g = 0;
                if (a != Real(0) && b != Real(0) && r_up2 > Real(0) && r_down2 > Real(0)) {
                    const Real w_up = Real(0.5) * std::abs(r_up2 - r) * inv_bin_width;
                    const Real w_down = Real(0.5) * std::abs(r - r_down2) * inv_bin_width;
                    // between the neighbours' footprint centres, (r + 2 r_q + r_q2) / 4 on either side
                    const Real span = (Real(2) * (r_up - r_down) + (r_up2 - r_down2)) * (Real(0.25) * inv_bin_width);
                    g = M::footprint_log_slope(row_echo(jj - 1, 0), w_up, row_echo(jj + 1, 0), w_down, span, width);
                }
                const Real inv_norm = Real(1) / (width * M::sinhc_of(Real(0.5) * g * width));
                // only the bins of the window: the rest of the footprint is gated away
                const int k_first = std::max(static_cast<int>(std::floor(lo)), 0);
                const int k_last = std::min(static_cast<int>(std::floor(hi)), nb - 1);
                for (int k = k_first; k <= k_last; ++k)
                    acc[static_cast<std::size_t>(k) * C + c] += M::footprint_share(lo, hi, centre, g, inv_norm, k) * e;
            } else if (tent) {
                Real t = x - Real(0.5);
                if (std::isnan(t)) continue;
                // Far outside the grid both shares are gated away anyway; keep floor() in int range.
                t = std::min(std::max(t, Real(-4)), static_cast<Real>(bins) + Real(4));
                const Real kf = std::floor(t);
                const Real w1 = t - kf;
                const std::int64_t k0 = static_cast<std::int64_t>(kf);
                // a share outside the window is gated away
                if (k0 >= 0 && k0 <= last) acc[static_cast<std::size_t>(k0) * C + c] += (Real(1) - w1) * e;
                if (k0 + 1 >= 0 && k0 + 1 <= last) acc[static_cast<std::size_t>(k0 + 1) * C + c] += w1 * e;
            } else {
                if (!(x >= Real(0) && x < static_cast<Real>(bins))) continue;
                const std::int64_t k = static_cast<std::int64_t>(std::floor(x));
                if (k >= 0 && k <= last) acc[static_cast<std::size_t>(k) * C + c] += e;
            }
        }
    }
    for (std::size_t i = 0; i < cells; ++i)
        profiles[i] = static_cast<float>(acc[i]);

    // resample: one cell per (beam j, bin k), columns in increasing order.
    for (std::uint32_t k = 0; k < bins; ++k) {
        const float* prof = profiles + static_cast<std::size_t>(k) * C;
        for (std::uint32_t j = 0; j < beams; ++j) {
            Real sum = Real(0);
            for (std::uint32_t c = plan.beam_column_begin[j]; c < plan.beam_column_end[j]; ++c) {
                const std::uint32_t share = M::resample_share(plan.column_beam[c], j, beams, plan.circular);
                const Real cw = static_cast<Real>(plan.column_weight[c]);
                const Real w = share == 1 ? cw : (share == 2 ? Real(1) - cw : Real(0));
                sum += w * static_cast<Real>(prof[c]);
            }
            beam_profiles[static_cast<std::size_t>(k) * beams + j] = static_cast<float>(sum);
        }
    }

    // sidelobe: polar(j) = sum_t weight[j][t] B(j - K + t), or a copy when the pattern is off.
    if (!plan.effects.horizontal_pattern) {
        std::copy(beam_profiles, beam_profiles + static_cast<std::size_t>(bins) * beams, polar);
        return;
    }
    const std::uint32_t taps = plan.sidelobe_taps;
    const std::int64_t K = (static_cast<std::int64_t>(taps) - 1) / 2;
    const std::int64_t nb = beams;
    const float* weights = plan.sidelobe_weight.data();
    for (std::uint32_t k = 0; k < bins; ++k) {
        const float* B = beam_profiles + static_cast<std::size_t>(k) * beams;
        float* out = polar + static_cast<std::size_t>(k) * beams;
        // An empty bin row stays exactly 0 (every term would add +0 to a +0 sum).
        if (std::all_of(B, B + beams, [](float b) { return b == 0.0f; })) {
            std::fill(out, out + beams, 0.0f);
            continue;
        }
        std::int64_t j = 0;
        while (j < nb) {
            if (j >= K && j + 3 + K < nb) {
                // Four interior beams at once: independent sums, each still in increasing t.
                const float* w0 = weights + static_cast<std::size_t>(j) * taps;
                const float* w1 = w0 + taps;
                const float* w2 = w1 + taps;
                const float* w3 = w2 + taps;
                const float* src = B + (j - K);
                Real s0 = Real(0), s1 = Real(0), s2 = Real(0), s3 = Real(0);
                for (std::uint32_t t = 0; t < taps; ++t) {
                    s0 += static_cast<Real>(w0[t]) * static_cast<Real>(src[t]);
                    s1 += static_cast<Real>(w1[t]) * static_cast<Real>(src[t + 1]);
                    s2 += static_cast<Real>(w2[t]) * static_cast<Real>(src[t + 2]);
                    s3 += static_cast<Real>(w3[t]) * static_cast<Real>(src[t + 3]);
                }
                out[j] = static_cast<float>(s0);
                out[j + 1] = static_cast<float>(s1);
                out[j + 2] = static_cast<float>(s2);
                out[j + 3] = static_cast<float>(s3);
                j += 4;
                continue;
            }
            const float* w = weights + static_cast<std::size_t>(j) * taps;
            if (plan.circular) { // source j - K + t modulo beams (plan.circular: K < beams / 2)
                Real sum = Real(0);
                for (std::int64_t t = 0; t < static_cast<std::int64_t>(taps); ++t)
                    sum += static_cast<Real>(w[t]) * static_cast<Real>(B[(j - K + t + nb) % nb]);
                out[j] = static_cast<float>(sum);
                ++j;
                continue;
            }
            // Taps whose source beam j - K + t lies in [0, beams), in increasing t.
            const std::int64_t first = std::max<std::int64_t>(0, K - j);
            const std::int64_t end = std::min<std::int64_t>(taps, nb + K - j);
            const float* src = B + (j - K);
            Real sum = Real(0);
            for (std::int64_t t = first; t < end; ++t)
                sum += static_cast<Real>(w[t]) * static_cast<Real>(src[t]);
            out[j] = static_cast<float>(sum);
            ++j;
        }
    }
}

std::size_t beamform_scratch_count(const Plan& plan) {
    return static_cast<std::size_t>(plan.bins) * plan.columns; // one accumulator per profile cell
}

template <class Real>
void beamform(const Plan& plan, const float* echo2, float* profiles, float* beam_profiles, float* polar) {
    std::vector<Real> acc(std::max<std::size_t>(beamform_scratch_count(plan), 1));
    beamform<Real>(plan, echo2, profiles, beam_profiles, polar, acc.data());
}

template void beamform<float>(const Plan&, const float*, float*, float*, float*, float*);
template void beamform<double>(const Plan&, const float*, float*, float*, float*, double*);
template void beamform<float>(const Plan&, const float*, float*, float*, float*);
template void beamform<double>(const Plan&, const float*, float*, float*, float*);

} // namespace vksonar::cpu
