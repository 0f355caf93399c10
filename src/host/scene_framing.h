// Seeing one's own scene (the CLI's `--pose frame` and its unit-mistake warning; Python's
// Renderer.frame_pose() and its warning): scene_framing.cpp.
#pragma once

#include <string>

#include "vksonar/config.h"
#include "vksonar/scene.h"

namespace vksonar::host {

// --pose frame: the sonar looks along +x at the scene's bounding box's centre from the distance where
// the box's width fills the horizontal field of view (not nearer than range_min, not farther than the
// middle of the range window, so a box larger than the window shows its middle), pitched down by half
// the vertical beamwidth (as sonars are usually mounted) and raised so that this pitch hits the centre.
// False for an empty scene (nothing to frame). `whole_box_in_window`: the box's far corner lies inside
// range_max.
bool frame_pose(const Scene& scene, const SonarConfig& config, Pose& pose, bool& whole_box_in_window);

// A scene far out of proportion with the range window is most often in other units: the warning line
// naming the likely mistake and how to fix it (`fix_before` + scale + `fix_after`, e.g. "--set
// scene.scale=" "0.001" ""), or empty when the scene's size looks plausible.
std::string unit_mistake_warning(const Scene& scene, const SonarConfig& config, const std::string& scene_name,
                                 const std::string& fix_before, const std::string& fix_after);

} // namespace vksonar::host
