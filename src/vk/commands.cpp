#include "vk/commands.h"

#include <cstdint>
#include <mutex>

#include "vk/handles.h"
#include "vk/vk_error.h"
#include "vk/vulkan_context.h"

namespace vksonar::vk {

VkResult queue_submit(VulkanContext& context, const VkSubmitInfo& submit, VkFence fence) {
    if (context.lock_queue != nullptr && context.unlock_queue != nullptr) {
        context.lock_queue(context.queue_lock_user);
        VkResult result = context.fn.vkQueueSubmit(context.queue, 1, &submit, fence);
        context.unlock_queue(context.queue_lock_user);
        return result;
    }
    std::lock_guard<std::mutex> lock(context.queue_mutex);
    return context.fn.vkQueueSubmit(context.queue, 1, &submit, fence);
}

Result<void> submit_once(VulkanContext& context, const std::function<void(VkCommandBuffer)>& record) {
    VkCommandPoolCreateInfo pool_info{};
    pool_info.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
    pool_info.flags = VK_COMMAND_POOL_CREATE_TRANSIENT_BIT;
    pool_info.queueFamilyIndex = context.queue_family;
    VkCommandPool pool_handle = VK_NULL_HANDLE;
    VKS_VK_TRY(context.fn.vkCreateCommandPool(context.device, &pool_info, context.allocator, &pool_handle));
    OwnedCommandPool pool(context, pool_handle);

    VkCommandBufferAllocateInfo allocate_info{};
    allocate_info.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO;
    allocate_info.commandPool = pool.get();
    allocate_info.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    allocate_info.commandBufferCount = 1;
    VkCommandBuffer commands = VK_NULL_HANDLE;
    VKS_VK_TRY(context.fn.vkAllocateCommandBuffers(context.device, &allocate_info, &commands));

    VkCommandBufferBeginInfo begin{};
    begin.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    VKS_VK_TRY(context.fn.vkBeginCommandBuffer(commands, &begin));
    record(commands);
    VkMemoryBarrier visible{};
    visible.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
    visible.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    visible.dstAccessMask = VK_ACCESS_MEMORY_READ_BIT | VK_ACCESS_MEMORY_WRITE_BIT;
    context.fn.vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, 0, 1,
                                    &visible, 0, nullptr, 0, nullptr);
    VKS_VK_TRY(context.fn.vkEndCommandBuffer(commands));

    VkFenceCreateInfo fence_info{};
    fence_info.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO;
    VkFence fence_handle = VK_NULL_HANDLE;
    VKS_VK_TRY(context.fn.vkCreateFence(context.device, &fence_info, context.allocator, &fence_handle));
    OwnedFence fence(context, fence_handle);

    VkSubmitInfo submit{};
    submit.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    submit.commandBufferCount = 1;
    submit.pCommandBuffers = &commands;
    VKS_VK_TRY(queue_submit(context, submit, fence.get()));
    VKS_VK_TRY(context.fn.vkWaitForFences(context.device, 1, &fence_handle, VK_TRUE, UINT64_MAX));
    return {};
}

VkBufferMemoryBarrier buffer_barrier(VkBuffer buffer, VkAccessFlags src_access, VkAccessFlags dst_access) {
    VkBufferMemoryBarrier barrier{};
    barrier.sType = VK_STRUCTURE_TYPE_BUFFER_MEMORY_BARRIER;
    barrier.srcAccessMask = src_access;
    barrier.dstAccessMask = dst_access;
    barrier.srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    barrier.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    barrier.buffer = buffer;
    barrier.offset = 0;
    barrier.size = VK_WHOLE_SIZE;
    return barrier;
}

void pipeline_barrier(const VulkanContext& context, VkCommandBuffer commands, VkPipelineStageFlags src_stages,
                      VkPipelineStageFlags dst_stages, std::uint32_t buffer_barrier_count,
                      const VkBufferMemoryBarrier* buffer_barriers) {
    context.fn.vkCmdPipelineBarrier(commands, src_stages, dst_stages, 0, 0, nullptr, buffer_barrier_count,
                                    buffer_barriers, 0, nullptr);
}

} // namespace vksonar::vk
