// The Vulkan implementation of the stages (depth pass + compute), same interface as the CPU one.
#pragma once

#include <memory>

#include "core/plan.h"
#include "scene/scene_data.h"
#include "stages/stage_backend.h"

namespace vksonar {

struct VulkanContext;

namespace vk {
// Creates every pipeline, buffer and image for the plan once, and uploads the scene.
[[nodiscard]] Result<std::unique_ptr<StageBackend>> make_backend(VulkanContext& context, const Plan& plan,
                                                                 const SceneData& scene);
} // namespace vk
} // namespace vksonar
