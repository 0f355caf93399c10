// The range spread of one pixel, shared by the beamform stage's profiles (cpu_beamform_profile.cpp) and the
// labels stage (labels.cpp), which must spread each pixel's energy over the same bins with the same
// shares.
#pragma once

#include <cstddef>
#include <cstdint>

#include "core/plan.h"
#include "core/sonar_math.hpp"

namespace vksonar::cpu {

// The ranges of pixel (row j, column c)'s row neighbours left and right, 0 where there is none in its
// view (view_first_column, view_columns; across its edge lies another camera's image), as profile.comp's
// row_neighbour_ranges.
struct RowNeighbours {
    float left_r, right_r;
};
// ... where the caller knows the view's columns [view_first, view_end) (the profile loops walk one view
// at a time: no division per pixel).
[[gnu::always_inline]] inline RowNeighbours row_neighbours_within(const Plan& plan, const float* echo2, std::uint32_t j,
                                                                  std::uint32_t c, std::uint32_t view_first,
                                                                  std::uint32_t view_end) {
    const float* p = echo2 + 2 * (static_cast<std::size_t>(j) * plan.columns + c);
    return {c > view_first ? p[-1] : 0.0f, c + 1 < view_end ? p[3] : 0.0f};
}
[[gnu::always_inline]] inline RowNeighbours row_neighbours(const Plan& plan, const float* echo2, std::uint32_t j,
                                                           std::uint32_t c) {
    const std::uint32_t view = view_of_column(plan, c), first = view_first_column(plan, view);
    return row_neighbours_within(plan, echo2, j, c, first, first + view_columns(plan, view));
}

// The range spread of pixel (row j, column c) of energy e, from the five-row window of its column and its
// row neighbours (as profile.comp's pixel_spread; range 0 = no hit or outside the image). Inlined into
// both profile loops.
template <class Real>
[[gnu::always_inline]] inline typename Math<Real>::RangeSpread
pixel_spread(const Plan& plan, const float* echo2, std::uint32_t j, std::uint32_t c, Real e, RowNeighbours across,
             Real range_min, Real inv_bin_width) {
    using vec2 = typename Math<Real>::vec2;
    const std::uint32_t C = plan.columns, R = plan.rows;
    const auto row_echo = [&](std::int64_t row) {
        if (row < 0 || row >= static_cast<std::int64_t>(R)) return vec2(Real(0));
        const float* q = echo2 + 2 * (static_cast<std::size_t>(row) * C + c);
        return vec2(static_cast<Real>(q[0]), static_cast<Real>(q[1]));
    };
    const std::int64_t jj = j;
    const float* p = echo2 + 2 * (static_cast<std::size_t>(j) * C + c);
    const Real range = static_cast<Real>(p[1]);
    return Math<Real>::range_spread(plan.params.range_kernel, row_echo(jj - 2), row_echo(jj - 1), vec2(e, range),
                                    row_echo(jj + 1), row_echo(jj + 2), static_cast<Real>(across.left_r),
                                    static_cast<Real>(across.right_r), range_min, inv_bin_width,
                                    static_cast<Real>(plan.params.edge_relative_jump), plan.bins,
                                    static_cast<Real>(plan.params.absorption_per_bin));
}
template <class Real>
[[gnu::always_inline]] inline typename Math<Real>::RangeSpread pixel_spread(const Plan& plan, const float* echo2,
                                                                            std::uint32_t j, std::uint32_t c, Real e,
                                                                            Real range_min, Real inv_bin_width) {
    return pixel_spread<Real>(plan, echo2, j, c, e, row_neighbours(plan, echo2, j, c), range_min, inv_bin_width);
}

} // namespace vksonar::cpu
