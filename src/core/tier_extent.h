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

// static_cast<int>(std::floor(x)) for x within int's range, without a libm call or a rounding instruction
// the baseline x86-64 build lacks (the CPU profile's per-pixel loop): truncate, then step down where
// truncation rounded up (x negative, not whole).
inline int floor_to_int(float x) {
    const int truncated = static_cast<int>(x);
    return truncated - (x < static_cast<float>(truncated) ? 1 : 0);
}

// The cone columns [first, last] a pixel at cone coordinate x with extent e feeds (its share of any other
// is 0): the tent's floor(x) and floor(x) + 1, or, a tier pixel of some width, the cells [c - 0.5, c + 0.5]
// its extent meets (sonar_kernels.h cone_share, cone_extent_share).
struct ConeColumns {
    int first = 0, last = 0;
};
inline ConeColumns cone_columns_fed(float x, ConeExtent e) {
    if (e.hi > e.lo) return {floor_to_int(e.lo + 0.5f), floor_to_int(e.hi + 0.5f)};
    const int below = floor_to_int(x);
    return {below, below + 1};
}

} // namespace vksonar
