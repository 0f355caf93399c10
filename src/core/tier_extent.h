// line_array: the cone coordinates a tier view's pixel covers (docs/pipeline.md "Vertical side lobes").
#pragma once

#include <cstdint>

#include "core/sonar_math.hpp"

namespace vksonar {

struct ConeExtent {
    float lo = 0, hi = 0;
};

// Pixel column c of a tier view [view_first, view_end) on a row of the plan's cone table (row_x): the
// cone coordinates [lo, hi] it covers, halfway to its neighbours in the view (sonar_kernels.h
// cone_extent_low/high), as profile.comp reads them from the same table.
inline ConeExtent tier_cone_extent(const float* row_x, std::uint32_t c, std::uint32_t view_first,
                                   std::uint32_t view_end) {
    const bool has_previous = c > view_first, has_next = c + 1 < view_end;
    const float previous = has_previous ? row_x[c - 1] : row_x[c];
    const float next = has_next ? row_x[c + 1] : row_x[c];
    return {math_f32::cone_extent_low(previous, row_x[c], next, has_previous, has_next),
            math_f32::cone_extent_high(previous, row_x[c], next, has_previous, has_next)};
}

} // namespace vksonar
