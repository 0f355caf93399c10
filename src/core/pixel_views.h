// The views of the depth pass (Plan::views) and the echo constants as the per-pixel kernels take them
// (PixelView, EchoConstants, EchoTerms: shaders/sonar_kernels.h): in float the SliceInfo floats the shaders read, in
// double the plan's double geometry (which the depth pass's matrices are composed from).
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

// The join group of pixel column c: 0 for the slices of the main band (which join at their seams),
// the view's index for a tier view (whose edges are the image's edges). Sobel reads a neighbour column
// only within the centre's group (normals.comp's joined() is the shader's twin).
inline std::uint32_t view_group(const Plan& plan, std::uint32_t c) {
    const std::uint32_t view = view_of_column(plan, c);
    return view < plan.slices ? 0u : view;
}

// The echo stage's constants of a view in the working precision: float reads the shaders' float values
// (SonarParams, SliceInfo), double the Plan's doubles.
template <class Real> typename Math<Real>::EchoConstants echo_constants(const Plan& plan, std::uint32_t view) {
    const shared::SonarParams& g = plan.params;
    const typename Math<Real>::PixelView pv = pixel_view<Real>(plan, view);
    typename Math<Real>::EchoConstants k;
    if constexpr (std::is_same_v<Real, float>) {
        k = {pv.tan_half_h,
             pv.tan_half_v,
             0.0f,
             0.0f,
             g.depth_a,
             g.depth_b,
             g.gate_min_m,
             g.gate_max_m,
             g.alpha_db_per_m,
             g.vpattern_k,
             g.vpattern_halfwidth_rad,
             g.vpattern_chebyshev_a,
             g.element_k};
    } else {
        k = {pv.tan_half_h,
             pv.tan_half_v,
             0.0,
             0.0,
             plan.depth_a,
             plan.depth_b,
             plan.gate_min_m,
             plan.gate_max_m,
             plan.alpha_db_per_m,
             plan.vpattern_k,
             plan.vpattern_halfwidth_rad,
             plan.vpattern_chebyshev_a,
             plan.element_k};
    }
    k.pixel_du = Real(2) * k.tan_half_h / static_cast<Real>(view_columns(plan, view));
    k.pixel_dv = Real(2) * k.tan_half_v / static_cast<Real>(plan.rows);
    return k;
}

// Which of the echo equation's terms the plan carries; incidence only where normals are at hand.
template <class Real> typename Math<Real>::EchoTerms echo_terms(const Plan& plan, bool with_normals) {
    return {plan.effects.incidence && with_normals,
            plan.rough_materials,
            plan.effects.vertical_pattern,
            plan.params.vpattern_shape,
            plan.effects.spreading,
            plan.effects.absorption};
}

} // namespace vksonar
