// The grain of speckle and ambient noise across beams (docs/pipeline.md §5, "Grain"): the tables the noise
// stage (src/host/noise.cpp) filters its white draws with.
//
// A beam hears the scatterers, and the elements' noise, through its receive pattern; two beams whose patterns
// overlap hear much the same, so their speckle and noise are correlated. Beam j's complex field is
// z_j = sum over directions u of a(u - u_j) c(u), with a the receive amplitude pattern and c white; the
// intensity correlation of two beams is then |rho(u_j - u_j')|^2, rho the aperture's |w|^2 transformed and
// normalized (for an unshaded array sinc itself). A defocus (beam_focus) multiplies w by a phase that both
// beams share, so the grain is the focused one at every range.
//
// The white field is drawn on a grid in u (the angle, or the sine for a line array). The aperture patterns
// are band-limited (a product of two has its spectrum within |s| < 2 in x = k u), so a sum of products over a
// grid finer than pi in x is their integral exactly, and where the grid lies against the beams does not
// matter. Each beam takes the grid points within the main lobe and two side lobes each side; the
// truncation leaves the intensity correlation within 0.04 of the untruncated one at every lag for an
// unshaded array, and within 1e-4 with hann shading. A pattern that ends abruptly (a box, or a planar fan's
// baffle) is not band-limited: it takes finer steps, and its end cells are weighed by their part inside
// (point_weight).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "core/angles.h"
#include "core/plan.h"
#include "core/plan_steps.h"
#include "core/sonar_math.hpp"

namespace vksonar {

using namespace plan_steps;

namespace {

// The receive amplitude pattern at separation `sep` (pattern_at_separation's power, as the signed
// amplitude whose square it is: the aperture patterns' sign changes from lobe to lobe).
double amplitude_at_separation(const Plan& p, double sep) {
    if (!separation_in_front(p, sep)) return 0.0;
    const std::uint32_t shape = shader_id(p.config.horizontal_pattern);
    if (shape != shared::kPatternBox && shape != shared::kPatternGaussian) return aperture_amplitude(p, sep);
    return std::sqrt(math_f64::pattern_power(shape, p.hpattern_k, p.hpattern_halfwidth_rad, p.hpattern_chebyshev_a,
                                             separation_angle(p, sep)));
}

// The grid's step, each beam's reach, and the half width of the pattern's support where it ends abruptly (a
// box's edge, a planar fan's baffle at 90 deg; infinity where it fades), in the separation's unit.
struct GrainGrid {
    double step = 0, reach = 0, support = std::numeric_limits<double>::infinity();
};

GrainGrid grain_grid(const Plan& p) {
    const double half_bw = 0.5 * p.config.horizontal_beamwidth_deg * kDegToRad;
    // A planar fan's aperture is baffled (separation_in_front): nothing reaches it from 90 deg off its axis or
    // more, and on a full circle a reach past that would take a point into a beam twice. A pattern cut there
    // is not band-limited: its steps are at most pi / 32 (and the cut cells weighed by their part inside).
    const double baffle = 0.5 * kPi;
    // (A cut support's reach takes in the half cell that straddles it.)
    const auto baffled = [&](GrainGrid g) {
        if (p.line_array || g.reach < baffle) return g;
        const double step = std::min(g.step, kPi / 32.0);
        return GrainGrid{step, baffle + 0.5 * step, baffle};
    };
    switch (p.config.horizontal_pattern) {
    case BeamPattern::box: { // amplitude 1 within the half width (its edge cells weighed by their part inside)
        const double step = half_bw / 16.0;
        return baffled({step, half_bw + 0.5 * step, half_bw});
    }
    case BeamPattern::gaussian: // power exp(-k a^2), to -40 dB
        return baffled({0.5 * half_bw, std::sqrt(std::log(1e4) / p.hpattern_k)});
    default:
        break;
    }
    // The aperture patterns in x = k u (planar: u the angle's sine, whose x changes by at most k per radian, so
    // steps of 0.8 pi / k radians stay inside the band limit at every angle): steps of 0.8 pi, inside the band
    // limit pi with a margin for the truncation (the same correlations as steps of a -3 dB half width, 1.39
    // for sinc, within 0.002, at 9 taps a beam instead of 15), to the first null and two side lobes beyond
    // it (each about pi wide). A chebyshev pattern's side lobes never decay, so for it this cut is the model.
    const double k = p.hpattern_k;
    const double a = p.hpattern_chebyshev_a;
    const double first_null = p.config.horizontal_pattern == BeamPattern::hann ? 2.0 * kPi
                              : p.config.horizontal_pattern == BeamPattern::chebyshev
                                  ? std::sqrt(a * a + 0.25 * kPi * kPi)
                                  : kPi;
    const double step_x = 0.8 * kPi, reach_x = first_null + 2.0 * kPi;
    if (p.line_array) return {step_x / k, reach_x / k};
    return baffled({step_x / k, reach_x >= k ? baffle : std::asin(reach_x / k)});
}

// Point weight at `offset` from a beam: the amplitude there, or for a cell the support's end cuts (step wide,
// centred on the point), the amplitude at the middle of its part inside times that part's share of the cell
// (so that a beam's weights change smoothly as it moves past the grid, and two beams never share them all).
double point_weight(const Plan& p, const GrainGrid& grid, double step, double offset) {
    const double lo = offset - 0.5 * step, hi = offset + 0.5 * step;
    if (lo >= -grid.support && hi <= grid.support) return amplitude_at_separation(p, offset);
    const double in_lo = std::max(lo, -grid.support), in_hi = std::min(hi, grid.support);
    if (!(in_hi > in_lo)) return 0.0;
    // just inside the support's end: the amplitude there, not the zero past a baffle
    const double middle =
        std::clamp(0.5 * (in_lo + in_hi), -grid.support * (1.0 - 1e-12), grid.support * (1.0 - 1e-12));
    return amplitude_at_separation(p, middle) * (in_hi - in_lo) / step;
}

void no_grain(Plan& p, std::string why) {
    p.grain = GrainTables{};
    p.grain.why = std::move(why);
}

} // namespace

void plan_grain(Plan& p) {
    const SonarConfig& c = p.config;
    if (c.beam_correlation == BeamCorrelation::none)
        return no_grain(p, "beam_correlation none: every cell drawn alone");
    if (p.beams < 2) return no_grain(p, "one beam");
    // the noise stage's row draws hash (beam or grid point, bin) in one 32-bit word
    constexpr std::uint32_t kMaxIndex = 1u << 16;
    if (p.beams >= kMaxIndex || p.bins >= kMaxIndex)
        return no_grain(p, "beams or bins 65536 or more: every cell drawn alone");
    const GrainGrid grid = grain_grid(p);
    const std::uint32_t beams = p.beams;
    std::vector<double> position(beams);
    for (std::uint32_t j = 0; j < beams; ++j)
        position[j] = p.line_array ? std::sin(p.beam_angle_rad[j]) : p.beam_angle_rad[j];
    double step = grid.step, origin = 0.0;
    std::uint32_t cells = 0;
    if (p.circular) {
        const double around = std::ceil(2.0 * kPi / step);
        if (around >= kMaxIndex) return no_grain(p, "65536 grid points or more: every cell drawn alone");
        cells = static_cast<std::uint32_t>(around);
        step = 2.0 * kPi / cells;
        origin = -kPi;
    } else {
        origin = *std::min_element(position.begin(), position.end()) - grid.reach;
    }
    // the points within reach of a beam: at most 2 reach / step + 1 of them, from its first on
    const double reach_steps = std::floor(2.0 * grid.reach / step) + 2.0;
    if (reach_steps > kGrainChunkPoints || (p.circular && reach_steps > cells))
        return no_grain(p, "the pattern's reach is too many grid steps");
    const auto taps = static_cast<std::uint32_t>(reach_steps);
    // each beam's first point and its taps' weights (beam-major), normalized
    std::vector<std::int32_t> first(beams);
    std::vector<double> weight(std::size_t(taps) * beams, 0.0);
    std::int64_t last_point = 0;
    for (std::uint32_t j = 0; j < beams; ++j) {
        const double first_point = std::ceil((position[j] - grid.reach - origin) / step);
        if (!(std::abs(first_point) + taps < kMaxIndex))
            return no_grain(p, "65536 grid points or more: every cell drawn alone");
        first[j] = static_cast<std::int32_t>(first_point);
        // beam_table's beams fall strictly, so their first points never rise (the blocks below rely on it)
        if (j > 0 && first[j] > first[j - 1]) return no_grain(p, "the beams' angles do not fall");
        double* w = weight.data() + std::size_t(j) * taps;
        double sum_squares = 0.0;
        for (std::uint32_t t = 0; t < taps; ++t) {
            const double offset = position[j] - (origin + (first_point + t) * step);
            if (std::abs(offset) > grid.reach) continue;
            w[t] = point_weight(p, grid, step, offset);
            sum_squares += w[t] * w[t];
        }
        const double norm = sum_squares > 0.0 ? 1.0 / std::sqrt(sum_squares) : 0.0;
        for (std::uint32_t t = 0; t < taps; ++t)
            w[t] *= norm;
        last_point = std::max<std::int64_t>(last_point, std::int64_t(first_point) + taps);
    }
    if (!p.circular) {
        if (last_point >= kMaxIndex) return no_grain(p, "65536 grid points or more: every cell drawn alone");
        cells = static_cast<std::uint32_t>(last_point);
    }
    // Chunks of consecutive beams whose points fit the noise stage's scratch. The beams' positions fall
    // strictly (beam_table), so their first points never rise: a run of beams takes the points from its
    // last beam's first to its first beam's last.
    p.grain.chunk.assign(1, 0);
    for (std::uint32_t j = 1; j < beams; ++j) {
        const std::uint32_t b0 = p.grain.chunk.back();
        if (j - b0 >= kGrainChunkBeams || std::int64_t(first[b0]) + taps - first[j] > std::int64_t(kGrainChunkPoints))
            p.grain.chunk.push_back(j);
    }
    p.grain.chunk.push_back(beams);
    p.grain.chunk_points.clear();
    p.grain.chunk_block.assign(1, 0);
    p.grain.chunk_low.clear();
    p.grain.block_points.clear();
    p.grain.block_weight.clear();
    p.grain.weight.clear();
    for (std::size_t chunk = 0; chunk + 1 < p.grain.chunk.size(); ++chunk) {
        const std::uint32_t b0 = p.grain.chunk[chunk], b1 = p.grain.chunk[chunk + 1];
        const std::int32_t low = first[b1 - 1];
        p.grain.chunk_low.push_back(low);
        p.grain.chunk_points.push_back(std::uint32_t(first[b0] + std::int32_t(taps) - low));
        // each block's points: from its last beam's first to its first beam's last
        for (std::uint32_t q0 = b0; q0 < b1; q0 += kGrainLanes) {
            const std::uint32_t q1 = std::min(q0 + kGrainLanes, b1);
            const std::int32_t m_begin = first[q1 - 1], m_end = first[q0] + std::int32_t(taps);
            p.grain.block_points.push_back(std::uint32_t(m_begin - low));
            p.grain.block_points.push_back(std::uint32_t(m_end - low));
            p.grain.block_weight.push_back(static_cast<std::uint32_t>(p.grain.weight.size()));
            for (std::int32_t m = m_begin; m < m_end; ++m) {
                for (std::uint32_t l = 0; l < kGrainLanes; ++l) {
                    const std::uint32_t q = q0 + l;
                    const bool reaches = q < q1 && first[q] <= m && m < first[q] + std::int32_t(taps);
                    p.grain.weight.push_back(
                        reaches ? static_cast<float>(weight[std::size_t(q) * taps + std::uint32_t(m - first[q])])
                                : 0.0f);
                }
            }
        }
        p.grain.chunk_block.push_back(static_cast<std::uint32_t>(p.grain.block_weight.size()));
    }
    p.grain.phase.resize(2 * std::size_t(kGrainPhases));
    for (std::uint32_t i = 0; i < kGrainPhases; ++i) {
        const double phase = 2.0 * kPi * i / kGrainPhases;
        p.grain.phase[2 * i] = static_cast<float>(std::cos(phase));
        p.grain.phase[2 * i + 1] = static_cast<float>(std::sin(phase));
    }
    p.grain.cells = cells;
    p.grain.taps = taps;
    p.grain.step = step;
    p.grain.why.clear();
}

} // namespace vksonar
