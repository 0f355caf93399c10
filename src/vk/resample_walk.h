// Whether resample.comp may walk each run of beams' columns once instead of gathering every beam's
// span on its own (its kWalk variant): the host proves, from the plan's tables, that both ways add
// the same terms in the same order, so the two give the same bits.
#pragma once
#include <cstdint>

#include "core/plan.h"

namespace vksonar::vk {

// True when, for every run of `beams_per_run` beams (as resample.comp's workgroups take them), the
// walk visits for each beam the columns of its span [beam_column_begin, beam_column_end), in order,
// with the weights of docs/pipeline.md §4. False on a full circle (beams 0 and beams-1 gather from
// every column) and wherever a span holds a column that gives the beam nothing.
[[nodiscard]] bool resample_can_walk(const Plan& plan, std::uint32_t beams_per_run);

} // namespace vksonar::vk
