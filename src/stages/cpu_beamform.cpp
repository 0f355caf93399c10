// CPU reference of the beamform stage's second pass (docs/pipeline.md §4): the range profiles
// (cpu_beamform_profile.cpp) resampled from their columns onto the beam table (the tent: the scan with the
// pattern off), then the horizontal pattern: each beam's near kernel over the profile columns within its
// reach, and the far side lobes (the columns on a coarse grid) beyond it. Every
// output cell is computed by one loop iteration with sums in increasing index order, so the result is
// deterministic (bit-identical run to run). Sums accumulate in Real; storage is float.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
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

// Far side lobes (plan.h far_cells), for kFarRows range bins at a time: each profile column's energy into
// its two cells per channel (far_deposit_weight), rounded to float as far_sidelobe.comp stores it, then
// the cells convolved with far_weight. Every (channel, cell, bin) sum runs over columns, then cells, in
// increasing order, as the shader's; the bins side by side are independent sums (vectorized).
constexpr std::uint32_t kFarRows = 8;

template <class Real> struct FarRows {
    std::array<Real, 3 * shared::kMaxFarCells * kFarRows> energy; // [(m * cells + c) * kFarRows + row]
    std::array<float, 3 * shared::kMaxFarCells * kFarRows> level; // the convolved cells, same layout
};

template <class Real>
typename Math<Real>::vec4 far_table_vec4(const std::vector<float>& table, std::int64_t j, std::size_t offset) {
    const float* b = table.data() + 8 * j + offset;
    return typename Math<Real>::vec4(b[0], b[1], b[2], b[3]);
}

// A beam's (or a profile column's) far side-lobe values, as the kernels compute them from Plan::far_beam_cell
// (far_column_cell), made once per plan (after the resample weights): its two cells c0, c1, their shares s0,
// s1 (far_cell_share), its phase (cos, sin), and per channel m its deposit weights into c0 and c1
// (far_deposit_weight). Beams read their cells back, columns deposit into them.
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

// far_sidelobe_rows's deposit: each profile column's energy in the batch's rows (bins k0 + r, r < rows; the
// accumulators rounded to float, the values the profiles hold) into its two cells per channel, scattered
// per column with the rows side by side: each cell still takes its columns in increasing order in every
// row (the shader gathers per cell). A column of zero energy in a row adds exactly +-0 there, which leaves
// the sum as it is (a sum that starts at +0 is never -0); a column with no cell (beyond a host camera's
// fan: c0 = cells) adds nothing (the shader adds 0 times it). The sums of the two cells the last column
// fed are held in registers (per channel) and written back when a column feeds another cell: the same
// additions in the same order, without a load and store per addition (consecutive columns share cells).
// The channel count is a constant, so that they stay in registers. far_column: FarBeam values per column;
// acc_k0: bin k0 of column 0 (columns T apart). energy: FarRows::energy, zeroed.
template <class Real, std::uint32_t kChannels>
[[gnu::always_inline]] inline void far_deposit_rows(const Real* far_column, const Real* acc_k0, std::size_t T,
                                                    std::uint32_t rows, std::uint32_t columns, std::uint32_t cells,
                                                    Real* energy_cells) {
    using V = typename FarLanes<Real>::type; // the batch's rows, lane r: bin k0 + r
    constexpr std::uint32_t kNone = ~0u;
    auto cell_at = [&](std::uint32_t m, std::uint32_t c) { return energy_cells + (m * cells + c) * kFarRows; };
    // (out parameters: a V is a value wider than the default build's registers, which a lambda must not return)
    auto load = [](V& v, const Real* p) { std::memcpy(&v, p, sizeof v); };
    auto store = [](Real* p, const V& v) { std::memcpy(p, &v, sizeof v); };
    std::uint32_t ca = kNone, cb = kNone; // the cells held: ca in sa, cb in sb
    V sa[kChannels] = {}, sb[kChannels] = {};
    for (std::uint32_t i = 0; i < columns; ++i) {
        V energy = {};
        bool any = false;
        const Real* column = acc_k0 + std::size_t(i) * T;
        for (std::uint32_t r = 0; r < rows; ++r) {
            energy[r] = static_cast<Real>(static_cast<float>(column[r]));
            any = any || energy[r] != Real(0);
        }
        if (!any) continue;
        const Real* f = far_column + std::size_t(i) * kFarBeamValues;
        const auto c0 = static_cast<std::uint32_t>(f[kFarC0]), c1 = static_cast<std::uint32_t>(f[kFarC1]);
        if (c0 >= cells) continue;  // no cell
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
[[gnu::always_inline]] inline void far_deposit_channels(const Real* far_column, const Real* acc_k0, std::size_t T,
                                                        std::uint32_t rows, std::uint32_t columns, std::uint32_t cells,
                                                        std::uint32_t channels, Real* energy_cells) {
    if (channels == 3)
        far_deposit_rows<Real, 3>(far_column, acc_k0, T, rows, columns, cells, energy_cells);
    else
        far_deposit_rows<Real, 1>(far_column, acc_k0, T, rows, columns, cells, energy_cells);
}
// In float also as an AVX2 build, where a batch's eight rows are one register and the six sums held
// (three channels) no longer spill: the same operations.
__attribute__((target_clones("avx2", "default"))) void far_deposit(const float* far_column, const float* acc_k0,
                                                                   std::size_t T, std::uint32_t rows,
                                                                   std::uint32_t columns, std::uint32_t cells,
                                                                   std::uint32_t channels, float* energy_cells) {
    far_deposit_channels<float>(far_column, acc_k0, T, rows, columns, cells, channels, energy_cells);
}
void far_deposit(const double* far_column, const double* acc_k0, std::size_t T, std::uint32_t rows,
                 std::uint32_t columns, std::uint32_t cells, std::uint32_t channels, double* energy_cells) {
    far_deposit_channels<double>(far_column, acc_k0, T, rows, columns, cells, channels, energy_cells);
}

template <class Real>
void far_sidelobe_rows(const Plan& plan, const Real* far_column, const Real* acc, std::uint32_t k0, std::uint32_t rows,
                       FarRows<Real>& far) {
    const std::uint32_t cells = plan.far_cells, channels = plan.far_channels;
    const std::size_t used = std::size_t(channels) * cells * kFarRows;
    std::fill(far.energy.begin(), far.energy.begin() + used, Real(0));
    far_deposit(far_column, acc + k0, profile_column_stride(plan), rows, plan.profile_columns, cells, channels,
                far.energy.data());
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

// The FarBeam values of every beam, then of every profile column.
std::size_t far_beam_count(const Plan& plan) {
    return plan.far_cells > 0 ? (std::size_t(plan.beams) + plan.profile_columns) * kFarBeamValues : 0;
}

// The near kernel's beams in groups of eight, j = 8 g + lane: beamform_beams's float loop sums a group's
// eight beams for eight bins at once (AVX2), over the group's columns (the union of its beams' columns,
// near_column_span), each column loaded once for the eight beams. Made once per plan: per group its first
// column and column count (as Real, exact below 2^24), then its weights column by column, the eight beams'
// weights of one column side by side: [g][t][lane], t < near_group_taps (0 where the column is not one
// of the beam's, and for the lanes past the last beam: a zero weight adds exactly +0, so every beam's sum
// is the one over its own columns). Not made with cpu.vector_loops off (the plain loop then reads the
// plan's table).
constexpr std::uint32_t kNearGroup = 8;

std::size_t near_group_count(const Plan& plan) {
    if (!plan.effects.horizontal_pattern || plan.near_column_begin.empty() ||
        plan.config.cpu_vector_loops == CpuVectorLoops::off)
        return 0;
    return (plan.beams + kNearGroup - 1) / kNearGroup;
}

// Group g's columns.
NearColumnSpan near_group_span(const Plan& plan, std::size_t g) {
    const auto first = static_cast<std::uint32_t>(g * kNearGroup);
    return near_column_span(plan, first, first + kNearGroup);
}

std::uint32_t near_group_taps(const Plan& plan) {
    std::uint32_t taps = 0;
    for (std::size_t g = 0; g < near_group_count(plan); ++g)
        taps = std::max(taps, near_group_span(plan, g).count);
    return taps;
}

// A group's values in the scratch: its first column and count, then its weights.
constexpr std::size_t kNearGroupHeader = 2;
std::size_t near_group_stride(std::uint32_t group_taps) {
    return kNearGroupHeader + std::size_t(group_taps) * kNearGroup;
}

// Column c of the range profiles, wrapped on a full circle (Plan::near_column_begin is unwrapped).
inline std::uint32_t wrap_column(std::int64_t c, std::uint32_t columns, bool circular) {
    if (!circular) return static_cast<std::uint32_t>(c);
    const std::int64_t n = columns;
    return static_cast<std::uint32_t>((c % n + n) % n);
}

} // namespace

// With focus bands (Plan::near_bands) every band has its groups, one band after another.
std::size_t resample_weight_count(const Plan& plan) {
    return column_weight_count(plan) + far_beam_count(plan) +
           std::size_t(plan.near_bands) * near_group_count(plan) * near_group_stride(near_group_taps(plan));
}

template <class Real> void resample_weights(const Plan& plan, Real* weights) {
    using M = Math<Real>;
    for (std::uint32_t j = 0; j < plan.beams; ++j)
        for (std::uint32_t c = plan.beam_column_begin[j]; c < plan.beam_column_end[j]; ++c)
            *weights++ = resample_weight<Real>(plan, j, c);
    const std::size_t far_entries = plan.far_cells > 0 ? std::size_t(plan.beams) + plan.profile_columns : 0;
    for (std::size_t e = 0; e < far_entries; ++e) { // FarBeam, the values the kernels give: beams, then columns
        const bool beam = e < plan.beams;
        const std::vector<float>& table = beam ? plan.far_beam_cell : plan.far_column_cell;
        const std::int64_t i = beam ? std::int64_t(e) : std::int64_t(e - plan.beams);
        const typename M::vec4 bc = far_table_vec4<Real>(table, i, 0), phase = far_table_vec4<Real>(table, i, 4);
        const auto c0 = static_cast<std::uint32_t>(bc.x), c1 = static_cast<std::uint32_t>(bc.y);
        Real* f = weights + e * kFarBeamValues;
        f[0] = static_cast<Real>(c0);
        f[1] = static_cast<Real>(c1);
        if (c0 >= plan.far_cells) { // a column with no cell (beyond a host camera's fan): every weight 0
            std::fill(f + 2, f + kFarBeamValues, Real(0));
            continue;
        }
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
    // A focus band's columns past its own reach weigh 0 (plan_beams.cpp): its groups leave them out, so a
    // band near focus costs what the configured reach does. (With one band nothing is left out: the plan
    // already drops a beam's zero weights at its ends.)
    const std::uint32_t group_taps = near_group_taps(plan);
    for (std::uint32_t band = 0; band < plan.near_bands; ++band)
        for (std::size_t g = 0; g < near_group_count(plan); ++g) {
            const NearColumnSpan span = near_group_span(plan, g);
            const float* band_weights =
                plan.near_column_weight.data() + std::size_t(band) * plan.beams * plan.near_column_taps;
            auto weight = [&](std::uint32_t t, std::uint32_t l) {
                const std::size_t j = g * kNearGroup + l;
                if (j >= plan.beams || t >= span.count) return Real(0);
                const std::int64_t own = span.first + t - plan.near_column_begin[j]; // the beam's own tap
                if (own < 0 || own >= std::int64_t(plan.near_column_count[j])) return Real(0);
                return static_cast<Real>(band_weights[j * plan.near_column_taps + std::size_t(own)]);
            };
            auto any_weight = [&](std::uint32_t t) {
                for (std::uint32_t l = 0; l < kNearGroup; ++l)
                    if (weight(t, l) != Real(0)) return true;
                return false;
            };
            std::uint32_t first = 0, end = span.count;
            while (first < end && !any_weight(first))
                ++first;
            while (end > first && !any_weight(end - 1))
                --end;
            *weights++ = static_cast<Real>(span.first + std::int64_t(first));
            *weights++ = static_cast<Real>(end - first);
            for (std::uint32_t t = 0; t < group_taps; ++t)
                for (std::uint32_t l = 0; l < kNearGroup; ++l)
                    *weights++ = t < end - first ? weight(first + t, l) : Real(0);
        }
}

namespace {

#if defined(__x86_64__) && defined(__GNUC__)
// The near kernel of one group of eight beams for eight bins (acc_k0: bin k0 of column 0), as
// beamform_beams's float loop makes them: beam 8 g + b's sum in register b, one lane per bin, each the
// same products added in the same (increasing column) order, no FMA in this target: the same floats.
// sums[r][b]: bin k0 + r, beam 8 g + b.
__attribute__((target("avx2"))) void near_group8(const float* wg, NearColumnSpan span, const float* acc_k0,
                                                 std::size_t T, std::uint32_t columns, bool circular,
                                                 float (&sums)[8][8]) {
    __m256 s[8];
    for (__m256& x : s)
        x = _mm256_setzero_ps();
    for (std::uint32_t t = 0; t < span.count; ++t, wg += kNearGroup) {
        const std::uint32_t c = wrap_column(span.first + t, columns, circular);
        const __m256 x = _mm256_loadu_ps(acc_k0 + std::size_t(c) * T);
        for (std::uint32_t b = 0; b < kNearGroup; ++b)
            s[b] = _mm256_add_ps(s[b], _mm256_mul_ps(_mm256_set1_ps(wg[b]), x));
    }
    store_transposed8(s, &sums[0][0], kNearGroup);
}
#else
void near_group8(const float*, NearColumnSpan, const float*, std::size_t, std::uint32_t, bool, float (&)[8][8]) {}
#endif

} // namespace

template <class Real>
void beamform_beams(const Plan& plan, const Real* acc, const Real* resample_w, float* beam_profiles, float* polar,
                    std::uint32_t bin_begin, std::uint32_t bin_end) {
    using M = Math<Real>;
    const std::uint32_t beams = plan.beams;
    // The tent: Frame::beam_profiles, the empty-bin test below, and with the pattern off the scan itself.
    resample_bins<Real>(plan, acc, resample_w, beam_profiles, bin_begin, bin_end);
    if (!plan.effects.horizontal_pattern) {
        std::copy(beam_profiles + std::size_t(bin_begin) * beams, beam_profiles + std::size_t(bin_end) * beams,
                  polar + std::size_t(bin_begin) * beams);
        return;
    }
    // The near kernel over the columns (Plan::near_column_*): polar(j) = sum_t w[j][t] profile(begin_j + t),
    // then plus the far side lobes (plan.h far_cells) of kFarRows bins at a time (far_sidelobe_rows), each
    // output adding far_sidelobe_level of its two cells (sidelobe.comp).
    const std::uint32_t cells = plan.far_cells, channels = plan.far_channels;
    const std::uint32_t columns = plan.profile_columns, taps = plan.near_column_taps;
    const std::size_t T = profile_column_stride(plan);
    FarRows<Real> far;
    std::uint32_t far_first = bin_begin;                                     // the first bin of the batch `far` holds
    const Real* far_beam = resample_w + column_weight_count(plan);           // FarBeam values per beam
    const Real* far_column = far_beam + std::size_t(beams) * kFarBeamValues; // and per profile column
    const Real* group_weights = far_beam + far_beam_count(plan);             // near_group_count's weights
    const std::size_t groups = near_group_count(plan);
    const std::uint32_t group_taps = groups > 0 ? near_group_taps(plan) : 0;
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
    const bool avx2 = std::is_same_v<Real, float> && groups > 0 && use_avx2(plan.config);
    for (std::uint32_t k0 = bin_begin; k0 < bin_end; k0 += kFarRows) {
        const std::uint32_t rows = std::min(kFarRows, bin_end - k0);
        float* out = polar + std::size_t(k0) * beams;
        const float* B = beam_profiles + std::size_t(k0) * beams;
        // Bins whose columns are all empty stay exactly 0 (every term would add +0 to a +0 sum, and the
        // far cells hold no energy): the tent's beams are 0 exactly where every column is.
        if (std::all_of(B, B + std::size_t(rows) * beams, [](float b) { return b == 0.0f; })) {
            std::fill(out, out + std::size_t(rows) * beams, 0.0f);
            continue;
        }
        far_first = k0;
        if (cells > 0) far_sidelobe_rows<Real>(plan, far_column, acc, k0, rows, far);
        // The AVX2 groups take eight bins of one focus band (the loop over beams below mixes bands).
        // (a fixed focus's bands are not monotonic in range: every bin is looked at).
        const std::uint32_t band = plan.near_bands > 1 ? plan.near_band_of_bin[k0] : 0;
        bool one_band = true;
        for (std::uint32_t r = 1; r < rows && plan.near_bands > 1; ++r)
            one_band = one_band && plan.near_band_of_bin[k0 + r] == band;
        if constexpr (std::is_same_v<Real, float>) {
            if (avx2 && rows == kFarRows && one_band) {
                if (cells > 0) far_values_into_rows(far_beam, far.level.data(), channels, cells, beams, rows, out);
                for (std::size_t g = 0; g < groups; ++g) {
                    float sums[8][8];
                    const float* group = group_weights + (band * groups + g) * near_group_stride(group_taps);
                    const NearColumnSpan span{static_cast<std::int64_t>(group[0]),
                                              static_cast<std::uint32_t>(group[1])};
                    near_group8(group + kNearGroupHeader, span, acc + k0, T, columns, plan.circular, sums);
                    const std::size_t j0 = g * kNearGroup, j_end = std::min<std::size_t>(j0 + kNearGroup, beams);
                    for (std::uint32_t r = 0; r < kFarRows; ++r)
                        for (std::size_t j = j0; j < j_end; ++j) {
                            float& cell = out[std::size_t(r) * beams + j];
                            cell = cells > 0 ? M::far_scan_cell(sums[r][j - j0], cell) : sums[r][j - j0]; // near + far
                        }
                }
                continue;
            }
        }
        // Each beam's rows side by side: kFarRows independent sums, each over the beam's columns in
        // increasing order (the profiles rounded to float first: the values they hold).
        // With focus bands each bin reads its own band's weights (Plan::near_band_of_bin).
        const std::size_t band_stride = std::size_t(beams) * taps;
        std::size_t band_offset[kFarRows] = {};
        for (std::uint32_t r = 0; r < rows && plan.near_bands > 1; ++r)
            band_offset[r] = plan.near_band_of_bin[k0 + r] * band_stride;
        for (std::uint32_t j = 0; j < beams; ++j) {
            Real sum[kFarRows] = {};
            const float* w = plan.near_column_weight.data() + std::size_t(j) * taps;
            for (std::uint32_t t = 0; t < plan.near_column_count[j]; ++t) {
                const Real* column =
                    acc +
                    std::size_t(wrap_column(std::int64_t(plan.near_column_begin[j]) + t, columns, plan.circular)) * T +
                    k0;
                for (std::uint32_t r = 0; r < rows; ++r)
                    sum[r] +=
                        static_cast<Real>(w[band_offset[r] + t]) * static_cast<Real>(static_cast<float>(column[r]));
            }
            for (std::uint32_t r = 0; r < rows; ++r)
                out[std::size_t(r) * beams + j] =
                    static_cast<float>(cells > 0 ? M::far_scan_cell(sum[r], far_at(j, k0 + r)) : sum[r]);
        }
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
