// The dispatch table: every Vulkan function vksonar calls, as pointers loaded once per context
// (VulkanContext::fn), so that vksonar's calls go where the host's go (a host with its own loader,
// layers or volk) and device calls skip the loader's trampoline (loaded with vkGetDeviceProcAddr, as
// volk does). The names are listed once, below, by the level they are loaded at.
//
// The only function vksonar calls from the Vulkan loader it links is vkGetInstanceProcAddr: an own
// context (Context::create) and an adopted one without HostVulkan::functions load the table from it;
// an adopted one with functions loads it from the host's vkGetInstanceProcAddr / vkGetDeviceProcAddr.
#pragma once

#include <string>

#include <vulkan/vulkan_core.h>

#include "vksonar/result.h"

// Global functions (no instance), for creating an own instance only: null in an adopted context.
#define VKSONAR_VK_GLOBAL_FUNCTIONS(X)                                                                                 \
    X(vkCreateInstance)                                                                                                \
    X(vkEnumerateInstanceExtensionProperties)                                                                          \
    X(vkEnumerateInstanceLayerProperties)

// Instance functions every context calls.
#define VKSONAR_VK_INSTANCE_FUNCTIONS(X)                                                                               \
    X(vkGetPhysicalDeviceFormatProperties)                                                                             \
    X(vkGetPhysicalDeviceMemoryProperties)                                                                             \
    X(vkGetPhysicalDeviceProperties)                                                                                   \
    X(vkGetPhysicalDeviceQueueFamilyProperties)

// Instance functions of an own instance only (choosing and creating the device, destroying both):
// null in an adopted context.
#define VKSONAR_VK_OWN_INSTANCE_FUNCTIONS(X)                                                                           \
    X(vkCreateDevice)                                                                                                  \
    X(vkDestroyInstance)                                                                                               \
    X(vkEnumerateDeviceExtensionProperties)                                                                            \
    X(vkEnumeratePhysicalDevices)

// VK_EXT_debug_utils, loaded only where an own instance enabled it (validation); may stay null.
#define VKSONAR_VK_DEBUG_UTILS_FUNCTIONS(X)                                                                            \
    X(vkCreateDebugUtilsMessengerEXT)                                                                                  \
    X(vkDestroyDebugUtilsMessengerEXT)

// Device functions every context calls (the renderers' objects, recording, submission).
#define VKSONAR_VK_DEVICE_FUNCTIONS(X)                                                                                 \
    X(vkAllocateCommandBuffers)                                                                                        \
    X(vkAllocateDescriptorSets)                                                                                        \
    X(vkAllocateMemory)                                                                                                \
    X(vkBeginCommandBuffer)                                                                                            \
    X(vkBindBufferMemory)                                                                                              \
    X(vkBindImageMemory)                                                                                               \
    X(vkCmdBeginRenderPass)                                                                                            \
    X(vkCmdBindDescriptorSets)                                                                                         \
    X(vkCmdBindIndexBuffer)                                                                                            \
    X(vkCmdBindPipeline)                                                                                               \
    X(vkCmdBindVertexBuffers)                                                                                          \
    X(vkCmdCopyBuffer)                                                                                                 \
    X(vkCmdCopyImageToBuffer)                                                                                          \
    X(vkCmdDispatch)                                                                                                   \
    X(vkCmdDrawIndexed)                                                                                                \
    X(vkCmdEndRenderPass)                                                                                              \
    X(vkCmdFillBuffer)                                                                                                 \
    X(vkCmdPipelineBarrier)                                                                                            \
    X(vkCmdPushConstants)                                                                                              \
    X(vkCmdResetQueryPool)                                                                                             \
    X(vkCmdSetEvent)                                                                                                   \
    X(vkCmdSetScissor)                                                                                                 \
    X(vkCmdSetViewport)                                                                                                \
    X(vkCmdWriteTimestamp)                                                                                             \
    X(vkCreateBuffer)                                                                                                  \
    X(vkCreateCommandPool)                                                                                             \
    X(vkCreateComputePipelines)                                                                                        \
    X(vkCreateDescriptorPool)                                                                                          \
    X(vkCreateDescriptorSetLayout)                                                                                     \
    X(vkCreateEvent)                                                                                                   \
    X(vkCreateFence)                                                                                                   \
    X(vkCreateFramebuffer)                                                                                             \
    X(vkCreateGraphicsPipelines)                                                                                       \
    X(vkCreateImage)                                                                                                   \
    X(vkCreateImageView)                                                                                               \
    X(vkCreatePipelineLayout)                                                                                          \
    X(vkCreateQueryPool)                                                                                               \
    X(vkCreateRenderPass)                                                                                              \
    X(vkCreateShaderModule)                                                                                            \
    X(vkDestroyBuffer)                                                                                                 \
    X(vkDestroyCommandPool)                                                                                            \
    X(vkDestroyDescriptorPool)                                                                                         \
    X(vkDestroyDescriptorSetLayout)                                                                                    \
    X(vkDestroyEvent)                                                                                                  \
    X(vkDestroyFence)                                                                                                  \
    X(vkDestroyFramebuffer)                                                                                            \
    X(vkDestroyImage)                                                                                                  \
    X(vkDestroyImageView)                                                                                              \
    X(vkDestroyPipeline)                                                                                               \
    X(vkDestroyPipelineLayout)                                                                                         \
    X(vkDestroyQueryPool)                                                                                              \
    X(vkDestroyRenderPass)                                                                                             \
    X(vkDestroyShaderModule)                                                                                           \
    X(vkEndCommandBuffer)                                                                                              \
    X(vkFreeMemory)                                                                                                    \
    X(vkGetBufferMemoryRequirements)                                                                                   \
    X(vkGetEventStatus)                                                                                                \
    X(vkGetImageMemoryRequirements)                                                                                    \
    X(vkGetQueryPoolResults)                                                                                           \
    X(vkMapMemory)                                                                                                     \
    X(vkQueueSubmit)                                                                                                   \
    X(vkResetCommandPool)                                                                                              \
    X(vkResetEvent)                                                                                                    \
    X(vkResetFences)                                                                                                   \
    X(vkUpdateDescriptorSets)                                                                                          \
    X(vkWaitForFences)

// Device functions of an own device only (its queue, its teardown): null in an adopted context.
#define VKSONAR_VK_OWN_DEVICE_FUNCTIONS(X)                                                                             \
    X(vkDestroyDevice)                                                                                                 \
    X(vkDeviceWaitIdle)                                                                                                \
    X(vkGetDeviceQueue)

namespace vksonar::vk {

// A plain table of pointers, filled by the load_* functions below and then only read (so shared by
// every thread that uses the context). Each member has its function's name and PFN_ type.
struct Functions {
    // Where the others come from: the linked loader's or the host's (HostVulkan::functions).
    PFN_vkGetInstanceProcAddr vkGetInstanceProcAddr = nullptr;
    PFN_vkGetDeviceProcAddr vkGetDeviceProcAddr = nullptr;
#define VKSONAR_VK_MEMBER(name) PFN_##name name = nullptr;
    VKSONAR_VK_GLOBAL_FUNCTIONS(VKSONAR_VK_MEMBER)
    VKSONAR_VK_INSTANCE_FUNCTIONS(VKSONAR_VK_MEMBER)
    VKSONAR_VK_OWN_INSTANCE_FUNCTIONS(VKSONAR_VK_MEMBER)
    VKSONAR_VK_DEBUG_UTILS_FUNCTIONS(VKSONAR_VK_MEMBER)
    VKSONAR_VK_DEVICE_FUNCTIONS(VKSONAR_VK_MEMBER)
    VKSONAR_VK_OWN_DEVICE_FUNCTIONS(VKSONAR_VK_MEMBER)
#undef VKSONAR_VK_MEMBER
};

// Each loads its groups with fn.vkGetInstanceProcAddr (global, instance) or fn.vkGetDeviceProcAddr
// (device), which must be set; `own`: also the own-instance / own-device group, loaded first (so that
// what destroys the instance or device is there even if a later name fails). load_instance_functions
// also sets fn.vkGetDeviceProcAddr from vkGetInstanceProcAddr where it is still null (a host that
// gives its own keeps it). Each fails with ErrorCode::unsupported naming the first function the getter
// returns null for, in one line: "<whose>vkGetDeviceProcAddr returns null for <name>" (`whose`: e.g.
// "Context::create: the Vulkan loader's ").
[[nodiscard]] Result<void> load_global_functions(Functions& fn, const std::string& whose);
[[nodiscard]] Result<void> load_instance_functions(Functions& fn, VkInstance instance, bool own,
                                                   const std::string& whose);
[[nodiscard]] Result<void> load_device_functions(Functions& fn, VkDevice device, bool own, const std::string& whose);
// The debug-utils group, with fn.vkGetInstanceProcAddr: where the getter returns null the member stays
// null (the caller then goes without the messenger). Never fails.
void load_debug_utils_functions(Functions& fn, VkInstance instance);

} // namespace vksonar::vk
