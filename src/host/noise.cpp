// Host stage 5 (docs/pipeline.md §5/6): clean -> intensity (speckle, ambient noise, TVG) -> display.
#include <algorithm>
#include <cassert>
#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstring>

#include "host/host_stages.h"
#include "host/rng.h"
#include "host/workers.h"

namespace vksonar::host {
namespace {

// Stream layout of one cell: speckle draws first (the gamma model uses kGammaStreams of them), then
// the ambient-noise draw. Fixed so that switching the speckle model never changes the noise draw.
constexpr std::uint32_t kSpeckleStream = 0;
constexpr std::uint32_t kNoiseStream = 64;
static_assert(kSpeckleStream + kGammaStreams <= kNoiseStream, "speckle streams overlap the noise stream");
// The grain's grid points (Plan::grain), keyed by (point, bin): two streams each (power, phase), apart from
// the cells' so that beam_correlation none and pattern never share a draw.
constexpr std::uint32_t kSpeckleGrainStream = 96;
constexpr std::uint32_t kNoiseGrainStream = 98;
// Gamma speckle's further looks (RowDraws::speckle_looks): look l >= 1 from streams 100 + 2 (l - 1) and the
// next, so its first look is Rayleigh speckle's field, and one look the same draws.
constexpr std::uint32_t kSpeckleLookStream = 100;
static_assert(kSpeckleLookStream >= kNoiseGrainStream + 2, "gamma's looks would draw the noise's field");

constexpr float kMinIntensityF = 1e-30f; // dB floor guard: 10 log10(1e-30) = -300 dB, far below any window
constexpr double kMinTvgRange = 1e-3;    // m; TVG's log10(r) at r -> 0

} // namespace

namespace {

struct NoiseTask {
    const Plan* plan;
    std::uint64_t seed, frame_index;
    Frame* frame;
    const float* clean_source;
    const NoiseDraws* draws;
};

void noise_bins(const Plan& plan, std::uint64_t seed, std::uint64_t frame_index, Frame& frame, const NoiseDraws* draws,
                std::size_t bin_begin, std::size_t bin_end);

// noise_bins, each bin's row of the clean scan first copied from clean_source (when there is one).
void copy_and_noise_bins(const NoiseTask& t, std::size_t bin_begin, std::size_t bin_end) {
    if (t.clean_source != nullptr) {
        const std::size_t beams = t.plan->beams;
        std::memcpy(t.frame->clean.data() + bin_begin * beams, t.clean_source + bin_begin * beams,
                    (bin_end - bin_begin) * beams * sizeof(float));
    }
    noise_bins(*t.plan, t.seed, t.frame_index, *t.frame, t.draws, bin_begin, bin_end);
}

// Blocks of kBinBlock bins, taken by the threads as they come: every cell is a pure function of its key,
// so the split changes nothing in the output.
constexpr std::uint32_t kBinBlock = 32;

// Whether the plan adds ambient noise: the effect on and each beam's level present (resolve_noise_floor;
// a plan without them adds none).
bool adds_ambient_noise(const Plan& plan) {
    return plan.effects.ambient_noise && plan.beam_noise.size() >= plan.beams;
}

} // namespace

RowDraws row_draws_of(const Plan& plan) {
    const SonarConfig& cfg = plan.config;
    const bool rows = plan.beams < rng::kMaxCell32 && plan.bins < rng::kMaxCell32;
    RowDraws out{rows && plan.effects.speckle && cfg.speckle == SpeckleModel::rayleigh,
                 rows && adds_ambient_noise(plan)};
    // gamma speckle in rows only where it is grained: a whole number of looks, each a grained field
    const double looks = cfg.speckle_looks;
    if (rows && plan.effects.speckle && cfg.speckle == SpeckleModel::gamma && plan.grain.taps > 0 && looks >= 1.0 &&
        looks <= kGrainMaxLooks && looks == std::floor(looks)) {
        out.speckle = true;
        out.speckle_looks = static_cast<std::uint32_t>(looks);
    }
    return out;
}

namespace {

// A block's kGrainLanes beams side by side (GCC's vector extension: one AVX-512 register, two AVX2 ones or
// four SSE2 ones, lane by lane the same operations).
typedef float GrainLanes __attribute__((vector_size(kGrainLanes * sizeof(float))));

// The grained draws (Plan::grain; docs/pipeline.md §5, "Grain") of the beams of chunk c, [grain.chunk[c],
// grain.chunk[c + 1]), in bin `bin`, into out[0, count): the chunk's grid points as complex normals of unit
// power (power Exp(1) from one hash, phase from another); each block of kGrainLanes beams sums its points'
// weighted values side by side in registers (every beam over its points in increasing order, whatever the
// vector width; a weight of 0 adds an exact 0), and each beam's draw is its field's power: Exp(1) in every
// cell, correlated between beams as their patterns overlap. Inlined into each build of its callers, whose
// loops it vectorizes with them.
[[gnu::always_inline]] inline void grain_draws(const Plan& plan, const rng::FrameKey& key, std::uint32_t bin,
                                               std::uint32_t stream, std::size_t c, float* out) {
    const std::uint32_t count = plan.grain.chunk[c + 1] - plan.grain.chunk[c];
    const std::uint32_t points = plan.grain.chunk_points[c]; // <= kGrainChunkPoints (plan_grain)
    const std::int64_t cells = plan.grain.cells;
    std::int64_t m = std::int64_t(plan.grain.chunk_low[c]) % cells; // on a circle the points wrap
    if (m < 0) m += cells;
    std::uint32_t point[kGrainChunkPoints]; // the wrap in a loop of its own: the draws' loop then vectorizes
    for (std::uint32_t i = 0; i < points; ++i) {
        point[i] = static_cast<std::uint32_t>(m);
        if (++m == cells) m = 0;
    }
    float re[kGrainChunkPoints], im[kGrainChunkPoints];
    const float* phases = plan.grain.phase.data();
    for (std::uint32_t i = 0; i < points; ++i) {
        const float amplitude = std::sqrt(rng::exp1_cell32(key, point[i], bin, stream));
        const std::uint32_t phase = rng::hash_cell32(key, point[i], bin, stream + 1) >> 20; // kGrainPhases = 2^12
        re[i] = amplitude * phases[2 * phase];
        im[i] = amplitude * phases[2 * phase + 1];
    }
    const std::uint32_t block_begin = plan.grain.chunk_block[c], block_end = plan.grain.chunk_block[c + 1];
    for (std::uint32_t b = block_begin; b < block_end; ++b) {
        const std::uint32_t q0 = (b - block_begin) * kGrainLanes;
        const float* w = plan.grain.weight.data() + plan.grain.block_weight[b];
        GrainLanes field_re = {}, field_im = {};
        for (std::uint32_t i = plan.grain.block_points[2 * b]; i < plan.grain.block_points[2 * b + 1];
             ++i, w += kGrainLanes) {
            GrainLanes weight;
            std::memcpy(&weight, w, sizeof weight);
            field_re += weight * re[i];
            field_im += weight * im[i];
        }
        const GrainLanes power = field_re * field_re + field_im * field_im;
        const std::uint32_t lanes = std::min(kGrainLanes, count - q0);
        for (std::uint32_t l = 0; l < lanes; ++l)
            out[q0 + l] = power[l];
    }
}

// The speckle of chunk c in bin `bin` (grain_draws of stream kSpeckleGrainStream), or with `looks` > 1 the mean
// of that many looks' grained draws (gamma speckle; RowDraws::speckle_looks), summed in look order and scaled by
// 1 / looks in float, the same operations in every build.
[[gnu::always_inline]] inline void grain_speckle(const Plan& plan, const rng::FrameKey& key, std::uint32_t bin,
                                                 std::uint32_t looks, std::size_t c, float* out) {
    grain_draws(plan, key, bin, kSpeckleGrainStream, c, out);
    if (looks <= 1) return;
    const std::uint32_t count = plan.grain.chunk[c + 1] - plan.grain.chunk[c];
    float look[kGrainChunkBeams];
    for (std::uint32_t l = 1; l < looks; ++l) {
        grain_draws(plan, key, bin, kSpeckleLookStream + 2 * (l - 1), c, look);
        for (std::uint32_t i = 0; i < count; ++i)
            out[i] += look[i];
    }
    const float inverse = 1.0f / static_cast<float>(looks);
    for (std::uint32_t i = 0; i < count; ++i)
        out[i] *= inverse;
}

// One bin's draws, built for AVX-512, AVX2 and baseline x86-64 as noise_bins is (the same bits: no
// FMA in either). The tests stay outside the loops: inside them (0c6d6d4) they kept the loops from being
// vectorized, 2.0 -> 4.4 ms on one thread here, and on an H100's host the draws outlasted the GPU's
// work: 904 instead of 1931 frames/s.
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
__attribute__((target_clones("avx512f", "avx2", "default")))
#endif
void draw_bin(const Plan& plan, const rng::FrameKey& key, RowDraws rows, std::uint32_t bin, float* speckle,
              float* noise) {
    const std::uint32_t beams = plan.beams;
    if (plan.grain.taps > 0) {
        for (std::size_t c = 0; c + 1 < plan.grain.chunk.size(); ++c) {
            const std::uint32_t b0 = plan.grain.chunk[c];
            if (rows.speckle) grain_speckle(plan, key, bin, rows.speckle_looks, c, speckle + b0);
            if (rows.noise) grain_draws(plan, key, bin, kNoiseGrainStream, c, noise + b0);
        }
        return;
    }
    if (rows.speckle) {
        for (std::uint32_t beam = 0; beam < beams; ++beam)
            speckle[beam] = rng::exp1_cell32(key, beam, bin, kSpeckleStream);
    }
    if (rows.noise) {
        for (std::uint32_t beam = 0; beam < beams; ++beam)
            noise[beam] = rng::exp1_cell32(key, beam, bin, kNoiseStream);
    }
}

struct DrawsTask {
    const Plan* plan;
    rng::FrameKey key;
    NoiseDraws draws;
    RowDraws rows;
};

} // namespace

bool noise_draws_ahead(const Plan& plan) {
    const RowDraws rows = row_draws_of(plan);
    return rows.speckle || rows.noise;
}

void noise_draws(const Plan& plan, std::uint64_t seed, std::uint64_t frame_index, const NoiseDraws& draws,
                 Workers* workers) {
    DrawsTask task{&plan, rng::frame_key(seed, frame_index), draws, row_draws_of(plan)};
    const auto block = [](void* context, std::uint32_t b, std::uint32_t) {
        const auto& t = *static_cast<DrawsTask*>(context);
        const std::uint32_t beams = t.plan->beams;
        const std::uint32_t end = std::min<std::uint32_t>((b + 1) * kBinBlock, t.plan->bins);
        for (std::uint32_t bin = b * kBinBlock; bin < end; ++bin)
            draw_bin(*t.plan, t.key, t.rows, bin, t.draws.speckle + std::size_t(bin) * beams,
                     t.draws.noise + std::size_t(bin) * beams);
    };
    const std::uint32_t blocks = (plan.bins + kBinBlock - 1) / kBinBlock;
    if (workers == nullptr) {
        for (std::uint32_t b = 0; b < blocks; ++b)
            block(&task, b, 0);
        return;
    }
    workers->run_blocks(block, &task, blocks);
}

void noise_and_gain(const Plan& plan, std::uint64_t seed, std::uint64_t frame_index, Frame& frame, Workers* workers,
                    const float* clean_source, const NoiseDraws* draws) {
    const std::size_t n = std::size_t(plan.beams) * plan.bins;
    assert(frame.clean.size() == n);
    assert(plan.bin_range_m.size() >= plan.bins);
    // The frame is allocated by make_frame(); these only allocate if a caller hands a wrong-sized frame.
    if (frame.clean.size() != n) frame.clean.resize(n, 0.0f);
    if (frame.intensity.size() != n) frame.intensity.resize(n);
    if (frame.display.size() != n) frame.display.resize(n);
    NoiseTask task{&plan, seed, frame_index, &frame, clean_source, draws};
    if (!workers || workers->count() == 1) {
        copy_and_noise_bins(task, 0, plan.bins);
        return;
    }
    workers->run_blocks(
        [](void* context, std::uint32_t block, std::uint32_t) {
            const auto& t = *static_cast<const NoiseTask*>(context);
            const std::size_t begin = std::size_t(block) * kBinBlock;
            copy_and_noise_bins(t, begin, std::min<std::size_t>(begin + kBinBlock, t.plan->bins));
        },
        &task, (plan.bins + kBinBlock - 1) / kBinBlock);
}

namespace {

// The default path's cells of one row: intensity = (SL clean speckle + noise) gain, in float and
// branch-free so that it vectorizes (no array overlaps another); within 2 ulps of the double path.
[[gnu::always_inline]] inline void combine_row(const float* __restrict clean, const float* __restrict speckle,
                                               const float* __restrict noise, float source,
                                               const float* __restrict noise_level, float gain, std::size_t count,
                                               float* __restrict stored, float* __restrict intensity) {
    for (std::size_t c = 0; c < count; ++c) {
        // NaN or negative echo energy would poison the frame: treat it as no echo.
        const float signal = clean[c] > 0.0f ? source * clean[c] * speckle[c] : 0.0f;
        const float value = (signal + noise_level[c] * noise[c]) * gain;
        stored[c] = value <= FLT_MAX ? value : FLT_MAX; // +inf
        intensity[c] = stored[c];
    }
}

// Built three times, for AVX-512, AVX2 and baseline x86-64, and picked at load time: the row loops
// below are vectorized, AVX2 doubles their width and multiplies 32-bit integers natively (the hashes),
// and AVX-512 halves the noise stage's time again where a CPU has it (0.62 -> 0.33 ms on the default
// scene, an AMD EPYC VM). Neither target brings FMA, so every build rounds every operation alike:
// identical output bytes.
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
__attribute__((target_clones("avx512f", "avx2", "default")))
#endif
void noise_bins(const Plan& plan, std::uint64_t seed, std::uint64_t frame_index, Frame& frame, const NoiseDraws* draws,
                std::size_t bin_begin, std::size_t bin_end) {
    const SonarConfig& cfg = plan.config;
    const std::size_t beams = plan.beams;

    const double source = std::pow(10.0, cfg.source_level_db / 10.0);
    // Each beam's noise floor 10^((NL - DI_j) / 10), 0 with the effect off (resolve_noise_floor).
    assert(!plan.effects.ambient_noise || plan.beam_noise.size() >= beams);
    const float* beam_noise = plan.beam_noise.data();
    const bool noise = adds_ambient_noise(plan);
    const bool speckle = plan.effects.speckle;
    const SpeckleModel model = cfg.speckle;
    const double looks = cfg.speckle_looks;
    const double sigma = cfg.speckle_gaussian_sigma;
    const double db_span = std::max(cfg.db_max - cfg.db_min, 1e-12);
    const double inv_db_span = 1.0 / db_span;
    const rng::FrameKey key = rng::frame_key(seed, frame_index);
    const auto db_min_f = static_cast<float>(cfg.db_min);
    const auto inv_db_span_f = static_cast<float>(inv_db_span);

    // Rayleigh speckle and ambient noise (the defaults), and grained gamma speckle, draw a row of cells at a
    // time through the vectorizable 32-bit path; the other speckle models and huge grids take the scalar
    // 64-bit one. (row_draws_of: the rule the draws made ahead follow too)
    const RowDraws rows = row_draws_of(plan);
    const bool row_speckle = rows.speckle, row_noise = rows.noise;
    const bool fast_path = row_speckle && row_noise;
    const auto source_f = static_cast<float>(source);
    constexpr std::size_t kChunk = kGrainChunkBeams; // beams per pass: the scratch stays on the stack
    const bool grain = plan.grain.taps > 0;
    float speckle_draw[kChunk], noise_draw[kChunk], stored[kChunk];

    for (std::size_t k = bin_begin; k < bin_end; ++k) {
        double gain = 1.0;
        if (plan.effects.tvg) {
            const double r = std::max(k < plan.bin_range_m.size() ? plan.bin_range_m[k] : 0.0, kMinTvgRange);
            gain = std::pow(10.0, (cfg.tvg_db_per_decade * std::log10(r) + 2.0 * plan.alpha_db_per_m * r) / 10.0);
        }
        const auto bin = static_cast<std::uint32_t>(k);
        // chunks of at most kChunk beams: the grain's (plan_grain), else kChunk at a time
        std::size_t count = 0;
        for (std::size_t j0 = 0, chunk = 0; j0 < beams; j0 += count, ++chunk) {
            count = grain ? plan.grain.chunk[chunk + 1] - j0 : std::min(kChunk, beams - j0);
            const auto beam0 = static_cast<std::uint32_t>(j0);
            // the draws made ahead (noise_draws: the same values), else made here
            const float* speckle_row = speckle_draw; // the row's draws: made ahead (noise_draws), else here
            const float* noise_row = noise_draw;
            if (row_speckle && draws != nullptr) {
                speckle_row = draws->speckle + k * beams + j0;
            } else if (row_speckle && grain) {
                grain_speckle(plan, key, bin, rows.speckle_looks, chunk, speckle_draw);
            } else if (row_speckle) {
                for (std::size_t c = 0; c < count; ++c)
                    speckle_draw[c] = rng::exp1_cell32(key, beam0 + std::uint32_t(c), bin, kSpeckleStream);
            }
            if (row_noise && draws != nullptr) {
                noise_row = draws->noise + k * beams + j0;
            } else if (row_noise && grain) {
                grain_draws(plan, key, bin, kNoiseGrainStream, chunk, noise_draw);
            } else if (row_noise) {
                for (std::size_t c = 0; c < count; ++c)
                    noise_draw[c] = rng::exp1_cell32(key, beam0 + std::uint32_t(c), bin, kNoiseStream);
            }
            if (fast_path) {
                // Speckle and ambient noise both in rows (the defaults, or grained gamma speckle) in float
                // and branch-free, so the compiler vectorizes it; within 2 ulps of the double path below.
                combine_row(frame.clean.data() + k * beams + j0, speckle_row, noise_row, source_f, beam_noise + j0,
                            static_cast<float>(gain), count, stored, frame.intensity.data() + k * beams + j0);
            } else {
                for (std::size_t c = 0; c < count; ++c) {
                    const std::size_t i = k * beams + j0 + c;
                    const auto beam = static_cast<std::uint32_t>(j0 + c);
                    const double clean = frame.clean[i];
                    // NaN or negative echo energy would poison the frame: treat it as no echo.
                    double signal = clean > 0.0 ? source * clean : 0.0;
                    if (speckle && signal > 0.0) {
                        double s = 1.0;
                        switch (model) {
                        case SpeckleModel::rayleigh:
                            s = row_speckle ? speckle_row[c] : rng::exp1(key, beam, bin, kSpeckleStream);
                            break;
                        case SpeckleModel::gamma: // grained in rows (RowDraws), else per cell
                            s = row_speckle
                                    ? speckle_row[c]
                                    : sample_gamma_unit_mean(looks, seed, frame_index, beam, bin, kSpeckleStream);
                            break;
                        case SpeckleModel::gaussian:
                            s = std::abs(1.0 + sigma * sample_normal01(seed, frame_index, beam, bin, kSpeckleStream));
                            break;
                        }
                        signal *= s;
                    }
                    double intensity = signal;
                    if (noise)
                        intensity += double(beam_noise[beam]) *
                                     (row_noise ? double(noise_row[c]) : rng::exp1(key, beam, bin, kNoiseStream));
                    intensity *= gain;
                    if (!(intensity <= static_cast<double>(FLT_MAX))) intensity = FLT_MAX; // +inf (NaN handled above)
                    stored[c] = static_cast<float>(intensity);
                    frame.intensity[i] = stored[c];
                }
            }
            // display is a function of the stored intensity alone (what polar.npy holds); an 8-to-16-bit
            // picture quantity, so the float log is plenty.
            float* display = frame.display.data() + k * beams + j0;
            for (std::size_t c = 0; c < count; ++c) {
                const float db = 10.0f * 0.43429448f * rng::fast_logf(std::max(stored[c], kMinIntensityF));
                display[c] = std::min(std::max((db - db_min_f) * inv_db_span_f, 0.0f), 1.0f);
            }
        }
    }
}

} // namespace

} // namespace vksonar::host
