// The pipeline's stages, in order: the one list that the Vulkan backend (src/vk/vulkan_frame.cpp),
// the host-depth path (src/vk/host_depth.cpp) and the CPU backend (src/stages/cpu_backend.cpp) walk.
// A backend maps each StageId to its own implementation of the stage; the order, the names that
// frames and benchmarks report and the rule for when a stage runs live only here.
//
// Where each stage is, by name (docs/pipeline.md has the math):
//   depth     shaders/depth*.vert/.frag (host depth image: import_depth.comp)  src/stages/cpu_depth.cpp
//   normals   shaders/normals.comp                                              src/stages/cpu_normals.cpp
//   echo      shaders/echo.comp                                                 src/stages/cpu_echo.cpp
//   beamform  shaders/profile.comp, resample.comp, far_sidelobe.comp,           src/stages/cpu_beamform.cpp
//             sidelobe.comp
// The per-pixel kernels of normals, echo and the range kernel of beamform are written once, in
// shaders/sonar_kernels.h, for both backends. The host stages (noise, gain, images) follow in
// src/host/ and are shared by both backends.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "core/plan.h"

namespace vksonar {

enum class StageId : std::uint8_t { depth, normals, echo, beamform };

struct StageInfo {
    StageId id;
    const char* name;            // Frame::stages_run, Frame::times, `vksonar bench` columns
    const char* host_depth_name; // the name with a host engine's depth image (HostDepthRenderer)
    bool (*runs)(const Plan&);   // whether the plan needs it (effects on demand)
};

inline constexpr std::array<StageInfo, 4> kStageTable{{
    {StageId::depth, "depth", "import", [](const Plan&) { return true; }},
    // only the incidence effect reads normals
    {StageId::normals, "normals", "normals", [](const Plan& plan) { return plan.effects.incidence; }},
    {StageId::echo, "echo", "echo", [](const Plan&) { return true; }},
    {StageId::beamform, "beamform", "beamform", [](const Plan&) { return true; }},
}};
inline constexpr std::size_t kStageCount = kStageTable.size();

constexpr bool stage_table_in_order() {
    for (std::size_t i = 0; i < kStageCount; ++i)
        if (static_cast<std::size_t>(kStageTable[i].id) != i) return false;
    return true;
}
static_assert(stage_table_in_order(), "kStageTable[i].id == i: backends index their per-stage arrays by StageId");

} // namespace vksonar
