// The Vulkan implementation of the stages (depth pass + compute), same interface as the CPU one.
#pragma once

#include <memory>

#include "core/plan.h"
#include "scene/scene_data.h"
#include "stages/stage_backend.h"
#include "vksonar/renderer.h"

namespace vksonar {

struct VulkanContext;

namespace vk {
// Creates every pipeline, buffer and image for the plan once, and uploads the scene.
// `options`: the Vulkan paths (tables, resample, stage_timing); the rest is not read here.
[[nodiscard]] Result<std::unique_ptr<StageBackend>>
make_backend(VulkanContext& context, const Plan& plan, const SceneData& scene, const RendererOptions& options = {});
} // namespace vk
} // namespace vksonar
