// C++ side of shaders/sonar_math.h and shaders/sonar_kernels.h: the same formulas and per-pixel
// kernels in float and double, GLM standing in for GLSL's vector types.
#pragma once

#include <cmath>
#include <cstdint>

#include <glm/geometric.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>

#include "sonar_shared.h"

namespace vksonar {

#define VKS_ATAN2 std::atan2

// Only the functions GLSL and <cmath> name alike are brought in: GLM's scalar min/max/abs would be
// ambiguous beside std's.
namespace math_f32 {
using namespace shared;
using glm::cross, glm::dot, glm::length;
using std::abs, std::asin, std::atan, std::cos, std::cosh, std::exp, std::floor, std::isnan, std::log, std::max,
    std::min, std::sin, std::sqrt;
using vec2 = glm::vec2;
using vec3 = glm::vec3;
using vec4 = glm::vec4;
#define REAL float
#include "sonar_math.h"
// the kernels call the formulas: after them
#include "sonar_kernels.h"
#undef REAL
} // namespace math_f32

namespace math_f64 {
using namespace shared;
using glm::cross, glm::dot, glm::length;
using std::abs, std::asin, std::atan, std::cos, std::cosh, std::exp, std::floor, std::isnan, std::log, std::max,
    std::min, std::sin, std::sqrt;
using vec2 = glm::dvec2;
using vec3 = glm::dvec3;
using vec4 = glm::dvec4;
#define REAL double
#include "sonar_math.h"
// the kernels call the formulas: after them
#include "sonar_kernels.h"
#undef REAL
} // namespace math_f64

#undef VKS_ATAN2

// Math<Real> stands for the namespace of the working precision in templated CPU code:
// Math<Real>::fn(...) calls math_f32::fn or math_f64::fn; Math<Real>::Sample etc. are its types.
// The table below reads best as laid out by hand. The forwarders are always inlined: a call through one
// must cost what a call of the kernel does (GCC otherwise kept range_spread out of line: +6 % beamform).
// clang-format off
#define VKS_MATH_TABLE(ns)                                                                                           \
    using vec2 = ns::vec2; using vec3 = ns::vec3; using vec4 = ns::vec4;                                             \
    using Sample = ns::Sample; using Column3 = ns::Column3; using Column5 = ns::Column5;                              \
    using EchoConstants = ns::EchoConstants; using EchoTerms = ns::EchoTerms; using RangeSpread = ns::RangeSpread;      \
    using PixelView = ns::PixelView;                                                                                 \
    VKS_FORWARD(ns, pixel_coord) VKS_FORWARD(ns, pixel_solid_angle) VKS_FORWARD(ns, view_z_from_depth)               \
    VKS_FORWARD(ns, slant_range) VKS_FORWARD(ns, pixel_azimuth) VKS_FORWARD(ns, pixel_elevation)                     \
    VKS_FORWARD(ns, pattern_power) VKS_FORWARD(ns, echo_energy) VKS_FORWARD(ns, range_bin_coord)                     \
    VKS_FORWARD(ns, footprint_edge_offset) VKS_FORWARD(ns, footprint_lo) VKS_FORWARD(ns, footprint_hi)               \
    VKS_FORWARD(ns, footprint_share) VKS_FORWARD(ns, footprint_log_slope) VKS_FORWARD(ns, sinhc_of)                  \
    VKS_FORWARD(ns, incidence_cos) VKS_FORWARD(ns, view_of_slice) VKS_FORWARD(ns, view_elevation_sin)                 \
    VKS_FORWARD(ns, in_view_wedge) VKS_FORWARD(ns, specular_facet) VKS_FORWARD(ns, scatter_factor)             \
    VKS_FORWARD(ns, resample_share) VKS_FORWARD(ns, pixel_ray) VKS_FORWARD(ns, no_sample)                            \
    VKS_FORWARD(ns, sample_at) VKS_FORWARD(ns, facing_normal) VKS_FORWARD(ns, oriented_normal)                       \
    VKS_FORWARD(ns, sobel3_normal) VKS_FORWARD(ns, sobel5_normal) VKS_FORWARD(ns, geometric_normal)                  \
    VKS_FORWARD(ns, material_index) VKS_FORWARD(ns, echo_of_pixel) VKS_FORWARD(ns, range_spread)       \
    VKS_FORWARD(ns, pixel_vertical_power) VKS_FORWARD(ns, depth_slant_range) VKS_FORWARD(ns, echo_at_range)     \
    VKS_FORWARD(ns, range_share) VKS_FORWARD(ns, array_axis_cosine) VKS_FORWARD(ns, cone_coord)                   \
    VKS_FORWARD(ns, cone_share) VKS_FORWARD(ns, cone_extent_low) VKS_FORWARD(ns, cone_extent_high) VKS_FORWARD(ns, cone_extent_share) VKS_FORWARD(ns, far_cell_share) VKS_FORWARD(ns, far_deposit_weight) VKS_FORWARD(ns, far_sidelobe_level) VKS_FORWARD(ns, far_scan_cell) \
    VKS_FORWARD(ns, ray_vertical_power) VKS_FORWARD(ns, element_power) VKS_FORWARD(ns, facet_echo) VKS_FORWARD(ns, subpixel_visible)
#define VKS_FORWARD(ns, fn) template <class... A> [[gnu::always_inline]] static inline decltype(auto) fn(A&&... a) { return ns::fn(static_cast<A&&>(a)...); }
template <class Real> struct Math;
template <> struct Math<float> { VKS_MATH_TABLE(math_f32) };
template <> struct Math<double> { VKS_MATH_TABLE(math_f64) };
#undef VKS_FORWARD
#undef VKS_MATH_TABLE
// clang-format on

} // namespace vksonar
