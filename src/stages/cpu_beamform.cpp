// CPU reference of the beamform stage's second pass (docs/pipeline.md §4): the range profiles
// (cpu_beamform_profile.cpp) resampled from their columns onto the beam table, then the side lobes along
// beams: the sampled pattern's kernel near each beam and the far side lobes beyond its reach. Every
// output cell is computed by one loop iteration with sums in increasing index order, so the result is
// deterministic (bit-identical run to run). Sums accumulate in Real; storage is float.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif
#include <type_traits>
#include <utility>
#include <vector>

#include "core/sonar_math.hpp"
#include "stages/cpu_simd.h"
#include "stages/cpu_stages.h"

namespace vksonar::cpu {

namespace {

// The weight beam j gives column c in the resample (resample_share of shaders/sonar_math.h).
template <class Real> Real resample_weight(const Plan& plan, std::uint32_t j, std::uint32_t c) {
    const std::uint32_t share = Math<Real>::resample_share(plan.column_beam[c], j, plan.beams, plan.circular);
    const Real cw = static_cast<Real>(plan.column_weight[c]);
    return share == 1 ? cw : (share == 2 ? Real(1) - cw : Real(0));
}

#if defined(__x86_64__) && defined(__GNUC__)
// Eight registers of eight lanes, s[b] lane l, as eight rows of eight: out[l * stride + b] = s[b][l].
__attribute__((target("avx2"), always_inline)) inline void store_transposed8(const __m256 (&s)[8], float* out,
                                                                             std::size_t stride) {
    const __m256 a0 = _mm256_unpacklo_ps(s[0], s[1]), a1 = _mm256_unpackhi_ps(s[0], s[1]);
    const __m256 a2 = _mm256_unpacklo_ps(s[2], s[3]), a3 = _mm256_unpackhi_ps(s[2], s[3]);
    const __m256 a4 = _mm256_unpacklo_ps(s[4], s[5]), a5 = _mm256_unpackhi_ps(s[4], s[5]);
    const __m256 a6 = _mm256_unpacklo_ps(s[6], s[7]), a7 = _mm256_unpackhi_ps(s[6], s[7]);
    const __m256 b0 = _mm256_shuffle_ps(a0, a2, _MM_SHUFFLE(1, 0, 1, 0));
    const __m256 b1 = _mm256_shuffle_ps(a0, a2, _MM_SHUFFLE(3, 2, 3, 2));
    const __m256 b2 = _mm256_shuffle_ps(a1, a3, _MM_SHUFFLE(1, 0, 1, 0));
    const __m256 b3 = _mm256_shuffle_ps(a1, a3, _MM_SHUFFLE(3, 2, 3, 2));
    const __m256 b4 = _mm256_shuffle_ps(a4, a6, _MM_SHUFFLE(1, 0, 1, 0));
    const __m256 b5 = _mm256_shuffle_ps(a4, a6, _MM_SHUFFLE(3, 2, 3, 2));
    const __m256 b6 = _mm256_shuffle_ps(a5, a7, _MM_SHUFFLE(1, 0, 1, 0));
    const __m256 b7 = _mm256_shuffle_ps(a5, a7, _MM_SHUFFLE(3, 2, 3, 2));
    _mm256_storeu_ps(out, _mm256_permute2f128_ps(b0, b4, 0x20));
    _mm256_storeu_ps(out + stride, _mm256_permute2f128_ps(b1, b5, 0x20));
    _mm256_storeu_ps(out + 2 * stride, _mm256_permute2f128_ps(b2, b6, 0x20));
    _mm256_storeu_ps(out + 3 * stride, _mm256_permute2f128_ps(b3, b7, 0x20));
    _mm256_storeu_ps(out + 4 * stride, _mm256_permute2f128_ps(b0, b4, 0x31));
    _mm256_storeu_ps(out + 5 * stride, _mm256_permute2f128_ps(b1, b5, 0x31));
    _mm256_storeu_ps(out + 6 * stride, _mm256_permute2f128_ps(b2, b6, 0x31));
    _mm256_storeu_ps(out + 7 * stride, _mm256_permute2f128_ps(b3, b7, 0x31));
}

// Beam j's eight sums: its columns' weights from w on (w then moves past them).
__attribute__((target("avx2"), always_inline)) inline __m256
resample_sum8(const Plan& plan, const float* acc_k0, std::size_t T, std::uint32_t j, const float*& w) {
    __m256 sum = _mm256_setzero_ps();
    const std::uint32_t c_begin = plan.beam_column_begin[j], c_end = plan.beam_column_end[j];
    for (std::uint32_t c = c_begin; c < c_end; ++c)
        sum = _mm256_add_ps(sum, _mm256_mul_ps(_mm256_set1_ps(w[c - c_begin]),
                                               _mm256_loadu_ps(acc_k0 + static_cast<std::size_t>(c) * T)));
    w += c_end - c_begin;
    return sum;
}
// resample_bins's block of eight bins k0 .. k0 + 7 in float, eight beams at a time: each beam's eight sums
// as the lanes of one AVX register (the same products added in the same order; no FMA, -ffp-contract=off:
// the same floats), the eight beams' registers transposed so that each bin row takes eight beams in
// one store. Beams past the last multiple of eight are stored lane by lane.
__attribute__((target("avx2"))) void resample_block8(const Plan& plan, const float* acc, const float* weights,
                                                     float* beam_profiles, std::uint32_t k0) {
    const std::uint32_t beams = plan.beams;
    const std::size_t T = profile_column_stride(plan);
    const float* w = weights;
    const float* acc_k0 = acc + k0;
    std::uint32_t j = 0;
    for (; j + 8 <= beams; j += 8) {
        __m256 s[8];
        for (std::uint32_t b = 0; b < 8; ++b)
            s[b] = resample_sum8(plan, acc_k0, T, j + b, w);
        store_transposed8(s, beam_profiles + static_cast<std::size_t>(k0) * beams + j, beams);
    }
    for (; j < beams; ++j) {
        float lanes[8];
        _mm256_storeu_ps(lanes, resample_sum8(plan, acc_k0, T, j, w));
        for (std::uint32_t l = 0; l < 8; ++l)
            beam_profiles[static_cast<std::size_t>(k0 + l) * beams + j] = lanes[l];
    }
}
#else
void resample_block8(const Plan&, const float*, const float*, float*, std::uint32_t) {}
#endif

// resample: one cell per (beam j, bin k), columns in increasing order, from the accumulators (rounded
// to float first: the values the profiles hold). Beam j's weights are weights[offset_j + c -
// beam_column_begin[j]], offset_j the sum of the earlier beams' column counts (resample_weights). Eight
// bins are summed side by side, each its own sum in the same order (eight independent chains).
template <class Real>
void resample_bins(const Plan& plan, const Real* acc, const Real* weights, float* beam_profiles,
                   std::uint32_t bin_begin, std::uint32_t bin_end) {
    constexpr std::uint32_t kBlock = 8;
    const std::uint32_t beams = plan.beams;
    const std::size_t T = profile_column_stride(plan);
    std::uint32_t k0 = bin_begin;
    auto block = [&](auto n_constant) {
        constexpr std::uint32_t n = decltype(n_constant)::value;
        const Real* w = weights;
        for (std::uint32_t j = 0; j < beams; ++j) {
            Real sum[n];
            for (std::uint32_t l = 0; l < n; ++l)
                sum[l] = Real(0);
            const std::uint32_t c_begin = plan.beam_column_begin[j], c_end = plan.beam_column_end[j];
            for (std::uint32_t c = c_begin; c < c_end; ++c) {
                const Real wc = w[c - c_begin];
                const Real* column = acc + static_cast<std::size_t>(c) * T + k0;
                for (std::uint32_t l = 0; l < n; ++l)
                    sum[l] += wc * static_cast<Real>(static_cast<float>(column[l]));
            }
            w += c_end - c_begin;
            for (std::uint32_t l = 0; l < n; ++l)
                beam_profiles[static_cast<std::size_t>(k0 + l) * beams + j] = static_cast<float>(sum[l]);
        }
    };
    const bool avx2 = std::is_same_v<Real, float> && use_avx2(plan.config);
    for (; k0 + kBlock <= bin_end; k0 += kBlock) {
        if constexpr (std::is_same_v<Real, float>) {
            if (avx2) {
                resample_block8(plan, acc, weights, beam_profiles, k0);
                continue;
            }
        }
        block(std::integral_constant<std::uint32_t, kBlock>());
    }
    for (; k0 < bin_end; ++k0)
        block(std::integral_constant<std::uint32_t, 1>());
}

// Far side lobes (plan.h far_cells), for kFarRows range bins at a time: each beam's energy into its
// two cells per channel (far_deposit_weight), rounded to float as far_sidelobe.comp stores it, then
// the cells convolved with far_weight. Every (channel, cell, bin) sum runs over beams, then cells, in
// increasing order, as the shader's; the bins side by side are independent sums (vectorized).
constexpr std::uint32_t kFarRows = 8;

template <class Real> struct FarRows {
    std::array<Real, 3 * shared::kMaxFarCells * kFarRows> energy; // [(m * cells + c) * kFarRows + row]
    std::array<float, 3 * shared::kMaxFarCells * kFarRows> level; // the convolved cells, same layout
};

template <class Real> typename Math<Real>::vec4 far_table_vec4(const Plan& plan, std::int64_t j, std::size_t offset) {
    const float* b = plan.far_beam_cell.data() + 8 * j + offset;
    return typename Math<Real>::vec4(b[0], b[1], b[2], b[3]);
}

// A beam's far side-lobe values, as the kernels compute them from Plan::far_beam_cell, made once per plan
// (after the resample weights): its two cells c0, c1, their shares s0, s1 (far_cell_share), its phase
// (cos, sin), and per channel m its deposit weights into c0 and c1 (far_deposit_weight).
constexpr std::size_t kFarBeamValues = 12;
enum FarBeam : std::size_t { kFarC0, kFarC1, kFarS0, kFarS1, kFarCos, kFarSin, kFarDeposit };

// kFarRows values of Real side by side, one per bin row of a batch (GCC's vector extension).
template <class Real> struct FarLanes { typedef Real type __attribute__((vector_size(kFarRows * sizeof(Real)))); };

// One channel's cells convolved with the far weights (w[a - b]: cell b into cell a), four cells a at a
// time, the batch's rows side by side: 4 x kFarRows independent sums, each over the live cells b
// (live[0, n), offset by `base` in energy's channel order) in increasing order. level: the channel's cells.
template <class Real>
[[gnu::always_inline]] inline void far_convolve_cells(const float* w, const Real* energy, const std::uint16_t* live,
                                                      std::size_t n, std::uint32_t base, std::uint32_t cells,
                                                      float* level) {
    using V = typename FarLanes<Real>::type;
    for (std::uint32_t a = 0; a < cells; a += 4) {
        V sum[4] = {};
        for (std::size_t i = 0; i < n; ++i) {
            const std::uint32_t b = live[i] - base;
            V e;
            std::memcpy(&e, energy + std::size_t(live[i]) * kFarRows, sizeof e);
            for (std::uint32_t q = 0; q < 4; ++q)
                sum[q] += static_cast<Real>(*(w + std::min(a + q, cells - 1) - b)) * e;
        }
        for (std::uint32_t q = 0; q < 4 && a + q < cells; ++q)
            for (std::uint32_t r = 0; r < kFarRows; ++r)
                level[(a + q) * kFarRows + r] = static_cast<float>(sum[q][r]);
    }
}
// In float also as an AVX2 build (a batch's eight rows in one register): the same operations.
__attribute__((target_clones("avx2", "default"))) void far_convolve(const float* w, const float* energy,
                                                                    const std::uint16_t* live, std::size_t n,
                                                                    std::uint32_t base, std::uint32_t cells,
                                                                    float* level) {
    far_convolve_cells<float>(w, energy, live, n, base, cells, level);
}
void far_convolve(const float* w, const double* energy, const std::uint16_t* live, std::size_t n, std::uint32_t base,
                  std::uint32_t cells, float* level) {
    far_convolve_cells<double>(w, energy, live, n, base, cells, level);
}

// far_sidelobe_rows's deposit: each beam's energy in the batch's rows (bins k0 + r, r < rows) into its two
// cells per channel, scattered per beam with the rows side by side: each cell still takes its beams in
// increasing order in every row (the shader gathers per cell). A beam of zero energy in a row adds exactly
// +-0 there, which leaves the sum as it is (a sum that starts at +0 is never -0). The sums of the two
// cells the last beam fed are held in registers (per channel) and written back when a beam feeds another
// cell: the same additions in the same order, without a load and store per addition (consecutive beams
// share cells). The channel count is a constant, so that they stay in registers. energy: FarRows::energy,
// zeroed.
template <class Real, std::uint32_t kChannels>
[[gnu::always_inline]] inline void far_deposit_rows(const Real* far_beam, const float* beam_profiles, std::uint32_t k0,
                                                    std::uint32_t rows, std::uint32_t beams, std::uint32_t cells,
                                                    Real* energy_cells) {
    using V = typename FarLanes<Real>::type; // the batch's rows, lane r: bin k0 + r
    constexpr std::uint32_t kNone = ~0u;
    auto cell_at = [&](std::uint32_t m, std::uint32_t c) { return energy_cells + (m * cells + c) * kFarRows; };
    // (out parameters: a V is a value wider than the default build's registers, which a lambda must not return)
    auto load = [](V& v, const Real* p) { std::memcpy(&v, p, sizeof v); };
    auto store = [](Real* p, const V& v) { std::memcpy(p, &v, sizeof v); };
    std::uint32_t ca = kNone, cb = kNone; // the cells held: ca in sa, cb in sb
    V sa[kChannels] = {}, sb[kChannels] = {};
    for (std::uint32_t i = 0; i < beams; ++i) {
        V energy = {};
        bool any = false;
        for (std::uint32_t r = 0; r < rows; ++r) {
            energy[r] = static_cast<Real>(beam_profiles[static_cast<std::size_t>(k0 + r) * beams + i]);
            any = any || energy[r] != Real(0);
        }
        if (!any) continue;
        const Real* f = far_beam + std::size_t(i) * kFarBeamValues;
        const auto c0 = static_cast<std::uint32_t>(f[kFarC0]), c1 = static_cast<std::uint32_t>(f[kFarC1]);
        if (c0 != ca || c1 != cb) { // c0 != c1 (plan_far_sidelobes)
            V na[kChannels], nb[kChannels];
            for (std::uint32_t m = 0; m < kChannels; ++m) {
                if (ca != kNone && ca != c0 && ca != c1) store(cell_at(m, ca), sa[m]);
                if (cb != kNone && cb != c0 && cb != c1) store(cell_at(m, cb), sb[m]);
            }
            for (std::uint32_t m = 0; m < kChannels; ++m) {
                if (c0 == ca || c0 == cb)
                    na[m] = c0 == ca ? sa[m] : sb[m];
                else
                    load(na[m], cell_at(m, c0));
                if (c1 == ca || c1 == cb)
                    nb[m] = c1 == ca ? sa[m] : sb[m];
                else
                    load(nb[m], cell_at(m, c1));
            }
            for (std::uint32_t m = 0; m < kChannels; ++m) {
                sa[m] = na[m];
                sb[m] = nb[m];
            }
            ca = c0;
            cb = c1;
        }
        for (std::uint32_t m = 0; m < kChannels; ++m) {
            sa[m] += f[kFarDeposit + 2 * m] * energy;
            sb[m] += f[kFarDeposit + 2 * m + 1] * energy;
        }
    }
    for (std::uint32_t m = 0; m < kChannels && ca != kNone; ++m) {
        store(cell_at(m, ca), sa[m]);
        store(cell_at(m, cb), sb[m]);
    }
}
// far_deposit_rows with the plan's channel count (3 or 1) as the constant.
template <class Real>
[[gnu::always_inline]] inline void
far_deposit_channels(const Real* far_beam, const float* beam_profiles, std::uint32_t k0, std::uint32_t rows,
                     std::uint32_t beams, std::uint32_t cells, std::uint32_t channels, Real* energy_cells) {
    if (channels == 3)
        far_deposit_rows<Real, 3>(far_beam, beam_profiles, k0, rows, beams, cells, energy_cells);
    else
        far_deposit_rows<Real, 1>(far_beam, beam_profiles, k0, rows, beams, cells, energy_cells);
}
// In float also as an AVX2 build, where a batch's eight rows are one register and the six sums held
// (three channels) no longer spill: the same operations.
__attribute__((target_clones("avx2", "default"))) void far_deposit(const float* far_beam, const float* beam_profiles,
                                                                   std::uint32_t k0, std::uint32_t rows,
                                                                   std::uint32_t beams, std::uint32_t cells,
                                                                   std::uint32_t channels, float* energy_cells) {
    far_deposit_channels<float>(far_beam, beam_profiles, k0, rows, beams, cells, channels, energy_cells);
}
void far_deposit(const double* far_beam, const float* beam_profiles, std::uint32_t k0, std::uint32_t rows,
                 std::uint32_t beams, std::uint32_t cells, std::uint32_t channels, double* energy_cells) {
    far_deposit_channels<double>(far_beam, beam_profiles, k0, rows, beams, cells, channels, energy_cells);
}

template <class Real>
void far_sidelobe_rows(const Plan& plan, const Real* far_beam, const float* beam_profiles, std::uint32_t k0,
                       std::uint32_t rows, FarRows<Real>& far) {
    const std::uint32_t cells = plan.far_cells, channels = plan.far_channels, beams = plan.beams;
    const std::size_t used = std::size_t(channels) * cells * kFarRows;
    std::fill(far.energy.begin(), far.energy.begin() + used, Real(0));
    far_deposit(far_beam, beam_profiles, k0, rows, beams, cells, channels, far.energy.data());
    // Cells with no energy in any of the rows are left out of the convolution: each would add exactly
    // +-0 to sums that start at +0 (the weights are finite).
    std::array<std::uint16_t, 3 * shared::kMaxFarCells> live;
    std::size_t live_count = 0;
    for (std::size_t mb = 0; mb < std::size_t(channels) * cells; ++mb) {
        bool any = false;
        for (std::uint32_t r = 0; r < kFarRows; ++r) {
            Real& e = far.energy[mb * kFarRows + r];
            e = static_cast<Real>(static_cast<float>(e));
            any = any || e != Real(0);
        }
        if (any) live[live_count++] = static_cast<std::uint16_t>(mb);
    }
    const float* w = plan.far_weight.data() + (cells - 1); // w[a - b]: cell b into cell a
    for (std::uint32_t m = 0; m < channels; ++m) {
        std::size_t first = 0, end = 0; // the live cells of channel m: live[first, end)
        while (first < live_count && live[first] < m * cells)
            ++first;
        end = first;
        while (end < live_count && live[end] < (m + 1) * cells)
            ++end;
        far_convolve(w, far.energy.data(), live.data() + first, end - first, m * cells, cells,
                     far.level.data() + std::size_t(m) * cells * kFarRows);
    }
}
// The far side lobes of a batch's rows k0 + r, r < rows, for beamform_beams's float group loop:
// far_sidelobe_level of every beam written into polar's rows (polar_k0: row k0), to which the loop then
// adds the convolution's sums. A beam's batch rows lie side by side in FarRows::level, so a beam is one
// vector of kFarRows lanes, and each lane takes far_at's operations in its order (per channel s0 level(c0)
// + s1 level(c1), then l0 - cos l1 - sin l2, then max(x, 0) as (x < 0) ? 0 : x): the same floats. Also
// as an AVX2 build (a beam's eight rows in one register).
__attribute__((target_clones("avx2", "default"))) void far_values_into_rows(const float* far_beam, const float* level,
                                                                            std::uint32_t channels, std::uint32_t cells,
                                                                            std::uint32_t beams, std::uint32_t rows,
                                                                            float* polar_k0) {
    using V = FarLanes<float>::type;
    for (std::uint32_t j = 0; j < beams; ++j) {
        const float* f = far_beam + std::size_t(j) * kFarBeamValues;
        const auto c0 = static_cast<std::uint32_t>(f[kFarC0]), c1 = static_cast<std::uint32_t>(f[kFarC1]);
        V l[3] = {};
        for (std::uint32_t m = 0; m < channels; ++m) {
            V v0, v1;
            std::memcpy(&v0, level + (std::size_t(m) * cells + c0) * kFarRows, sizeof v0);
            std::memcpy(&v1, level + (std::size_t(m) * cells + c1) * kFarRows, sizeof v1);
            l[m] = f[kFarS0] * v0 + f[kFarS1] * v1;
        }
        const V x = l[0] - f[kFarCos] * l[1] - f[kFarSin] * l[2];
        const V value = x < V{} ? V{} : x;
        for (std::uint32_t r = 0; r < rows; ++r)
            polar_k0[std::size_t(r) * beams + j] = value[r];
    }
}

} // namespace

namespace {

std::size_t column_weight_count(const Plan& plan) {
    std::size_t n = 0;
    for (std::uint32_t j = 0; j < plan.beams; ++j)
        n += plan.beam_column_end[j] - plan.beam_column_begin[j];
    return n;
}

std::size_t far_beam_count(const Plan& plan) {
    return plan.far_cells > 0 ? std::size_t(plan.beams) * kFarBeamValues : 0;
}

// The side-lobe convolution's beams in groups of four, j = 4 q + lane: beamform_beams sums a group's
// four beams as the lanes of one vector, from a copy of the bin row padded by K beams either side (zeros,
// or the wrapped beams with plan.circular) so that every tap reads inside it. Their weights, made once
// per plan, are stored per group tap by tap, the four beams' weights of tap t side by side:
// [q][t][lane] (0 for the lanes past the last beam). Not made for a row of more than kMaxPaddedRow beams
// with its padding, nor with cpu.vector_loops off: those take the scalar loop.
constexpr std::size_t kMaxPaddedRow = 8192;

std::size_t sidelobe_group_count(const Plan& plan) {
    if (!plan.effects.horizontal_pattern || plan.config.cpu_vector_loops == CpuVectorLoops::off) return 0;
    const std::size_t K = (plan.sidelobe_taps - 1) / 2;
    if (plan.beams + 2 * K + 4 > kMaxPaddedRow) return 0;
    return (plan.beams + 3) / 4;
}

} // namespace

std::size_t resample_weight_count(const Plan& plan) {
    return column_weight_count(plan) + far_beam_count(plan) + sidelobe_group_count(plan) * 4 * plan.sidelobe_taps;
}

template <class Real> void resample_weights(const Plan& plan, Real* weights) {
    using M = Math<Real>;
    for (std::uint32_t j = 0; j < plan.beams; ++j)
        for (std::uint32_t c = plan.beam_column_begin[j]; c < plan.beam_column_end[j]; ++c)
            *weights++ = resample_weight<Real>(plan, j, c);
    for (std::uint32_t j = 0; j < plan.beams && plan.far_cells > 0; ++j) { // FarBeam, the values the kernels give
        const typename M::vec4 bc = far_table_vec4<Real>(plan, j, 0), phase = far_table_vec4<Real>(plan, j, 4);
        const auto c0 = static_cast<std::uint32_t>(bc.x), c1 = static_cast<std::uint32_t>(bc.y);
        Real* f = weights + std::size_t(j) * kFarBeamValues;
        f[0] = static_cast<Real>(c0);
        f[1] = static_cast<Real>(c1);
        f[2] = M::far_cell_share(bc, c0);
        f[3] = M::far_cell_share(bc, c1);
        f[4] = phase.x;
        f[5] = phase.y;
        for (std::uint32_t m = 0; m < 3; ++m) {
            f[6 + 2 * m] = M::far_deposit_weight(bc, phase, c0, m);
            f[7 + 2 * m] = M::far_deposit_weight(bc, phase, c1, m);
        }
    }
    weights += far_beam_count(plan);
    const std::uint32_t taps = plan.sidelobe_taps;
    for (std::size_t q = 0; q < sidelobe_group_count(plan); ++q)
        for (std::uint32_t t = 0; t < taps; ++t)
            for (std::uint32_t l = 0; l < 4; ++l) {
                const std::size_t j = 4 * q + l;
                *weights++ = j < plan.beams ? static_cast<Real>(plan.sidelobe_weight[j * taps + t]) : Real(0);
            }
}

namespace {

#if defined(__x86_64__) && defined(__GNUC__)
// The side-lobe sums of one run of four groups (16 beams) for one or two bin rows (row1 null: one), as
// beamform_beams's float loop makes them, two groups per AVX register: lanes 0-3 group g, 4-7 group
// g + 1, each lane the same products added in the same (increasing t) order, no FMA in this target, so
// the same floats. sums[r][4 g + l]: row r, beam j0 + 4 g + l; row0, row1 at the run's first beam
// (padded rows: beam j0 + 4 g + l takes row[t + 4 g + l]).
__attribute__((target("avx2"))) void sidelobe_run8(const float* wq, std::uint32_t taps, const float* row0,
                                                   const float* row1, std::uint32_t t_begin, std::uint32_t t_end,
                                                   float (&sums)[2][16]) {
    __m256 s0a = _mm256_setzero_ps(), s0b = s0a, s1a = s0a, s1b = s0a; // row r, groups 0-1 (a) and 2-3 (b)
    // group g's weights at tap t: w[g][t]; groups g and g + 1 side by side in one register
    const float* w0 = wq + std::size_t(t_begin) * 4;
    const std::size_t group = std::size_t(taps) * 4;
    for (std::uint32_t t = t_begin; t < t_end; ++t, w0 += 4) {
        const __m256 wa = _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(w0)), _mm_loadu_ps(w0 + group), 1);
        const __m256 wb =
            _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(w0 + 2 * group)), _mm_loadu_ps(w0 + 3 * group), 1);
        s0a = _mm256_add_ps(s0a, _mm256_mul_ps(wa, _mm256_loadu_ps(row0 + t)));
        s0b = _mm256_add_ps(s0b, _mm256_mul_ps(wb, _mm256_loadu_ps(row0 + t + 8)));
        if (row1 != nullptr) { // the same in every iteration: the compiler unswitches the loop
            s1a = _mm256_add_ps(s1a, _mm256_mul_ps(wa, _mm256_loadu_ps(row1 + t)));
            s1b = _mm256_add_ps(s1b, _mm256_mul_ps(wb, _mm256_loadu_ps(row1 + t + 8)));
        }
    }
    _mm256_storeu_ps(sums[0], s0a);
    _mm256_storeu_ps(sums[0] + 8, s0b);
    _mm256_storeu_ps(sums[1], s1a);
    _mm256_storeu_ps(sums[1] + 8, s1b);
}
#else
void sidelobe_run8(const float*, std::uint32_t, const float*, const float*, std::uint32_t, std::uint32_t,
                   float (&)[2][16]) {}
#endif

} // namespace

template <class Real>
void beamform_beams(const Plan& plan, const Real* acc, const Real* resample_w, float* beam_profiles, float* polar,
                    std::uint32_t bin_begin, std::uint32_t bin_end) {
    using M = Math<Real>;
    const std::uint32_t beams = plan.beams;
    resample_bins<Real>(plan, acc, resample_w, beam_profiles, bin_begin, bin_end);

    // sidelobe: polar(j) = sum_t weight[j][t] B(j - K + t), or a copy when the pattern is off.
    if (!plan.effects.horizontal_pattern) {
        std::copy(beam_profiles + std::size_t(bin_begin) * beams, beam_profiles + std::size_t(bin_end) * beams,
                  polar + std::size_t(bin_begin) * beams);
        return;
    }
    const std::uint32_t taps = plan.sidelobe_taps;
    const std::int64_t K = (static_cast<std::int64_t>(taps) - 1) / 2;
    const std::int64_t nb = beams;
    const float* weights = plan.sidelobe_weight.data();
    const std::uint32_t* tap_begin = plan.sidelobe_tap_begin.data();
    const std::uint32_t* tap_end = plan.sidelobe_tap_end.data();
    // Far side lobes (plan.h far_cells), kFarRows bins at a time (far_sidelobe_rows); each output adds
    // far_sidelobe_level of its two cells (sidelobe.comp).
    const std::uint32_t cells = plan.far_cells, channels = plan.far_channels;
    FarRows<Real> far;
    std::uint32_t far_first = bin_begin;                           // the first bin of the batch `far` holds
    const Real* far_beam = resample_w + column_weight_count(plan); // FarBeam values per beam
    const Real* group_weights = far_beam + far_beam_count(plan);   // sidelobe_group_count's weights
    const std::size_t groups = sidelobe_group_count(plan);
    auto far_at = [&](std::int64_t j, std::uint32_t k) -> Real {
        if (cells == 0) return Real(0);
        const Real* f = far_beam + std::size_t(j) * kFarBeamValues;
        const auto c0 = static_cast<std::uint32_t>(f[kFarC0]), c1 = static_cast<std::uint32_t>(f[kFarC1]);
        const std::uint32_t r = k - far_first;
        Real l[3] = {Real(0), Real(0), Real(0)};
        for (std::uint32_t m = 0; m < channels; ++m)
            l[m] = f[kFarS0] * static_cast<Real>(far.level[(m * cells + c0) * kFarRows + r]) +
                   f[kFarS1] * static_cast<Real>(far.level[(m * cells + c1) * kFarRows + r]);
        return M::far_sidelobe_level(typename M::vec4(f[kFarCos], f[kFarSin], Real(0), Real(0)), l[0], l[1], l[2]);
    };
    auto empty_row = [&](const float* row) { return std::all_of(row, row + beams, [](float b) { return b == 0.0f; }); };
    using V = typename Lanes4<Real>::type;
    float padded[2][kMaxPaddedRow]; // padded[r][i]: beam i - K of the r-th row of a pair
    const bool avx2 = use_avx2(plan.config);
    for (std::uint32_t k = bin_begin; k < bin_end;) {
        if (cells > 0 && (k == bin_begin || k - far_first == kFarRows)) {
            far_first = k;
            const std::uint32_t rows = std::min(kFarRows, bin_end - k);
            far_sidelobe_rows<Real>(plan, far_beam, beam_profiles, k, rows, far);
            if constexpr (std::is_same_v<Real, float>) {
                if (groups > 0) // the group loop below adds its sums to these
                    far_values_into_rows(far_beam, far.level.data(), channels, cells, beams, rows,
                                         polar + std::size_t(k) * beams);
            }
        }
        const float* B = beam_profiles + static_cast<std::size_t>(k) * beams;
        // An empty bin row stays exactly 0 (every term would add +0 to a +0 sum).
        if (empty_row(B)) {
            std::fill(polar + static_cast<std::size_t>(k) * beams, polar + static_cast<std::size_t>(k + 1) * beams,
                      0.0f);
            ++k;
            continue;
        }
        if (groups > 0) {
            // Two bin rows at a time where the next one has energy too (and its far side lobes are in the
            // same batch): each weight is read once for both rows, and the eight sums in flight hide the
            // adds' latency. Every beam, four groups (16 beams) at a time: each beam's sum is one lane,
            // still in increasing t, over the taps where any beam of the groups has a weight, from the
            // padded row (a zero weight, or a zero beyond the fan's edge, adds exactly +0: the same sums
            // as the scalar loop below, which leaves those terms out). Rows never mix: the same sums as
            // one row at a time.
            const bool pair = k + 1 < bin_end && (cells == 0 || k + 1 - far_first < kFarRows) && !empty_row(B + beams);
            const std::uint32_t rows = pair ? 2 : 1;
            for (std::uint32_t r = 0; r < rows; ++r) {
                // padded[r][K + b] = beam b for b in [-K, nb + K + 4): the beams themselves, then the
                // padding either side (the wrapped beams with plan.circular, where K < nb / 2, else zeros)
                const float* row = B + std::size_t(r) * beams;
                float* out = padded[r] + K;
                std::memcpy(out, row, sizeof(float) * beams);
                for (std::int64_t b = -K; b < 0; ++b)
                    out[b] = plan.circular ? row[b + nb] : 0.0f;
                for (std::int64_t b = nb; b < nb + K + 4; ++b)
                    out[b] = plan.circular ? row[(b + nb) % nb] : 0.0f;
            }
            for (std::size_t q0 = 0; q0 < groups; q0 += 4) {
                const std::size_t n = std::min<std::size_t>(4, groups - q0);
                const std::size_t j0 = 4 * q0, j_end = std::min<std::size_t>(j0 + 4 * n, beams);
                std::uint32_t t_begin = taps, t_end = 0;
                for (std::size_t i = j0; i < j_end; ++i) {
                    t_begin = std::min(t_begin, tap_begin[i]);
                    t_end = std::max(t_end, tap_end[i]);
                }
                const Real* wq = group_weights + q0 * 4 * taps;
                V s[2][4] = {};
                // s[r][g] += w(g, t) * row r's beams j0 + 4 g + t - K .. + 3 (out parameters: a double V is
                // an AVX-sized value)
                auto load = [&](V& x, std::uint32_t r, std::size_t g, std::uint32_t t) {
                    const float* src = padded[r] + j0 + t + 4 * g; // beam j0 + 4 g + l takes src[l]
                    if constexpr (std::is_same_v<Real, float>) {
                        std::memcpy(&x, src, sizeof x);
                    } else {
                        for (std::uint32_t l = 0; l < 4; ++l)
                            x[l] = static_cast<Real>(src[l]);
                    }
                };
                auto mac = [&](std::uint32_t rows_used, std::size_t g, std::uint32_t t) {
                    V w, x;
                    std::memcpy(&w, wq + (g * taps + t) * 4, sizeof w);
                    load(x, 0, g, t);
                    s[0][g] += w * x;
                    if (rows_used == 2) {
                        load(x, 1, g, t);
                        s[1][g] += w * x;
                    }
                };
                if (std::is_same_v<Real, float> && n == 4 && avx2) {
                    if constexpr (std::is_same_v<Real, float>) {
                        float sums[2][16];
                        sidelobe_run8(wq, taps, padded[0] + j0, rows == 2 ? padded[1] + j0 : nullptr, t_begin, t_end,
                                      sums);
                        std::memcpy(s, sums, sizeof sums);
                    }
                } else if (n == 4 && rows == 2) {
                    for (std::uint32_t t = t_begin; t < t_end; ++t) {
                        mac(2, 0, t);
                        mac(2, 1, t);
                        mac(2, 2, t);
                        mac(2, 3, t);
                    }
                } else if (n == 4) {
                    for (std::uint32_t t = t_begin; t < t_end; ++t) {
                        mac(1, 0, t);
                        mac(1, 1, t);
                        mac(1, 2, t);
                        mac(1, 3, t);
                    }
                } else {
                    for (std::uint32_t t = t_begin; t < t_end; ++t)
                        for (std::size_t g = 0; g < n; ++g)
                            mac(rows, g, t);
                }
                for (std::uint32_t r = 0; r < rows; ++r) {
                    float* out = polar + static_cast<std::size_t>(k + r) * beams;
                    if constexpr (std::is_same_v<Real, float>) {
                        if (cells > 0) { // the far side lobes are in out already (far_values_into_rows)
                            for (std::size_t jj = j0; jj < j_end; ++jj)
                                out[jj] = s[r][(jj - j0) / 4][(jj - j0) % 4] + out[jj];
                            continue;
                        }
                    }
                    for (std::size_t jj = j0; jj < j_end; ++jj) {
                        const std::size_t g = (jj - j0) / 4, l = (jj - j0) % 4;
                        out[jj] = static_cast<float>(s[r][g][l] + far_at(static_cast<std::int64_t>(jj), k + r));
                    }
                }
            }
            k += rows;
            continue;
        }
        float* out = polar + static_cast<std::size_t>(k) * beams;
        std::int64_t j = 0;
        while (j < nb) {
            const float* w = weights + static_cast<std::size_t>(j) * taps;
            if (plan.circular) { // source j - K + t modulo beams (plan.circular: K < beams / 2)
                Real sum = Real(0);
                for (std::int64_t t = 0; t < static_cast<std::int64_t>(taps); ++t)
                    sum += static_cast<Real>(w[t]) * static_cast<Real>(B[(j - K + t + nb) % nb]);
                out[j] = static_cast<float>(sum + far_at(j, k));
                ++j;
                continue;
            }
            // Taps whose source beam j - K + t lies in [0, beams) and whose weight is not 0, in increasing t.
            const std::int64_t first = std::max<std::int64_t>(std::max<std::int64_t>(0, K - j), tap_begin[j]);
            const std::int64_t end = std::min<std::int64_t>(std::min<std::int64_t>(taps, nb + K - j), tap_end[j]);
            const float* src = B + (j - K);
            Real sum = Real(0);
            for (std::int64_t t = first; t < end; ++t)
                sum += static_cast<Real>(w[t]) * static_cast<Real>(src[t]);
            out[j] = static_cast<float>(sum + far_at(j, k));
            ++j;
        }
        ++k;
    }
}

template <class Real>
void beamform(const Plan& plan, const float* echo2, float* profiles, float* beam_profiles, float* polar,
              Real* scratch) {
    Real* resample_w = scratch + beamform_accumulator_count(plan);
    resample_weights<Real>(plan, resample_w);
    beamform_profiles<Real>(plan, echo2, profiles, scratch, 0, plan.profile_columns);
    beamform_beams<Real>(plan, scratch, resample_w, beam_profiles, polar, 0, plan.bins);
}

std::size_t beamform_scratch_count(const Plan& plan) {
    return beamform_accumulator_count(plan) + resample_weight_count(plan);
}

template <class Real>
void beamform(const Plan& plan, const float* echo2, float* profiles, float* beam_profiles, float* polar) {
    std::vector<Real> scratch(std::max<std::size_t>(beamform_scratch_count(plan), 1));
    beamform<Real>(plan, echo2, profiles, beam_profiles, polar, scratch.data());
}

template void resample_weights<float>(const Plan&, float*);
template void resample_weights<double>(const Plan&, double*);
template void beamform_beams<float>(const Plan&, const float*, const float*, float*, float*, std::uint32_t,
                                    std::uint32_t);
template void beamform_beams<double>(const Plan&, const double*, const double*, float*, float*, std::uint32_t,
                                     std::uint32_t);
template void beamform<float>(const Plan&, const float*, float*, float*, float*, float*);
template void beamform<double>(const Plan&, const float*, float*, float*, float*, double*);
template void beamform<float>(const Plan&, const float*, float*, float*, float*);
template void beamform<double>(const Plan&, const float*, float*, float*, float*);

} // namespace vksonar::cpu
