// Context::adopt: wraps a host engine's instance, device and queue. Everything here is borrowed:
// owns_instance / owns_device stay false, so ~VulkanContext destroys nothing of the host's.
#include <cstdio>
#include <string>
#include <vector>

#include "vk/vulkan_context.h"
#include "vksonar/context.h"

namespace vksonar {
namespace {

std::string version_text(std::uint32_t version) {
    return std::to_string(VK_API_VERSION_MAJOR(version)) + "." + std::to_string(VK_API_VERSION_MINOR(version));
}

Error unsupported(const std::string& what) {
    return make_error(ErrorCode::unsupported, "Context::adopt: " + what);
}

// Every device-level function vksonar calls (src/vk), resolved through the host's vkGetDeviceProcAddr.
constexpr const char* kDeviceFunctions[] = {
    "vkAllocateCommandBuffers",
    "vkAllocateDescriptorSets",
    "vkAllocateMemory",
    "vkBeginCommandBuffer",
    "vkBindBufferMemory",
    "vkBindImageMemory",
    "vkCmdBeginRenderPass",
    "vkCmdBindDescriptorSets",
    "vkCmdBindIndexBuffer",
    "vkCmdBindPipeline",
    "vkCmdBindVertexBuffers",
    "vkCmdCopyBuffer",
    "vkCmdCopyImageToBuffer",
    "vkCmdDispatch",
    "vkCmdDrawIndexed",
    "vkCmdEndRenderPass",
    "vkCmdFillBuffer",
    "vkCmdPipelineBarrier",
    "vkCmdPushConstants",
    "vkCmdResetQueryPool",
    "vkCmdSetEvent",
    "vkCmdSetScissor",
    "vkCmdSetViewport",
    "vkCmdWriteTimestamp",
    "vkCreateBuffer",
    "vkCreateCommandPool",
    "vkCreateComputePipelines",
    "vkCreateDescriptorPool",
    "vkCreateDescriptorSetLayout",
    "vkCreateEvent",
    "vkCreateFence",
    "vkCreateFramebuffer",
    "vkCreateGraphicsPipelines",
    "vkCreateImage",
    "vkCreateImageView",
    "vkCreatePipelineLayout",
    "vkCreateQueryPool",
    "vkCreateRenderPass",
    "vkCreateShaderModule",
    "vkDestroyBuffer",
    "vkDestroyCommandPool",
    "vkDestroyDescriptorPool",
    "vkDestroyDescriptorSetLayout",
    "vkDestroyEvent",
    "vkDestroyFence",
    "vkDestroyFramebuffer",
    "vkDestroyImage",
    "vkDestroyImageView",
    "vkDestroyPipeline",
    "vkDestroyPipelineLayout",
    "vkDestroyQueryPool",
    "vkDestroyRenderPass",
    "vkDestroyShaderModule",
    "vkEndCommandBuffer",
    "vkFreeMemory",
    "vkGetBufferMemoryRequirements",
    "vkGetEventStatus",
    "vkGetImageMemoryRequirements",
    "vkGetQueryPoolResults",
    "vkMapMemory",
    "vkQueueSubmit",
    "vkResetCommandPool",
    "vkResetEvent",
    "vkResetFences",
    "vkUpdateDescriptorSets",
    "vkWaitForFences",
};

// VulkanFunctions' checks (context.h): set, from the loader vksonar links, resolving what vksonar calls.
Result<void> check_functions(const VulkanFunctions& functions, VkDevice device) {
    if (functions.vkGetInstanceProcAddr == nullptr || functions.vkGetDeviceProcAddr == nullptr) {
        return make_error(
            ErrorCode::invalid_argument,
            std::string("Context::adopt: HostVulkan.functions->") +
                (functions.vkGetInstanceProcAddr == nullptr ? "vkGetInstanceProcAddr" : "vkGetDeviceProcAddr") +
                " is null (both are required when functions is given)");
    }
    // A global command: no dispatchable handle, so asking both loaders is safe whichever the host has.
    if (functions.vkGetInstanceProcAddr(VK_NULL_HANDLE, "vkCreateInstance") !=
        vkGetInstanceProcAddr(VK_NULL_HANDLE, "vkCreateInstance")) {
        return unsupported("HostVulkan.functions do not come from the Vulkan loader vksonar links (libvulkan): "
                           "vksonar calls the loader's exported functions, so the host must load Vulkan through "
                           "the same loader");
    }
    for (const char* name : kDeviceFunctions) {
        if (functions.vkGetDeviceProcAddr(device, name) == nullptr) {
            return unsupported(std::string("the host's vkGetDeviceProcAddr does not resolve ") + name +
                               " on HostVulkan.device");
        }
    }
    return {};
}

} // namespace

Result<AdoptedContext> Context::adopt(const HostVulkan& host) {
    if (host.instance == VK_NULL_HANDLE || host.physical_device == VK_NULL_HANDLE || host.device == VK_NULL_HANDLE ||
        host.queue == VK_NULL_HANDLE) {
        return make_error(ErrorCode::invalid_argument,
                          "Context::adopt: HostVulkan.instance, physical_device, device and queue must all be set");
    }
    if ((host.lock_queue == nullptr) != (host.unlock_queue == nullptr)) {
        return make_error(ErrorCode::invalid_argument,
                          "Context::adopt: HostVulkan.lock_queue and unlock_queue must be given together");
    }
    if (host.functions != nullptr) {
        if (auto checked = check_functions(*host.functions, host.device); !checked) return checked.error();
    }
    // The shaders are SPIR-V 1.3 (--target-env vulkan1.1), which a 1.0 instance or device may not accept.
    if (host.instance_api_version != 0 && host.instance_api_version < VK_API_VERSION_1_1) {
        return unsupported("the instance was created for Vulkan " + version_text(host.instance_api_version) +
                           " (VkApplicationInfo.apiVersion); vksonar needs Vulkan 1.1");
    }
    auto vulkan = std::make_unique<VulkanContext>();
    VulkanContext& context = *vulkan;
    vkGetPhysicalDeviceProperties(host.physical_device, &context.properties);
    if (context.properties.apiVersion < VK_API_VERSION_1_1) {
        return unsupported(std::string("device ") + context.properties.deviceName + " supports Vulkan " +
                           version_text(context.properties.apiVersion) + "; vksonar needs Vulkan 1.1");
    }
    std::uint32_t family_count = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(host.physical_device, &family_count, nullptr);
    std::vector<VkQueueFamilyProperties> families(family_count);
    vkGetPhysicalDeviceQueueFamilyProperties(host.physical_device, &family_count, families.data());
    if (host.queue_family >= family_count) {
        return make_error(ErrorCode::invalid_argument,
                          "Context::adopt: HostVulkan.queue_family = " + std::to_string(host.queue_family) +
                              " but the device has " + std::to_string(family_count) + " queue families");
    }
    const VkQueueFlags flags = families[host.queue_family].queueFlags;
    if ((flags & VK_QUEUE_COMPUTE_BIT) == 0) {
        return unsupported("queue family " + std::to_string(host.queue_family) +
                           " has no VK_QUEUE_COMPUTE_BIT; vksonar's stages are compute shaders");
    }

    context.instance = host.instance;
    context.physical_device = host.physical_device;
    context.device = host.device;
    context.queue_family = host.queue_family;
    context.queue = host.queue;
    context.owns_instance = false;
    context.owns_device = false;
    context.graphics = (flags & VK_QUEUE_GRAPHICS_BIT) != 0;
    context.timestamp_valid_bits = families[host.queue_family].timestampValidBits;
    context.lock_queue = host.lock_queue;
    context.unlock_queue = host.unlock_queue;
    context.queue_lock_user = host.queue_lock_user;
    context.allocator = host.allocator;
    char driver[16];
    std::snprintf(driver, sizeof(driver), "%x", context.properties.driverVersion);
    context.description = std::string(context.properties.deviceName) + " (Vulkan " +
                          version_text(context.properties.apiVersion) + ", driver 0x" + driver + ", adopted)";

    AdoptedContext adopted;
    adopted.vk_ = std::move(vulkan);
    return adopted;
}

} // namespace vksonar
