// C++ side of shaders/sonar_math.h: the same formulas in float and double.
#pragma once

#include <cmath>
#include <cstdint>

#include "sonar_shared.h"

namespace vksonar {

#define VKS_ATAN2 std::atan2

namespace math_f32 {
using shared::uint;
using std::abs, std::atan, std::cos, std::cosh, std::exp, std::log, std::max, std::min, std::sin, std::sqrt;
#define REAL float
#include "sonar_math.h"
#undef REAL
} // namespace math_f32

namespace math_f64 {
using shared::uint;
using std::abs, std::atan, std::cos, std::cosh, std::exp, std::log, std::max, std::min, std::sin, std::sqrt;
#define REAL double
#include "sonar_math.h"
#undef REAL
} // namespace math_f64

#undef VKS_ATAN2

// math<Real>::fn selects the precision in templated CPU code.
// The table below reads best as laid out by hand.
// clang-format off
template <class Real> struct Math;
template <> struct Math<float> {
#define VKS_FORWARD(fn) template <class... A> static auto fn(A... a) { return math_f32::fn(a...); }
    VKS_FORWARD(pixel_coord) VKS_FORWARD(pixel_solid_angle) VKS_FORWARD(view_z_from_depth) VKS_FORWARD(slant_range)
    VKS_FORWARD(pixel_azimuth) VKS_FORWARD(pixel_elevation) VKS_FORWARD(pattern_power) VKS_FORWARD(echo_energy)
    VKS_FORWARD(range_bin_coord) VKS_FORWARD(footprint_edge_offset) VKS_FORWARD(footprint_lo)
    VKS_FORWARD(footprint_hi) VKS_FORWARD(footprint_share) VKS_FORWARD(footprint_log_slope) VKS_FORWARD(sinhc_of)
    VKS_FORWARD(incidence_cos) VKS_FORWARD(face_normal_sonar_x) VKS_FORWARD(face_normal_sonar_y)
    VKS_FORWARD(face_normal_sonar_z) VKS_FORWARD(specular_facet) VKS_FORWARD(scatter_factor)
    VKS_FORWARD(resample_share)
#undef VKS_FORWARD
};
template <> struct Math<double> {
#define VKS_FORWARD(fn) template <class... A> static auto fn(A... a) { return math_f64::fn(a...); }
    VKS_FORWARD(pixel_coord) VKS_FORWARD(pixel_solid_angle) VKS_FORWARD(view_z_from_depth) VKS_FORWARD(slant_range)
    VKS_FORWARD(pixel_azimuth) VKS_FORWARD(pixel_elevation) VKS_FORWARD(pattern_power) VKS_FORWARD(echo_energy)
    VKS_FORWARD(range_bin_coord) VKS_FORWARD(footprint_edge_offset) VKS_FORWARD(footprint_lo)
    VKS_FORWARD(footprint_hi) VKS_FORWARD(footprint_share) VKS_FORWARD(footprint_log_slope) VKS_FORWARD(sinhc_of)
    VKS_FORWARD(incidence_cos) VKS_FORWARD(face_normal_sonar_x) VKS_FORWARD(face_normal_sonar_y)
    VKS_FORWARD(face_normal_sonar_z) VKS_FORWARD(specular_facet) VKS_FORWARD(scatter_factor)
    VKS_FORWARD(resample_share)
#undef VKS_FORWARD
};
// clang-format on

} // namespace vksonar
