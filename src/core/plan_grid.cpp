// make_plan's steps for the depth pass's pixel grid (plan_steps.h): the slices, the vertical side
// lobes' tier views beside them, a host engine's grid instead, the profile columns and each pixel's cone
// coordinate.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "core/angles.h"
#include "core/plan_steps.h"
#include "core/sonar_math.hpp"
#include "core/tier_extent.h"

namespace vksonar::plan_steps {

namespace {
// lavapipe and most GPUs allow 16384-wide framebuffers; more pixel columns than that buys nothing.
constexpr std::uint32_t kMaxColumns = 16384;
constexpr std::uint32_t kMaxRows = 4096;
} // namespace

// The pixel columns that resolve an angle `width_rad` at pixels_per_beam per resolved angle (the finer
// of the beam spacing and the beamwidth).
double columns_for(const Plan& p, double width_rad) {
    const SonarConfig& c = p.config;
    const double hfov = c.hfov_deg * kDegToRad;
    const double spacing = p.beams > 1 ? hfov / p.beams : hfov;
    const double resolved_angle = std::min(spacing, c.horizontal_beamwidth_deg * kDegToRad);
    return std::ceil(c.pixels_per_beam * width_rad / resolved_angle);
}

// Step: vksonar's own pixel grid and the vertical pattern's constants (its coverage reaches the
// pattern's first null).
Result<void> plan_pixel_grid(Plan& p) {
    const SonarConfig& c = p.config;
    const double hfov = c.hfov_deg * kDegToRad;

    // Vertical coverage (physical mode): at least vertical_coverage beamwidths and, with the vertical
    // pattern on, its main lobe out to the first null, where the pattern's power reaches 0 (cut at
    // 20 deg, the sinc pattern of a 20-degree beam is still at -17 dB: the first seabed returns, which
    // come from there, lost 5-20 dB). And at every azimuth of a slice: a perspective slice sees its edge
    // columns' rays at lower elevations (tan(elevation) = v / sqrt(1 + u^2)), so v reaches further by
    // sqrt(1 + tan_half_h^2) to hold the elevation there (a 60-degree slice's edges saw only +-17.5 of
    // +-20 degrees). The null is found by sampling (horizontal_lobes: steps of 0.045 deg); gaussian and
    // box patterns have none. Rows keep rows_per_vfov per beamwidth of the centre column's coverage
    // (docs/pipeline.md). The legacy modes keep their plugins' plain vertical field of view.
    const double vfov = c.vfov_deg * kDegToRad;
    p.vpattern_chebyshev_a = c.vertical_pattern == BeamPattern::chebyshev ? chebyshev_a(c.vertical_sidelobe_db) : 0.0;
    p.vpattern_k = pattern_constant(c.vertical_pattern, vfov, p.vpattern_chebyshev_a);
    p.vpattern_halfwidth_rad = 0.5 * vfov;
    double half_coverage = 0.5 * std::min(c.vfov_deg * c.vertical_coverage, 170.0) * kDegToRad;
    if (c.mode == SonarMode::physical) {
        if (c.effects.vertical_pattern != EffectMode::off) {
            const HorizontalLobes lobes = horizontal_lobes(shader_id(c.vertical_pattern), p.vpattern_k,
                                                           p.vpattern_halfwidth_rad, p.vpattern_chebyshev_a, 0.5 * kPi);
            half_coverage = std::max(half_coverage, lobes.first_null_rad);
        }
        half_coverage = std::min(half_coverage, 85.0 * kDegToRad);
    }

    // The azimuths the pixel grid covers: the fan (planar), or with line_array the fan's edge cones as
    // far as the covered elevations take them: the cone sin(theta) = cos(elevation) sin(azimuth) of the
    // edge beam reaches azimuth asin(sin(hfov / 2) / cos(half_coverage)). Up to 89 degrees: each slice
    // must stay short of 90 (the cone coordinate then increases along a row), and what lies beyond is
    // a sliver at the largest elevations of a fan close to 180 degrees.
    double covered = hfov;
    if (p.line_array) {
        const double reach = std::sin(0.5 * hfov) / std::cos(half_coverage);
        covered = 2.0 * std::min(reach < 1.0 ? std::asin(reach) : 0.5 * kPi, 89.0 * kDegToRad);
        covered = std::max(covered, hfov);
    }

    // Pixel grid: enough columns that pixels_per_beam of them fall in the finer of the beam spacing and
    // the beamwidth, split into slices no wider than max_slice_deg.
    const double covered_deg = p.line_array ? covered / kDegToRad : c.hfov_deg;
    const double wanted_columns = columns_for(p, covered);
    p.slices = static_cast<std::uint32_t>(std::ceil(covered_deg / c.max_slice_deg - 1e-9));
    p.slices = std::max(1u, p.slices);
    if (p.slices > shared::kMaxSlices) {
        const std::string span = p.line_array ? "the " + fmt(covered_deg) +
                                                    "-degree span a line array's pixel grid covers (hfov " +
                                                    fmt(c.hfov_deg) + ")"
                                              : "hfov " + fmt(c.hfov_deg);
        return make_error(ErrorCode::invalid_argument, "config: accuracy.max_slice = " + fmt(c.max_slice_deg) +
                                                           " needs " + std::to_string(p.slices) + " slices for " +
                                                           span + "; at most " + std::to_string(shared::kMaxSlices));
    }
    if (wanted_columns > kMaxColumns) {
        // name what sets the column width: the beam spacing or, where it is finer, the beamwidth
        const double spacing_deg = p.beams > 1 ? c.hfov_deg / p.beams : c.hfov_deg;
        const std::string finer = c.horizontal_beamwidth_deg < spacing_deg
                                      ? "horizontal_beamwidth = " + fmt(c.horizontal_beamwidth_deg) + " degrees"
                                      : "the beam spacing hfov / beams = " + fmt(spacing_deg) + " degrees";
        return make_error(ErrorCode::invalid_argument,
                          "config: " + fmt(wanted_columns) +
                              " pixel columns needed (accuracy.pixels_per_beam = " + fmt(c.pixels_per_beam) + " per " +
                              finer + ", the finer of the beam spacing and the beamwidth, over " + fmt(covered_deg) +
                              " degrees) exceeds " + std::to_string(kMaxColumns));
    }
    const std::uint32_t min_columns = 8; // a 1-beam sonar still needs a few columns for its pattern
    const std::uint32_t total = std::max(min_columns, static_cast<std::uint32_t>(wanted_columns));
    p.slice_columns = (total + p.slices - 1) / p.slices;
    p.columns = p.slice_columns * p.slices;
    p.slice_width_rad = covered / p.slices;
    p.tan_half_h = std::tan(0.5 * p.slice_width_rad);

    double tan_half_v = std::tan(half_coverage);
    if (c.mode == SonarMode::physical) {
        tan_half_v *= std::sqrt(1.0 + p.tan_half_h * p.tan_half_h);
        p.elevation_gate_sin = std::sin(half_coverage);
    }
    p.tan_half_v = tan_half_v;
    p.vertical_coverage_rad = 2.0 * std::atan(p.tan_half_v); // at the slice's centre column
    const double rows = std::ceil(c.rows_per_vfov * p.vertical_coverage_rad / (c.vfov_deg * kDegToRad));
    if (rows > kMaxRows) {
        return make_error(ErrorCode::invalid_argument,
                          "config: accuracy.rows_per_vfov = " + std::to_string(c.rows_per_vfov) + " gives " +
                              fmt(rows) + " rows; at most " + std::to_string(kMaxRows));
    }
    p.rows = std::max(2u, static_cast<std::uint32_t>(rows));

    // The slices: level cameras at their centre azimuths. The float table rounds the double centre's
    // cosine and sine; the double geometry takes them of the float centre (as the depth pass always has).
    p.view_geometry.assign(p.slices, ViewGeometry{});
    p.slice_info.assign(p.slices, shared::SliceInfo{});
    for (std::uint32_t s = 0; s < p.slices; ++s) {
        const double centre = 0.5 * covered - (s + 0.5) * p.slice_width_rad;
        const float centre_f = static_cast<float>(centre), cs = static_cast<float>(std::cos(centre)),
                    sn = static_cast<float>(std::sin(centre));
        const double cd = std::cos(double(centre_f)), sd = std::sin(double(centre_f));
        ViewGeometry& view = p.view_geometry[s];
        view = {
            {cd, sd, 0.0},        {sd, -cd, 0.0}, {0.0, 0.0, -1.0}, p.tan_half_h, p.tan_half_v, -p.elevation_gate_sin,
            p.elevation_gate_sin, false,          {1.0, 0.0},       {1.0, 0.0}};
        shared::SliceInfo& info = p.slice_info[s];
        info.center_azimuth_rad = centre_f;
        info.tan_half_h = static_cast<float>(p.tan_half_h);
        info.tan_half_v = static_cast<float>(p.tan_half_v);
        info.forward_x = cs;
        info.forward_y = sn;
        info.right_x = sn;
        info.right_y = -cs;
        info.down_z = -1.0f;
        info.sin_elevation_min = -static_cast<float>(p.elevation_gate_sin);
        info.sin_elevation_max = static_cast<float>(p.elevation_gate_sin);
    }
    p.views = p.slices;

    return {};
}

namespace {

// A tier view's pixel size relative to a slice's: the square root of the ratio of their solid angles
// (the views share the grid's rows: their half extents' products, the horizontal ones per column), for
// a tier view `columns` wide.
double tier_pixel_ratio(const Plan& p, double tan_h, double tan_v, std::uint32_t columns) {
    return std::sqrt((tan_h / columns) / (p.tan_half_h / p.slice_columns) * (tan_v / p.tan_half_v));
}

// The most the tier views' pixels may be coarser than the slices' before the side lobes are left out.
constexpr double kMaxTierPixelRatio = 4.0;

// Whether the line array's cone coordinate increases along every row of the view (its axis cosine, the
// ray's y over its length, decreases with u), sampled at every pixel centre in double, with a margin.
bool cone_increases_along_rows(const Plan& p, const ViewGeometry& v, std::uint32_t columns) {
    for (std::uint32_t row = 0; row < p.rows; ++row) {
        const double vv = math_f64::pixel_coord(row, p.rows, v.tan_half_v);
        double previous = 2.0;
        for (std::uint32_t col = 0; col < columns; ++col) {
            const double u = math_f64::pixel_coord(col, columns, v.tan_half_h);
            const double y = v.forward[1] + u * v.right[1] + vv * v.down[1];
            const double axis = y / std::sqrt(1.0 + u * u + vv * vv);
            if (!(axis < previous - 1e-6)) return false;
            previous = axis;
        }
    }
    return true;
}

// A tier view's camera: looking at azimuth `centre`, pitched by `pitch` (positive: down), right axis level.
ViewGeometry tier_camera(double centre, double pitch) {
    ViewGeometry v;
    const double c = std::cos(centre), s = std::sin(centre), cb = std::cos(pitch), sb = std::sin(pitch);
    const double f[3] = {cb * c, cb * s, -sb}, r[3] = {s, -c, 0.0};
    for (int i = 0; i < 3; ++i) {
        v.forward[i] = f[i];
        v.right[i] = r[i];
    }
    v.down[0] = f[1] * r[2] - f[2] * r[1]; // down = forward x right, as a slice's (0, 0, -1)
    v.down[1] = f[2] * r[0] - f[0] * r[2];
    v.down[2] = f[0] * r[1] - f[1] * r[0];
    return v;
}

// The half extents a camera needs to hold the cell azimuth [a0, a1] x elevation [e0, e1] (sampled
// densely on its edges, where a cell's projection has its extremes, and on a coarse interior grid);
// false if a direction of the cell is not in front of it.
bool cell_extents(const ViewGeometry& v, double a0, double a1, double e0, double e1, double& tan_h, double& tan_v) {
    constexpr int kEdge = 96, kInner = 12;
    tan_h = tan_v = 0.0;
    auto hold = [&](double a, double e) {
        const double d[3] = {std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e)};
        const double z = d[0] * v.forward[0] + d[1] * v.forward[1] + d[2] * v.forward[2];
        if (!(z > 0.05)) return false;
        tan_h = std::max(tan_h, std::abs(d[0] * v.right[0] + d[1] * v.right[1] + d[2] * v.right[2]) / z);
        tan_v = std::max(tan_v, std::abs(d[0] * v.down[0] + d[1] * v.down[1] + d[2] * v.down[2]) / z);
        return true;
    };
    for (int i = 0; i <= kEdge; ++i) {
        const double t = double(i) / kEdge, a = a0 + t * (a1 - a0), e = e0 + t * (e1 - e0);
        if (!hold(a, e0) || !hold(a, e1) || !hold(a0, e) || !hold(a1, e)) return false;
    }
    for (int i = 1; i < kInner; ++i)
        for (int j = 1; j < kInner; ++j)
            if (!hold(a0 + (a1 - a0) * i / kInner, e0 + (e1 - e0) * j / kInner)) return false;
    return true;
}

// The tier views of one band (elevations [e0, e1], down: below the slices): the azimuths in front of
// the array, [-90, 90) degrees (its baffled elements hear nothing from behind), in n equal wedges, n
// the fewest whose cameras' pixels stay within accuracy.tier_pixel_ratio of the slices' in angle (the
// square root of their solid angles' ratio; at most 8 wedges, the finest they allow if none does). The
// side lobes are 13 dB and more below the main lobe: their returns need the range footprint more than
// fine azimuths (a flat seabed's closed form holds within 0.07 dB at 2.85x, tests/hard_cases). Each
// camera is pitched to need the smallest pixels; its half extents are its cell's, judged at a slice's
// width (plan_tier_views then narrows the views and widens each by two pixels past its cell).
std::vector<ViewGeometry> tier_band(const Plan& p, double e0, double e1, bool down) {
    std::vector<ViewGeometry> best;
    double best_ratio = std::numeric_limits<double>::infinity();
    for (int n = 1; n <= 8; ++n) {
        std::vector<ViewGeometry> band;
        double worst = 0.0;
        for (int w = 0; w < n; ++w) {
            const double a0 = -0.5 * kPi + kPi * w / n, a1 = a0 + kPi / n, centre = 0.5 * (a0 + a1);
            ViewGeometry chosen;
            double chosen_ratio = std::numeric_limits<double>::infinity();
            for (int i = 1; i <= 90; ++i) {
                const double pitch = i * kDegToRad;
                ViewGeometry v = tier_camera(centre, down ? pitch : -pitch);
                double tan_h = 0.0, tan_v = 0.0;
                if (!cell_extents(v, a0, a1, e0, e1, tan_h, tan_v)) continue;
                const double ratio = tier_pixel_ratio(p, tan_h, tan_v, p.slice_columns);
                if (ratio < chosen_ratio) {
                    chosen_ratio = ratio;
                    v.tan_half_h = tan_h;
                    v.tan_half_v = tan_v;
                    v.wedge = true;
                    v.wedge_start[0] = std::cos(a0);
                    v.wedge_start[1] = std::sin(a0);
                    v.wedge_end[0] = std::cos(a1);
                    v.wedge_end[1] = std::sin(a1);
                    chosen = v;
                }
            }
            worst = std::max(worst, chosen_ratio);
            band.push_back(chosen);
        }
        if (worst < best_ratio) {
            best_ratio = worst;
            best = band;
        }
        if (worst <= p.config.tier_pixel_ratio) break;
    }
    return best;
}

} // namespace

// Step (after the pixel grid): the vertical side lobes. Where they are simulated, tier views below
// and above the slices' band see every elevation beyond the elevation gate; they join the pixel
// grid after the slices. Only with a line array's beams (a tier pixel's beam is its cone, which any
// direction has; planar beams are the pixel columns' azimuths) and a vertical pattern with side lobes.
Result<void> plan_tier_views(Plan& p) {
    const SonarConfig& c = p.config;
    const EffectMode mode = c.effects.vertical_sidelobes;
    const bool has_lobes = c.vertical_pattern == BeamPattern::sinc || c.vertical_pattern == BeamPattern::hann ||
                           c.vertical_pattern == BeamPattern::chebyshev;
    std::string without;
    if (c.mode != SonarMode::physical)
        without = "the legacy modes have no vertical side lobes";
    else if (c.effects.vertical_pattern == EffectMode::off)
        without = "the vertical pattern is off";
    else if (!has_lobes)
        without = "the " + std::string(c.vertical_pattern == BeamPattern::box ? "box" : "gaussian") +
                  " vertical pattern has no side lobes";
    else if (!p.line_array)
        without = "planar beams (" + p.beam_geometry_why + "): tier views need the line_array beam geometry";
    else if (!(p.elevation_gate_sin < 1.0))
        without = "the depth pass covers every elevation";
    if (mode == EffectMode::off) {
        p.vertical_sidelobes_why = "off in config";
        return {};
    }
    if (!without.empty()) {
        if (mode == EffectMode::on)
            return make_error(ErrorCode::invalid_argument, "config: effects.vertical_sidelobes = on, but " + without);
        p.vertical_sidelobes_why = "auto: " + without;
        return {};
    }
    const double gate = std::asin(p.elevation_gate_sin);
    std::vector<ViewGeometry> tiers = tier_band(p, -0.5 * kPi, -gate, true);
    const std::size_t below = tiers.size();
    for (const ViewGeometry& v : tier_band(p, gate, 0.5 * kPi, false))
        tiers.push_back(v);
    // The tier views' width: the fewest columns (at most a slice's) that keep their pixels within
    // accuracy.tier_pixel_ratio of the slices'; the side lobes' share of the frame's time follows it.
    // Each camera is then widened by two pixels past its cell.
    const auto widened = [&](ViewGeometry v, std::uint32_t columns) {
        v.tan_half_h *= 1.0 + 4.0 / columns;
        v.tan_half_v *= 1.0 + 4.0 / p.rows;
        return v;
    };
    const auto worst_ratio_at = [&](std::uint32_t columns) {
        double worst = 0.0;
        for (const ViewGeometry& cell : tiers) {
            const ViewGeometry v = widened(cell, columns);
            worst = std::max(worst, tier_pixel_ratio(p, v.tan_half_h, v.tan_half_v, columns));
        }
        return worst;
    };
    constexpr std::uint32_t kMinTierColumns = 8;
    const std::uint32_t full = p.slice_columns;
    std::uint32_t tier_columns = full;
    if (const double at_full = worst_ratio_at(full); at_full < c.tier_pixel_ratio) {
        const double scale = at_full / c.tier_pixel_ratio; // the ratio grows as 1 / sqrt(columns)
        tier_columns = std::clamp(static_cast<std::uint32_t>(std::ceil(full * scale * scale)), kMinTierColumns, full);
        while (tier_columns < full && worst_ratio_at(tier_columns) > c.tier_pixel_ratio)
            ++tier_columns;
    }
    for (ViewGeometry& v : tiers)
        v = widened(v, tier_columns);
    // What the tier views can hold: pixels at most kMaxTierPixelRatio times the slices' (a fan of a few
    // degrees has slices of a few columns; its tier views would be as many columns over 90 degrees), and
    // a cone coordinate that increases along each of their rows (the profile stage's gather needs it).
    double worst_ratio = 0.0;
    bool monotonic = true;
    for (const ViewGeometry& v : tiers) {
        worst_ratio = std::max(worst_ratio, tier_pixel_ratio(p, v.tan_half_h, v.tan_half_v, tier_columns));
        monotonic = monotonic && cone_increases_along_rows(p, v, tier_columns);
    }
    if (worst_ratio > kMaxTierPixelRatio || !monotonic) {
        const std::string why = !monotonic
                                    ? "the tier views' rows would not run along the beams (vfov " + fmt(c.vfov_deg) +
                                          ", hfov " + fmt(c.hfov_deg) + ")"
                                    : "the tier views' pixels would be " + fmt(std::round(worst_ratio * 10) / 10) +
                                          "x the slices' (at most " + fmt(kMaxTierPixelRatio) + "x)";
        if (mode == EffectMode::on)
            return make_error(ErrorCode::invalid_argument, "config: effects.vertical_sidelobes = on, but " + why);
        p.vertical_sidelobes_why = "auto: off: " + why;
        return {};
    }
    if (p.slices + tiers.size() > shared::kMaxViews)
        return make_error(ErrorCode::invalid_argument,
                          "config: accuracy.max_slice = " + fmt(c.max_slice_deg) + " gives " +
                              std::to_string(p.slices) + " slices and " + std::to_string(tiers.size()) +
                              " tier views for the vertical side lobes; at most " + std::to_string(shared::kMaxViews) +
                              " views (raise max_slice or set effects.vertical_sidelobes off)");
    // Each band's elevation range, as its views gate it: beyond the slices' gate (the slices keep
    // |sin e| <= gate, the tiers the rest, so every direction is counted once).
    const float gate_f = static_cast<float>(p.elevation_gate_sin);
    for (std::size_t i = 0; i < tiers.size(); ++i) {
        ViewGeometry& v = tiers[i];
        const bool down = i < below;
        v.sin_elevation_min = down ? -2.0 : std::nextafter(p.elevation_gate_sin, 2.0);
        v.sin_elevation_max = down ? std::nextafter(-p.elevation_gate_sin, -2.0) : 2.0;
        shared::SliceInfo info{};
        info.center_azimuth_rad = static_cast<float>(std::atan2(v.forward[1], v.forward[0]));
        info.tan_half_h = static_cast<float>(v.tan_half_h);
        info.tan_half_v = static_cast<float>(v.tan_half_v);
        info.forward_x = static_cast<float>(v.forward[0]);
        info.forward_y = static_cast<float>(v.forward[1]);
        info.forward_z = static_cast<float>(v.forward[2]);
        info.right_x = static_cast<float>(v.right[0]);
        info.right_y = static_cast<float>(v.right[1]);
        info.right_z = static_cast<float>(v.right[2]);
        info.down_x = static_cast<float>(v.down[0]);
        info.down_y = static_cast<float>(v.down[1]);
        info.down_z = static_cast<float>(v.down[2]);
        info.sin_elevation_min = down ? -2.0f : std::nextafter(gate_f, 2.0f);
        info.sin_elevation_max = down ? std::nextafter(-gate_f, -2.0f) : 2.0f;
        info.wedge = 1u;
        info.wedge_start_x = static_cast<float>(v.wedge_start[0]);
        info.wedge_start_y = static_cast<float>(v.wedge_start[1]);
        info.wedge_end_x = static_cast<float>(v.wedge_end[0]);
        info.wedge_end_y = static_cast<float>(v.wedge_end[1]);
        p.view_geometry.push_back(v);
        p.slice_info.push_back(info);
    }
    p.views = static_cast<std::uint32_t>(p.view_geometry.size());
    p.tier_columns = tier_columns;
    p.columns = p.slice_columns * p.slices + tier_columns * (p.views - p.slices);
    p.vertical_sidelobes_why =
        (mode == EffectMode::on ? std::string("on in config") : std::string("auto")) +
        ": the vertical pattern's side lobes beyond +-" + fmt(std::round(gate / kDegToRad * 10.0) / 10.0) +
        " deg, to the nadir and the zenith: " + std::to_string(below) + " + " + std::to_string(tiers.size() - below) +
        " tier views, pixels up to " + fmt(std::round(worst_ratio * 100.0) / 100.0) + "x the slices'";
    return {};
}

// Step, instead of plan_pixel_grid: a host engine's pixel grid (one slice) and the vertical
// pattern's constants.
void use_host_grid(Plan& p, const HostPixelGrid& grid) {
    const SonarConfig& c = p.config;
    const double vfov = c.vfov_deg * kDegToRad;
    p.vpattern_chebyshev_a = c.vertical_pattern == BeamPattern::chebyshev ? chebyshev_a(c.vertical_sidelobe_db) : 0.0;
    p.vpattern_k = pattern_constant(c.vertical_pattern, vfov, p.vpattern_chebyshev_a);
    p.vpattern_halfwidth_rad = 0.5 * vfov;
    p.slices = 1;
    p.slice_columns = grid.columns;
    p.columns = grid.columns;
    p.rows = grid.rows;
    p.tan_half_h = grid.tan_half_h;
    p.tan_half_v = grid.tan_half_v;
    p.slice_width_rad = 2.0 * std::atan(grid.tan_half_h);
    p.vertical_coverage_rad = 2.0 * std::atan(grid.tan_half_v);
    p.views = 1;
    ViewGeometry view;
    view.tan_half_h = grid.tan_half_h;
    view.tan_half_v = grid.tan_half_v;
    p.view_geometry.assign(1, view);
    shared::SliceInfo info{};
    info.tan_half_h = static_cast<float>(grid.tan_half_h);
    info.tan_half_v = static_cast<float>(grid.tan_half_v);
    info.forward_x = 1.0f;
    info.right_y = -1.0f;
    info.down_z = -1.0f;
    info.sin_elevation_min = -2.0f;
    info.sin_elevation_max = 2.0f;
    p.slice_info.assign(1, info);
    p.vertical_sidelobes_why = "a host engine's depth image: its own pixel grid";
}

// Step (after the pixel grid): the columns of the range profiles. line_array: the cone columns over the
// fan, as many as the planar grid would have pixel columns there.
void plan_profile_columns(Plan& p) {
    if (!p.line_array) {
        p.profile_columns = p.columns;
        p.cone_step_rad = 0.0;
        p.pixel_cone_coord.clear();
        return;
    }
    const double hfov = p.config.hfov_deg * kDegToRad;
    p.profile_columns = std::max(8u, static_cast<std::uint32_t>(columns_for(p, hfov)));
    p.cone_step_rad = hfov / p.profile_columns;
}

// Step (after the memory check): line_array, every pixel's cone coordinate. Along each view's row it
// must not decrease (the profile stage's gather searches a view's row for a cone column's pixels).
void plan_cone_table(Plan& p) {
    if (!p.line_array) return;
    const double hfov = p.config.hfov_deg * kDegToRad;
    const float half_fov = static_cast<float>(0.5 * hfov);
    const float inv_step = static_cast<float>(1.0 / p.cone_step_rad);
    p.pixel_cone_coord.resize(static_cast<std::size_t>(p.rows) * p.columns);
    for (std::uint32_t row = 0; row < p.rows; ++row) {
        for (std::uint32_t col = 0; col < p.columns; ++col) {
            const std::uint32_t index = view_of_column(p, col), first = view_first_column(p, index);
            const math_f32::PixelView view = math_f32::view_of_slice(p.slice_info[index]);
            const float v = math_f32::pixel_coord(row, p.rows, view.tan_half_v);
            const float u = math_f32::pixel_coord(col - first, view_columns(p, index), view.tan_half_h);
            const float axis = math_f32::array_axis_cosine(u, v, view);
            p.pixel_cone_coord[std::size_t(row) * p.columns + col] = math_f32::cone_coord(axis, half_fov, inv_step);
            // A tier view's (plan_tier_views checked its rows in double, with a margin): held non-decreasing
            // against float rounding, the same table for both backends. The slices' as before.
            float& x = p.pixel_cone_coord[std::size_t(row) * p.columns + col];
            if (col != first && index >= p.slices) x = std::max(x, (&x)[-1]);
        }
    }
    // The tier pixels' widest reach from their cone coordinate, over 1 per mille and a thousandth of a
    // column: the searches compare x with a cone column's bounds widened by it, in float.
    float reach = 0.0f;
    for (std::uint32_t row = 0; row < p.rows; ++row) {
        const float* row_x = p.pixel_cone_coord.data() + std::size_t(row) * p.columns;
        for (std::uint32_t view = p.slices; view < p.views; ++view) {
            const std::uint32_t first = view_first_column(p, view), end = first + view_columns(p, view);
            for (std::uint32_t col = first; col < end; ++col) {
                const ConeExtent e = tier_cone_extent(row_x, col, first, end);
                reach = std::max({reach, row_x[col] - e.lo, e.hi - row_x[col]});
            }
        }
    }
    p.tier_cone_reach = reach > 0.0f ? reach * 1.001f + 1e-3f : 0.0f;
}

} // namespace vksonar::plan_steps
