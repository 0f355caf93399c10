// Command-buffer helpers: one-off submissions (uploads at creation time) and barrier shorthands.
#pragma once

#include <functional>

#include <vulkan/vulkan_core.h>

#include "vksonar/result.h"

namespace vksonar {
struct VulkanContext;
}

namespace vksonar::vk {

// Records `record` into a temporary command buffer, submits it and waits. Creation time only.
// Ends with a barrier that makes transfer writes visible to every later command on the queue.
[[nodiscard]] Result<void> submit_once(VulkanContext& context, const std::function<void(VkCommandBuffer)>& record);

// Submits under the context's queue lock.
[[nodiscard]] VkResult queue_submit(VulkanContext& context, const VkSubmitInfo& submit, VkFence fence);

VkBufferMemoryBarrier buffer_barrier(VkBuffer buffer, VkAccessFlags src_access, VkAccessFlags dst_access);

void pipeline_barrier(const VulkanContext& context, VkCommandBuffer commands, VkPipelineStageFlags src_stages,
                      VkPipelineStageFlags dst_stages, std::uint32_t buffer_barrier_count,
                      const VkBufferMemoryBarrier* buffer_barriers);

} // namespace vksonar::vk
