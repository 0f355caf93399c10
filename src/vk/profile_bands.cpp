// See profile_bands.h.
#include "vk/profile_bands.h"

#include <algorithm>
#include <cmath>

namespace vksonar::vk {

namespace {

// The pixel columns [begin, end) of one row's view whose cone coordinate x has lo < x < hi (increasing
// along the view: the plan checks it), for windows whose lo and hi only grow: two cursors.
struct WindowCount {
    const float* x;
    std::uint32_t begin, end, first, last;
    WindowCount(const float* row_x, std::uint32_t view_begin, std::uint32_t view_end)
        : x(row_x), begin(view_begin), end(view_end), first(view_begin), last(view_begin) {}
    std::uint32_t count(float lo, float hi) {
        while (first < end && !(x[first] > lo))
            ++first;
        last = std::max(last, first);
        while (last < end && x[last] < hi)
            ++last;
        return last - first;
    }
};

} // namespace

double profile_footprint_bins(const Plan& plan) {
    const double pixel_side = std::max(2.0 * plan.tan_half_h / std::max(plan.slice_columns, 1u),
                                       2.0 * plan.tan_half_v / std::max(plan.rows, 1u));
    const double metres = std::max(kProfileFootprintM, kProfileFootprintGrazing * plan.config.range_max_m * pixel_side);
    return std::min(std::max(kProfileFootprintBins, metres / plan.bin_width_m),
                    double(shared::kMaxFootprintBins) + 2.0);
}

double profile_row_cost(const Plan& plan, const DeviceShape& shape, std::uint32_t row) {
    const double bins = profile_footprint_bins(plan);
    if (!plan.line_array) return 2.0 + bins + 1.0; // the row's loop, its pixel's bins (and the loop's exit)
    const std::uint32_t slices_end = plan.slices * plan.slice_columns;
    const std::uint32_t width = plan.tier_columns;
    const std::uint32_t tiers = plan.views > plan.slices && width > 0 ? (plan.columns - slices_end) / width : 0;
    const float* row_x = plan.pixel_cone_coord.data() + std::size_t(row) * plan.columns;
    const float reach = plan.tier_cone_reach;
    const std::uint32_t cones = shape.cones_per_invocation;
    // a tier pixel feeds the cone columns its extent touches, at most all of an invocation's
    const double tier_cones = std::min<double>(cones, std::floor(2.0 * reach) + 2.0);
    std::vector<WindowCount> windows;
    windows.emplace_back(row_x, 0, slices_end);
    for (std::uint32_t t = 0; t < tiers; ++t)
        windows.emplace_back(row_x, slices_end + t * width, slices_end + (t + 1) * width);
    double worst = 0.0;
    for (std::uint32_t first_cone = 0; first_cone < plan.profile_columns; first_cone += cones) {
        const std::uint32_t end_cone = std::min(first_cone + cones, plan.profile_columns);
        const float lo = float(first_cone) - 1.0f, hi = float(end_cone);
        // per view: its two searches and the pixel loop's exits, a few each, then its pixels
        double cost = 2.0 + 8.0 * windows.size();
        cost += windows[0].count(lo, hi) * (3.0 + bins);
        for (std::size_t v = 1; v < windows.size(); ++v)
            cost += windows[v].count(lo - reach, hi + reach) * (4.0 + tier_cones * (2.0 + bins));
        worst = std::max(worst, cost);
    }
    return worst;
}

std::vector<shared::ProfileRowBand> profile_row_bands(const Plan& plan, const DeviceShape& shape, bool block_rows) {
    std::vector<shared::ProfileRowBand> bands;
    if (block_rows || plan.rows == 0) {
        bands.push_back({0, plan.rows, kLoopCheckTurns, 0});
        return bands;
    }
    // Rows join the band until the next would take it past the budget (each band at least one row). The
    // searches that find each view's first column on the band's first row, and the sub-pixel returns
    // after the last band, cost a few hundred iterations: within the budget's margin.
    std::uint32_t begin = 0;
    double cost = 0.0;
    for (std::uint32_t row = 0; row < plan.rows; ++row) {
        const double row_cost = profile_row_cost(plan, shape, row);
        if (row > begin && cost + row_cost > kProfileBandBudget) {
            bands.push_back({begin, row, kLoopCheckTurns, 0});
            begin = row;
            cost = 0.0;
        }
        cost += row_cost;
    }
    bands.push_back({begin, plan.rows, kLoopCheckTurns, 0});
    return bands;
}

} // namespace vksonar::vk
