// The plan of a renderer that consumes a host engine's depth image (HostDepthRenderer::create):
// the sonar's beams, bins, patterns and effects as make_plan derives them, on the host image's pixel
// grid (one slice, the host camera's pinhole projection) instead of vksonar's own sliced grid.
#pragma once

#include "core/plan.h"
#include "vksonar/host_depth.h"

namespace vksonar {

// Fails with a message naming the HostDepthDesc field at fault, or with ErrorCode::unsupported if the
// host image does not cover the sonar (beam centres outside its horizontal fov, vertical -3 dB
// beamwidth outside its vertical fov, off-centre principal point).
[[nodiscard]] Result<Plan> make_host_depth_plan(const SonarConfig& config, const HostDepthDesc& desc);

} // namespace vksonar
