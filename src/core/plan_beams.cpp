// make_plan's steps for the beams (plan_steps.h): which beams each profile column feeds (the resample's
// tent on the beam table), and the horizontal pattern's kernel: each beam's weights over the profile
// columns out to the kernel's reach (the near kernel), and the far side lobes' cells beyond it.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "core/angles.h"
#include "core/plan_focus.h"
#include "core/plan_steps.h"
#include "core/sonar_math.hpp"

namespace vksonar {

double sidelobe_reach_units(bool line_array, double reach) {
    if (!line_array) return reach;
    // Two beams' sines differ by up to 2 (a fan's two edges): past a quarter turn the reach goes on
    // growing, continuously, to 2 at half a turn.
    return reach <= 0.5 * kPi ? std::sin(reach) : 1.0 + std::sin(std::min(reach - 0.5 * kPi, 0.5 * kPi));
}

void assign_columns_to_beams(Plan& p, double exclude_beyond_rad) {
    const std::vector<double>& b = p.beam_angle_rad;
    const std::uint32_t columns = static_cast<std::uint32_t>(p.column_azimuth_rad.size()); // profile columns
    p.column_beam.resize(columns);
    p.column_weight.resize(columns);
    for (std::uint32_t col = 0; col < columns; ++col) {
        const double a = p.column_azimuth_rad[col];
        if (std::abs(a) > exclude_beyond_rad) {
            p.column_beam[col] = p.beams; // no beam: the resample tables skip it
            p.column_weight[col] = 0.0f;
        } else if (p.circular && (a > b.front() || a < b.back())) {
            // The seam between beam 0 and beam beams-1 (at b.back() + 2 pi): a tent across it, so a
            // target at 180 deg is beamformed like one anywhere else.
            const double two_pi = 2.0 * 3.14159265358979323846;
            const double beyond_beam0 = a > b.front() ? a - b.front() : a + two_pi - b.front();
            p.column_beam[col] = p.beams - 1;
            p.column_weight[col] = static_cast<float>(beyond_beam0 / (b.back() + two_pi - b.front()));
        } else if (a >= b.front()) {
            p.column_beam[col] = 0;
            p.column_weight[col] = 1.0f;
        } else if (a <= b.back()) {
            p.column_beam[col] = p.beams - 1;
            p.column_weight[col] = 1.0f;
        } else {
            // first beam j+1 with b[j+1] < a (b decreasing), so b[j] >= a > b[j+1]
            const auto it = std::upper_bound(b.begin(), b.end(), a, [](double x, double y) { return x > y; });
            const std::uint32_t j = static_cast<std::uint32_t>(it - b.begin()) - 1;
            p.column_beam[col] = j;
            p.column_weight[col] = static_cast<float>((a - b[j + 1]) / (b[j] - b[j + 1]));
        }
    }
    p.beam_column_begin.assign(p.beams, columns);
    p.beam_column_end.assign(p.beams, 0);
    for (std::uint32_t col = 0; col < columns; ++col) {
        for (std::uint32_t j : {p.column_beam[col], p.column_beam[col] + 1}) {
            if (j >= p.beams) continue;
            p.beam_column_begin[j] = std::min(p.beam_column_begin[j], col);
            p.beam_column_end[j] = std::max(p.beam_column_end[j], col + 1);
        }
    }
    if (p.circular) { // the edge beams gather seam columns at both ends of the pixel grid
        for (std::uint32_t j : {0u, p.beams - 1}) {
            p.beam_column_begin[j] = 0;
            p.beam_column_end[j] = columns;
        }
    }
    for (std::uint32_t j = 0; j < p.beams; ++j) {
        if (p.beam_column_begin[j] > p.beam_column_end[j]) p.beam_column_begin[j] = p.beam_column_end[j] = 0;
    }
}

namespace plan_steps {

double sidelobe_reach(const Plan& p, double reach) {
    return sidelobe_reach_units(p.line_array, reach);
}

// Step: which beams each pixel column feeds (tent on the beam table). Columns at |azimuth| beyond
// exclude_beyond_rad feed none.
void plan_column_tables(Plan& p, double exclude_beyond_rad) {
    p.column_azimuth_rad.resize(p.profile_columns);
    if (p.line_array) { // the cone columns' steering angles
        const double half_fov = 0.5 * p.config.hfov_deg * kDegToRad;
        for (std::uint32_t col = 0; col < p.profile_columns; ++col)
            p.column_azimuth_rad[col] = half_fov - (col + 0.5) * p.cone_step_rad;
        assign_columns_to_beams(p, exclude_beyond_rad);
        return;
    }
    for (std::uint32_t col = 0; col < p.columns; ++col) {
        const std::uint32_t s = col / p.slice_columns;
        const double u = math_f64::pixel_coord(col % p.slice_columns, p.slice_columns, p.tan_half_h);
        p.column_azimuth_rad[col] = math_f64::pixel_azimuth(p.slice_info[s].center_azimuth_rad, u);
    }
    assign_columns_to_beams(p, exclude_beyond_rad);
}

bool separation_in_front(const Plan& p, double& sep) {
    if (p.circular) sep = std::remainder(sep, 2.0 * kPi); // into [-pi, pi]
    // A planar fan's beam is formed by an aperture facing along it, baffled: it hears nothing from behind
    // (a separation of 90 deg or more). Written in sin(separation), the pattern would give a source
    // behind the beam the response of one in front (a full-strength ghost, 180 deg from each target, on a
    // fan wider than 180 deg).
    return p.line_array || std::abs(sep) < 0.5 * kPi;
}

double separation_angle(const Plan& p, double sep) {
    return p.line_array ? std::asin(std::clamp(sep, -1.0, 1.0)) : sep;
}

double aperture_amplitude(const Plan& p, double sep) {
    return math_f64::aperture_pattern_amplitude(shader_id(p.config.horizontal_pattern), p.hpattern_k,
                                                p.hpattern_chebyshev_a, p.line_array ? sep : std::sin(sep));
}

namespace {

// The horizontal power pattern at separation `sep` of two beams in the side-lobe kernel's unit: the
// angle, or with line_array its sine. A line array's aperture patterns are functions of
// sin(theta') - sin(theta) over its whole range [-2, 2]; the others (box, gaussian) are read at the
// angle whose sine it is (at most 90 degrees). With a defocus `phase` > 0 (plan_focus.cpp) the aperture's
// pattern defocused by it.
double pattern_at_separation(const Plan& p, double sep, const DefocusedPattern* defocused = nullptr,
                             double phase = 0.0) {
    const std::uint32_t hshape = shader_id(p.config.horizontal_pattern);
    if (!separation_in_front(p, sep)) return 0.0;
    if (defocused != nullptr && phase > 0.0)
        return defocused->power(p.hpattern_k * (p.line_array ? sep : std::sin(sep)), phase);
    if (hshape == shared::kPatternBox || hshape == shared::kPatternGaussian)
        return math_f64::pattern_power(hshape, p.hpattern_k, p.hpattern_halfwidth_rad, p.hpattern_chebyshev_a,
                                       separation_angle(p, sep));
    const double amplitude = aperture_amplitude(p, sep);
    return amplitude * amplitude;
}

// The pattern of beam j in focus band b at separation `sep`: the band's phase, a line array's beam steered
// to theta taking cos^2 theta of it (its aperture seen from there is shorter).
double pattern_in_band(const Plan& p, const DefocusedPattern* defocused, std::uint32_t b, std::uint32_t j, double sep) {
    const double steering = p.line_array ? std::cos(p.beam_angle_rad[j]) : 1.0;
    return pattern_at_separation(p, sep, defocused, p.near_band_phase[b] * steering * steering);
}

// The separation variable of beam j: its angle, or with line_array its sine.
double beam_position(const Plan& p, std::uint32_t j) {
    return p.line_array ? std::sin(p.beam_angle_rad[j]) : p.beam_angle_rad[j];
}

// The separation variable of profile column c: its direction's angle, or with line_array its sine.
double column_position(const Plan& p, std::uint32_t c) {
    return p.line_array ? std::sin(p.column_azimuth_rad[c]) : p.column_azimuth_rad[c];
}

// An offset of d cells as the index of its weight in fit_far_weights: |d|, and on a circle the shorter way
// round (the weights are even in d, and periodic on a circle).
std::size_t fold_offset(std::int64_t d, std::uint32_t cells, bool circular) {
    if (!circular) return static_cast<std::size_t>(std::abs(d));
    const std::int64_t m = (d % std::int64_t(cells) + cells) % cells;
    return static_cast<std::size_t>(std::min<std::int64_t>(m, cells - m));
}

// The normal equations (normal: n x n, symmetric positive definite) solved for the unknowns `free`
// alone, the others held at 0: Cholesky of the free rows and columns, then forward and back substitution.
std::vector<double> solve_normal_equations(const std::vector<double>& normal, const std::vector<double>& rhs,
                                           std::size_t n, const std::vector<std::size_t>& free) {
    const std::size_t m = free.size();
    std::vector<double> l(m * m, 0.0), v(m, 0.0);
    for (std::size_t a = 0; a < m; ++a)
        for (std::size_t b = 0; b < m; ++b)
            l[a * m + b] = normal[free[a] * n + free[b]];
    for (std::size_t c = 0; c < m; ++c) {
        double d = l[c * m + c];
        for (std::size_t k = 0; k < c; ++k)
            d -= l[c * m + k] * l[c * m + k];
        const double root = std::sqrt(std::max(d, 1e-300));
        l[c * m + c] = root;
        for (std::size_t r = c + 1; r < m; ++r) {
            double e = l[r * m + c];
            for (std::size_t k = 0; k < c; ++k)
                e -= l[r * m + k] * l[c * m + k];
            l[r * m + c] = e / root;
        }
    }
    for (std::size_t r = 0; r < m; ++r) {
        v[r] = rhs[free[r]];
        for (std::size_t k = 0; k < r; ++k)
            v[r] -= l[r * m + k] * v[k];
        v[r] /= l[r * m + r];
    }
    for (std::size_t r = m; r-- > 0;) {
        for (std::size_t k = r + 1; k < m; ++k)
            v[r] -= l[k * m + r] * v[k];
        v[r] /= l[r * m + r];
    }
    return v;
}

// The far grid's weight for each offset of cells (index fold_offset). A column puts its energy into its
// two cells by the tent and a beam reads its two cells back by the tent, so a column and a beam D cells
// apart read the weights at the three offsets around D, mixed by where each falls in its cells. Taking the
// target's own values as weights over-reads a convex envelope (by 0.4 to 0.5 dB on lobes 3 to 6 at the
// default; averaged over a cell, as an earlier version did, by more). So the weights are fitted: least
// squares of the relative error over every separation from `first` (the reach, in cells) to the widest,
// in 1/16 of a cell, and 16 places of the column in its cell (each placing the beam), by the normal
// equations, no weight below 0. A weight no such pair reads (within the reach) is drawn to the target by a
// tiny ridge term (at separations under `first`, the target at `first`: finite, where a 1 / du^2
// envelope is not).
template <class Target>
std::vector<double> fit_far_weights(std::uint32_t cells, bool circular, double first, Target target) {
    const std::size_t n = circular ? cells / 2 + 1 : cells;
    const double last = circular ? 0.5 * cells : cells - 1.0;
    std::vector<double> scale(n); // weight i = scale[i] * v[i]: the unknowns v near 1
    for (std::size_t i = 0; i < n; ++i)
        scale[i] = std::max(target(std::max(double(i), first)), 1e-300);
    std::vector<double> normal(n * n, 0.0), rhs(n, 0.0);
    constexpr int kSteps = 16;
    for (int k = 0; first + double(k) / kSteps <= last; ++k) {
        const double apart = first + double(k) / kSteps, goal = target(apart);
        if (!(goal > 0.0)) continue;
        for (int i = 0; i < kSteps; ++i) {
            const double s = (i + 0.5) / kSteps; // the column, its second cell's share (cells 0 and 1)
            const double x = s + apart, a0 = std::floor(x), t = x - a0; // the beam: cells a0, a0 + 1
            const double column_share[2] = {1.0 - s, s}, beam_share[2] = {1.0 - t, t};
            std::size_t index[4];
            double coef[4];
            bool inside = true;
            for (int a = 0; a < 2; ++a)
                for (int b = 0; b < 2; ++b) {
                    const std::size_t f = fold_offset(std::int64_t(a0) + a - b, cells, circular);
                    inside = inside && f < n;
                    index[2 * a + b] = f;
                    coef[2 * a + b] = inside ? beam_share[a] * column_share[b] * scale[f] / goal : 0.0;
                }
            if (!inside) continue; // offsets past the fan's last cell
            for (int u = 0; u < 4; ++u) {
                rhs[index[u]] += coef[u];
                for (int v = 0; v < 4; ++v)
                    normal[index[u] * n + index[v]] += coef[u] * coef[v];
            }
        }
    }
    double largest = 0.0;
    for (std::size_t i = 0; i < n; ++i)
        largest = std::max(largest, normal[i * n + i]);
    const double ridge = 1e-9 * std::max(largest, 1.0);
    for (std::size_t i = 0; i < n; ++i) {
        normal[i * n + i] += ridge;
        rhs[i] += ridge;
    }
    // No weight below 0: a negative weight makes the grid's level at some beams negative, which the
    // read-back cuts at 0 (far_sidelobe_level), and near + far would no longer be the pattern. So the
    // weights the solution takes negative are held at 0 and the rest solved again, until none is.
    std::vector<double> v(n, 0.0);
    std::vector<bool> held(n, false);
    for (std::size_t round = 0; round <= n; ++round) {
        std::vector<std::size_t> free;
        for (std::size_t i = 0; i < n; ++i)
            if (!held[i]) free.push_back(i);
        const std::vector<double> solved = solve_normal_equations(normal, rhs, n, free);
        bool negative = false;
        for (std::size_t f = 0; f < free.size(); ++f) {
            v[free[f]] = std::max(solved[f], 0.0);
            if (solved[f] < 0.0) negative = held[free[f]] = true;
        }
        if (!negative) break;
    }
    for (std::size_t i = 0; i < n; ++i)
        v[i] *= scale[i];
    return v;
}

// Step: the far side lobes' grid (Plan::far_cells), when the kernel stops short of the fan. The cells
// are as narrow as far_sidelobe_cell * reach, and at most kMaxFarCells.
void plan_far_sidelobes(Plan& p, double reach_units) {
    p.far_cells = 0;
    p.far_channels = 1;
    p.far_beam_cell.clear();
    p.far_column_cell.clear();
    p.far_cell_columns.clear();
    p.far_weight.clear();
    const double cell_fraction = p.config.far_sidelobe_cell;
    if (!(cell_fraction > 0.0) || p.beams < 2 || !(reach_units > 0.0)) return;
    const double span = p.circular ? 2.0 * kPi : beam_position(p, 0) - beam_position(p, p.beams - 1);
    if (reach_units >= span) return; // every pair of beams is within the kernel's reach, where it is exact
    if (!p.line_array && reach_units >= 0.5 * kPi) return; // past 90 deg the pattern is 0: nothing to carry
    const double wanted = cell_fraction * reach_units;
    std::uint32_t cells = 0;
    double step = 0.0;
    if (p.circular) {
        cells = static_cast<std::uint32_t>(std::clamp(std::ceil(span / wanted), 3.0, double(shared::kMaxFarCells)));
        step = span / cells;
    } else {
        cells =
            static_cast<std::uint32_t>(std::clamp(std::ceil(span / wanted) + 1.0, 2.0, double(shared::kMaxFarCells)));
        step = span / (cells - 1);
    }
    p.far_cells = cells;
    // A line array's sinc^2 pattern is sin^2(k du) / (k du)^2, and sin^2(k (u_s - u_j)) =
    // (1 - cos 2k u_s cos 2k u_j - sin 2k u_s sin 2k u_j) / 2: the crests and nulls factor into a phase of
    // each beam, and only the smooth 1 / (k du)^2 goes on the grid (three channels: the energy, and the
    // energy times each beam's cos 2k u and sin 2k u). Other patterns keep the lobes' mean (one channel).
    const bool phased = p.line_array && shader_id(p.config.horizontal_pattern) == shared::kPatternSinc;
    p.far_channels = phased ? 3u : 1u;
    // Each beam's and each column's two cells and the share of the second: position x = (first beam's
    // position - its own) / step; its phase 2k u with the phase channels. Columns deposit (each at its own
    // direction, as the near kernel weighs them), beams read back.
    auto place = [&](double position, float* entry) {
        double x = (beam_position(p, 0) - position) / step;
        if (p.circular) x = std::fmod(std::fmod(x, double(cells)) + cells, double(cells));
        auto c0 = static_cast<std::uint32_t>(std::max(std::floor(x), 0.0));
        if (p.circular)
            c0 %= cells;
        else
            c0 = std::min(c0, cells - 2);
        const std::uint32_t c1 = p.circular ? (c0 + 1) % cells : c0 + 1;
        entry[0] = static_cast<float>(c0);
        entry[1] = static_cast<float>(c1);
        entry[2] = static_cast<float>(std::clamp(x - c0, 0.0, 1.0)); // c0 = floor(x) but at the ends
        if (phased) {
            const double phase = 2.0 * p.hpattern_k * position;
            entry[4] = static_cast<float>(std::cos(phase));
            entry[5] = static_cast<float>(std::sin(phase));
        }
        return std::pair<std::uint32_t, std::uint32_t>(c0, c1);
    };
    p.far_beam_cell.assign(std::size_t(p.beams) * 8, 0.0f);
    for (std::uint32_t j = 0; j < p.beams; ++j)
        place(beam_position(p, j), p.far_beam_cell.data() + 8 * std::size_t(j));
    const std::uint32_t columns = p.profile_columns;
    p.far_column_cell.assign(std::size_t(columns) * 8, 0.0f);
    std::vector<std::uint32_t> first(cells, columns), last(cells, 0);
    for (std::uint32_t col = 0; col < columns; ++col) {
        float* entry = p.far_column_cell.data() + 8 * std::size_t(col);
        if (p.column_beam[col] >= p.beams) { // beyond a host camera's fan: no cell
            entry[0] = entry[1] = static_cast<float>(cells);
            continue;
        }
        const auto [c0, c1] = place(column_position(p, col), entry);
        for (std::uint32_t c : {c0, c1}) {
            first[c] = std::min(first[c], col);
            last[c] = std::max(last[c], col);
        }
    }
    p.far_cell_columns.assign(std::size_t(cells) * 2, 0);
    for (std::uint32_t c = 0; c < cells; ++c) {
        if (first[c] > last[c]) continue; // no column feeds it
        p.far_cell_columns[2 * c] = first[c];
        p.far_cell_columns[2 * c + 1] = last[c] + 1;
    }
    // far_weight: cell b into cell a depends on a - b only, fitted so that the grid reads the target
    // past the reach (fit_far_weights): with the phase channels the pattern's smooth part 1 / (2 (k du)^2),
    // else the pattern averaged over one cell (the lobes' mean level). Within the reach the near kernel
    // carries the pattern less whatever the grid gives (far_grid_weight), so no weight there needs to be
    // right, only finite.
    auto target = [&](double cells_apart) {
        const double sep = cells_apart * step;
        if (phased) {
            const double x = p.hpattern_k * (p.circular ? std::remainder(sep, 2.0 * kPi) : sep);
            return 0.5 / (x * x);
        }
        // the mean over a cell, or over two of the pattern's lobes (pi / k apart) where a cell is narrower:
        // a mean level, not crests and nulls the cells would follow
        const double window = std::max(step, 2.0 * kPi / std::max(p.hpattern_k, 1e-12));
        constexpr int kSamples = 32; // midpoint rule
        double sum = 0.0;
        for (int i = 0; i < kSamples; ++i)
            sum += pattern_at_separation(p, sep + ((i + 0.5) / kSamples - 0.5) * window);
        return sum / kSamples;
    };
    const std::vector<double> by_offset = fit_far_weights(cells, p.circular, reach_units / step, target);
    p.far_weight.assign(2 * std::size_t(cells) - 1, 0.0f);
    for (std::int64_t d = -std::int64_t(cells) + 1; d < std::int64_t(cells); ++d)
        p.far_weight[std::size_t(d + cells - 1)] = static_cast<float>(by_offset[fold_offset(d, cells, p.circular)]);
}

// What the far grid gives beam j from a unit of energy in profile column c, as the backends compute it
// from plan_far_sidelobes' float tables, by the same kernels (sonar_kernels.h), in double: the column's
// deposit into its two cells per channel (far_deposit_weight), convolved (far_weight), read back with the
// beam's two cells' shares (far_cell_share) and phase (far_sidelobe_level).
double far_grid_weight(const Plan& p, std::uint32_t c, std::uint32_t j) {
    using math_f64::vec4;
    const std::uint32_t cells = p.far_cells;
    const float* column = p.far_column_cell.data() + 8 * std::size_t(c);
    const float* beam = p.far_beam_cell.data() + 8 * std::size_t(j);
    if (static_cast<std::uint32_t>(column[0]) >= cells) return 0.0; // the column feeds no cell
    const vec4 column_cell(column[0], column[1], column[2], column[3]);
    const vec4 column_phase(column[4], column[5], column[6], column[7]);
    const vec4 beam_cell(beam[0], beam[1], beam[2], beam[3]), beam_phase(beam[4], beam[5], beam[6], beam[7]);
    double level[3] = {0.0, 0.0, 0.0};
    for (std::uint32_t m = 0; m < p.far_channels; ++m)
        for (const float a : {beam[0], beam[1]})
            for (const float b : {column[0], column[1]}) {
                const auto read = static_cast<std::uint32_t>(a), deposit = static_cast<std::uint32_t>(b);
                level[m] += math_f64::far_cell_share(beam_cell, read) *
                            math_f64::far_deposit_weight(column_cell, column_phase, deposit, m) *
                            double(p.far_weight[std::size_t(cells - 1 + std::int64_t(read) - deposit)]);
            }
    return math_f64::far_sidelobe_level(beam_phase, level[0], level[1], level[2]);
}

} // namespace

namespace {

// The near kernel's table over the columns within the reach of each beam (reach_units, in the separation
// unit) and within offset_cut beams of it (by the column's fractional beam index, the tent's position;
// wrapped on a circle): weights the pattern at the separation less what the far grid gives the same
// column at the same beam (far_grid_weight). With `tent` (no kernel, K = 0, the effect forced on) the columns within a
// beam of it instead, weighed by the tent (1 - their distance in beams: the resample's own shares, so the pass gives
// B). Zero weights at either end of a beam's columns are left out (a null at the reach); columns that feed no beam
// (beyond a host camera's fan) are never in a kernel.
void plan_near_columns(Plan& p, double reach_units, double offset_cut, bool tent) {
    const std::uint32_t beams = p.beams, columns = p.profile_columns;
    // One band of phase 0 with the tent (plan_focus_bands: no kernel to apply a focus).
    const std::uint32_t bands = p.near_bands;
    std::unique_ptr<DefocusedPattern> defocused;
    const bool defocus = out_of_focus(p);
    if (defocus)
        defocused =
            std::make_unique<DefocusedPattern>(shader_id(p.config.horizontal_pattern), p.near_band_phase.back());
    p.near_column_begin.assign(beams, 0);
    p.near_column_count.assign(beams, 0);
    std::vector<float> flat;                // every beam's weights, one after another
    std::vector<std::size_t> offset(beams); // beam j's first weight in flat
    std::vector<float> row;
    p.near_column_taps = 1;
    // An unwrapped column index as a column (on a circle the indices wrap; elsewhere they stay in range).
    auto wrap = [&](std::int64_t c) { return static_cast<std::uint32_t>((c % columns + columns) % columns); };
    for (std::uint32_t j = 0; j < beams; ++j) {
        const double position = beam_position(p, j);
        auto separation = [&](std::int64_t c) {
            const double sep = column_position(p, wrap(c)) - position;
            return p.circular ? std::remainder(sep, 2.0 * kPi) : sep;
        };
        // The column nearest the beam's direction (positions fall with the column index), then out
        // either way while the columns are within reach (on a circle, never more than all of them).
        std::int64_t lo = 0;
        {
            std::uint32_t a = 0, b = columns; // first column at or past the beam's position
            while (a < b) {
                const std::uint32_t m = (a + b) / 2;
                if (column_position(p, m) > position)
                    a = m + 1;
                else
                    b = m;
            }
            lo = std::min<std::int64_t>(a, columns - 1);
            if (lo > 0 && std::abs(separation(lo - 1)) < std::abs(separation(lo))) --lo;
        }
        std::int64_t hi = lo; // columns [lo, hi]
        // Beams between the column's tent position and beam j (-1: the column feeds no beam).
        auto beams_away = [&](std::int64_t c) {
            const std::uint32_t wrapped = wrap(c);
            if (p.column_beam[wrapped] >= beams) return -1.0;
            double d = std::abs(p.column_beam[wrapped] + (1.0 - p.column_weight[wrapped]) - j);
            return p.circular ? std::min(d, beams - d) : d;
        };
        // Out of focus a band keeps its own pattern out to focus_reach_x of its phase (plan_focus.h), past the
        // configured reach where that is further; the far grid's far-field lobes take over beyond.
        auto x_of = [&](double sep) {
            return p.hpattern_k * (p.line_array ? std::abs(sep) : std::sin(std::min(std::abs(sep), 0.5 * kPi)));
        };
        const double steering = p.line_array ? std::cos(p.beam_angle_rad[j]) : 1.0;
        auto band_reach_x = [&](std::uint32_t b) {
            return defocus ? focus_reach_x(p.near_band_phase[b] * steering * steering) : 0.0;
        };
        const double widest_x = band_reach_x(bands - 1); // the bands' phases increase
        auto in_configured = [&](std::int64_t c, double d) {
            return std::abs(separation(c)) <= reach_units + 1e-12 && d <= offset_cut;
        };
        auto in_kernel = [&](std::int64_t c) {
            const double d = beams_away(c);
            if (d < 0.0) return false;
            if (tent) return d < 1.0;
            const double sep = separation(c);
            return in_configured(c, d) ||
                   (defocus && x_of(sep) <= widest_x && (p.line_array || std::abs(sep) < 0.5 * kPi));
        };
        const bool any = in_kernel(lo);
        auto room = [&] { return p.circular ? hi - lo + 1 < std::int64_t(columns) : true; };
        while (any && room() && (p.circular || lo > 0) && in_kernel(lo - 1))
            --lo;
        while (any && room() && (p.circular || hi + 1 < std::int64_t(columns)) && in_kernel(hi + 1))
            ++hi;
        // One row per band, side by side: row[b * width + (c - lo)].
        const std::size_t width = any ? std::size_t(hi - lo + 1) : 0;
        row.assign(width * bands, 0.0f);
        for (std::int64_t c = lo; any && c <= hi; ++c) {
            if (tent) {
                row[std::size_t(c - lo)] = static_cast<float>(std::max(1.0 - beams_away(c), 0.0));
                continue;
            }
            // The pattern less what the far grid already gives this column at this beam: within the reach
            // the two add up to the pattern exactly, whatever the grid's cells make of it.
            const double far = p.far_cells > 0 ? far_grid_weight(p, wrap(c), j) : 0.0;
            const double sep = separation(c), x = x_of(sep);
            const bool configured = in_configured(c, beams_away(c));
            for (std::uint32_t b = 0; b < bands; ++b)
                if (configured || (defocus && x <= band_reach_x(b)))
                    row[b * width + std::size_t(c - lo)] =
                        static_cast<float>(pattern_in_band(p, defocused.get(), b, j, sep) - far);
        }
        // Zero weights at both ends of every band are left out.
        auto zero_column = [&](std::size_t i) {
            for (std::uint32_t b = 0; b < bands; ++b)
                if (row[b * width + i] != 0.0f) return false;
            return true;
        };
        std::size_t first = 0, end = width;
        while (first < end && zero_column(first))
            ++first;
        while (end > first && zero_column(end - 1))
            --end;
        offset[j] = flat.size();
        for (std::uint32_t b = 0; b < bands; ++b)
            flat.insert(flat.end(), row.begin() + b * width + first, row.begin() + b * width + end);
        p.near_column_begin[j] = static_cast<std::int32_t>(lo + std::int64_t(first));
        p.near_column_count[j] = static_cast<std::uint32_t>(end - first);
        p.near_column_taps = std::max(p.near_column_taps, p.near_column_count[j]);
    }
    const std::size_t taps = p.near_column_taps;
    p.near_column_weight.assign(std::size_t(bands) * beams * taps, 0.0f);
    for (std::uint32_t b = 0; b < bands; ++b)
        for (std::uint32_t j = 0; j < beams; ++j) {
            const std::size_t count = p.near_column_count[j];
            const auto from = flat.begin() + std::ptrdiff_t(offset[j] + b * count);
            std::copy(from, from + std::ptrdiff_t(count),
                      p.near_column_weight.begin() + std::ptrdiff_t((std::size_t(b) * beams + j) * taps));
        }
}

} // namespace

// Step: the horizontal pattern's kernel: the far side lobes' grid beyond the reach, and the near kernel
// over the profile columns within it.
Result<void> plan_sidelobe_kernel(Plan& p, std::uint32_t half_taps, double reach, bool far_sidelobes) {
    p.sidelobe_taps = 2 * half_taps + 1;
    const double reach_units = sidelobe_reach(p, reach);
    // A kernel asked to reach across the fan (bench accuracy's reference) is exact everywhere it reaches.
    const bool stops_short = reach < p.config.hfov_deg * kDegToRad;
    if (half_taps > 0 && far_sidelobes && stops_short) plan_far_sidelobes(p, reach_units);
    if (p.far_cells > 0) // meta.json and Frame::effects say how the pattern reaches past the kernel
        for (EffectState& state : p.effects.states)
            if (state.name == "horizontal_pattern")
                state.why += "; far side lobes over the fan on " + std::to_string(p.far_cells) + " cells" +
                             (p.far_channels == 3 ? " (sinc^2 crests and nulls exact)" : " (the lobes' mean level)");
    p.near_column_taps = 0;
    p.near_column_weight.clear();
    p.near_column_begin.clear();
    p.near_column_count.clear();
    if (!p.effects.horizontal_pattern) return {};
    if (half_taps == 0) {
        plan_near_columns(p, reach_units, 0.0, true);
        return {};
    }
    // The reach in the separation unit, and no further than K + 1 beams (K = half_taps: the kernel's reach
    // over the beam spacing, capped at kMaxSidelobeHalfTaps, and on a circle under half of it so that no
    // column is heard twice; a column up to a beam past K lies within the reach where it was not capped).
    const double offset_cut = double(half_taps) + 1.0;
    // Each beam's weights for the columns within reach (at most all of them; bounded here by the densest
    // columns): refused where that table alone would pass 1 GiB (thousands of beams with a kernel across
    // the fan).
    double min_column_spacing = std::numeric_limits<double>::infinity();
    for (std::uint32_t c = 1; c < p.profile_columns; ++c) {
        const double gap = column_position(p, c - 1) - column_position(p, c);
        if (gap > 0.0) min_column_spacing = std::min(min_column_spacing, gap);
    }
    // Out of focus the most defocused band reaches further (plan_focus.h focus_reach_x).
    const double focus_units =
        out_of_focus(p) ? std::min(focus_reach_x(p.near_band_phase.back()) / p.hpattern_k, 1.0) : 0.0;
    const double kernel_units = std::max(reach_units, p.line_array ? focus_units : std::asin(focus_units));
    const double widest = std::min<double>(p.profile_columns, 2.0 * kernel_units / min_column_spacing + 2.0);
    const double table_bytes = 4.0 * p.beams * widest * p.near_bands;
    if (table_bytes > 1073741824.0)
        return make_error(
            ErrorCode::invalid_argument,
            "config: the side-lobe kernel's column table would hold " +
                std::to_string(static_cast<long long>(table_bytes / 1048576.0)) + " MiB (" + std::to_string(p.beams) +
                " beams x up to " + std::to_string(static_cast<long long>(widest)) + " profile columns each" +
                (p.near_bands > 1 ? ", in " + std::to_string(p.near_bands) + " focus bands" : "") + "); " +
                (p.near_bands > 1 ? "raise range_min, or move focus_range into the range window"
                                  : "lower accuracy.sidelobe_kernel_beamwidths or beams"));
    plan_near_columns(p, reach_units, offset_cut, false);
    if (out_of_focus(p)) // meta.json and Frame::effects say how far out of focus it goes
        for (EffectState& state : p.effects.states)
            if (state.name == "horizontal_pattern")
                state.why += "; focused " +
                             (p.config.beam_focus == BeamFocus::fixed ? "at " + fmt(p.config.focus_range_m) + " m"
                                                                      : std::string("at infinity")) +
                             ": " + std::to_string(p.near_bands) + " focus bands, defocus up to " +
                             fmt(p.near_band_phase.back()) + " rad";
    return {};
}

} // namespace plan_steps
} // namespace vksonar
