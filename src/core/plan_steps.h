// What make_plan's steps (plan.cpp) share with the two files that hold some of them: plan_grid.cpp (the
// depth pass's pixel grid, its views: the slices and the vertical side lobes' tier views, and the cone
// table) and plan_beams.cpp (which beams each profile column feeds, and the side-lobe kernel: its near
// taps and far cells). Each step reads the config from p.config and what the steps before it set;
// make_plan takes them in order. Internal to src/core.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>

#include "core/plan.h"

namespace vksonar::plan_steps {

// The public enums and the shaders' constants (sonar_shared.h) are the same numbers, checked here:
// adding a model or a shape to one without the other fails to compile.
constexpr std::uint32_t shader_id(BeamPattern shape) {
    return static_cast<std::uint32_t>(shape);
}
static_assert(shader_id(BeamPattern::box) == shared::kPatternBox &&
              shader_id(BeamPattern::sinc) == shared::kPatternSinc &&
              shader_id(BeamPattern::hann) == shared::kPatternHann &&
              shader_id(BeamPattern::gaussian) == shared::kPatternGaussian &&
              shader_id(BeamPattern::chebyshev) == shared::kPatternChebyshev);
constexpr std::uint32_t shader_id(AcousticMaterial::Model model) {
    return static_cast<std::uint32_t>(model);
}
static_assert(shader_id(AcousticMaterial::Model::lambert) == shared::kScatterLambert &&
              shader_id(AcousticMaterial::Model::constant) == shared::kScatterConstant &&
              shader_id(AcousticMaterial::Model::rough) == shared::kScatterRough);
constexpr std::uint32_t shader_id(RangeKernel kernel) {
    return static_cast<std::uint32_t>(kernel);
}
static_assert(shader_id(RangeKernel::nearest) == shared::kRangeKernelNearest &&
              shader_id(RangeKernel::tent) == shared::kRangeKernelTent &&
              shader_id(RangeKernel::footprint) == shared::kRangeKernelFootprint);
constexpr std::uint32_t shader_id(NormalMethod method) {
    return static_cast<std::uint32_t>(method);
}
static_assert(shader_id(NormalMethod::sobel3) == shared::kNormalsSobel3 &&
              shader_id(NormalMethod::sobel5) == shared::kNormalsSobel5 &&
              shader_id(NormalMethod::geometric) == shared::kNormalsGeometric);

inline std::string fmt(double v) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%g", v);
    return buf;
}

// plan_grid.cpp
// The pixel columns that resolve an angle `width_rad` at pixels_per_beam per resolved angle.
double columns_for(const Plan& p, double width_rad);
Result<void> plan_pixel_grid(Plan& p);
Result<void> plan_tier_views(Plan& p);
void use_host_grid(Plan& p, const HostPixelGrid& grid);
void plan_profile_columns(Plan& p);
void plan_cone_table(Plan& p);

// plan_beams.cpp
// The side-lobe kernel's reach (an angle from the beam's axis) in the unit the beams are separated in.
double sidelobe_reach(const Plan& p, double reach);
// A separation between two directions as the patterns take it (in place): on a full circle into [-pi, pi];
// false where a planar fan's baffled aperture hears nothing (90 deg or more off its axis).
bool separation_in_front(const Plan& p, double& sep);
// The angle a separation stands for (a line array's sine's arcsine), where box and gaussian patterns are read.
double separation_angle(const Plan& p, double sep);
// An aperture pattern's (sinc, hann, chebyshev) signed amplitude at a separation in front: its argument the
// separation (line array) or its sine (planar). The power pattern is its square; the grain filters with it.
double aperture_amplitude(const Plan& p, double sep);
void plan_column_tables(Plan& p, double exclude_beyond_rad);
Result<void> plan_sidelobe_kernel(Plan& p, std::uint32_t half_taps, double reach, bool far_sidelobes);

} // namespace vksonar::plan_steps
