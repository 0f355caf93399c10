// The views of the depth pass (Plan::views) as the per-pixel kernels take them (PixelView,
// shaders/sonar_kernels.h): in float the SliceInfo floats the shaders read, in double the plan's
// double geometry (which the depth pass's matrices are composed from).
#pragma once

#include <cstdint>
#include <type_traits>

#include "core/plan.h"
#include "core/sonar_math.hpp"

namespace vksonar {

template <class Real> typename Math<Real>::PixelView pixel_view(const Plan& plan, std::uint32_t view) {
    if constexpr (std::is_same_v<Real, float>) {
        return math_f32::view_of_slice(plan.slice_info[view]);
    } else {
        const ViewGeometry& g = plan.view_geometry[view];
        math_f64::PixelView v;
        v.forward = {g.forward[0], g.forward[1], g.forward[2]};
        v.right = {g.right[0], g.right[1], g.right[2]};
        v.down = {g.down[0], g.down[1], g.down[2]};
        v.tan_half_h = g.tan_half_h;
        v.tan_half_v = g.tan_half_v;
        v.sin_elevation_min = g.sin_elevation_min;
        v.sin_elevation_max = g.sin_elevation_max;
        v.wedge = g.wedge;
        v.wedge_start = {g.wedge_start[0], g.wedge_start[1]};
        v.wedge_end = {g.wedge_end[0], g.wedge_end[1]};
        return v;
    }
}

// Whether pixel columns a and b (both in the image) see one surface side by side: the same view, or two
// slices of the main band, which join at their seams. A tier view's edges are the image's edges.
inline bool columns_join(const Plan& plan, std::uint32_t a, std::uint32_t b) {
    const std::uint32_t va = a / plan.slice_columns, vb = b / plan.slice_columns;
    return va == vb || (va < plan.slices && vb < plan.slices);
}

} // namespace vksonar
