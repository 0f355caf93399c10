// Context::adopt: wraps a host engine's instance, device and queue. Everything here is borrowed:
// VulkanContext's owners stay empty, so ~VulkanContext destroys nothing of the host's.
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

// The dispatch table (vk/functions.h) from the host's getters if it gave HostVulkan::functions, else
// from the loader vksonar links; either way every function vksonar calls on the host's instance and
// device is resolved here, before any call, and a missing one is named.
Result<void> load_functions(const HostVulkan& host, vk::Functions& fn) {
    std::string whose = "Context::adopt: the Vulkan loader's ";
    if (host.functions != nullptr) {
        const VulkanFunctions& functions = *host.functions;
        if (functions.vkGetInstanceProcAddr == nullptr || functions.vkGetDeviceProcAddr == nullptr) {
            return make_error(
                ErrorCode::invalid_argument,
                std::string("Context::adopt: HostVulkan.functions->") +
                    (functions.vkGetInstanceProcAddr == nullptr ? "vkGetInstanceProcAddr" : "vkGetDeviceProcAddr") +
                    " is null (both are required when functions is given)");
        }
        fn.vkGetInstanceProcAddr = functions.vkGetInstanceProcAddr;
        fn.vkGetDeviceProcAddr = functions.vkGetDeviceProcAddr;
        whose = "Context::adopt: HostVulkan.functions->";
    } else {
        fn.vkGetInstanceProcAddr = vkGetInstanceProcAddr; // the bootstrap (vk/functions.h)
    }
    if (auto loaded = vk::load_instance_functions(fn, host.instance, false, whose); !loaded) return loaded;
    return vk::load_device_functions(fn, host.device, false, whose);
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
    auto vulkan = std::make_unique<VulkanContext>();
    VulkanContext& context = *vulkan;
    if (auto loaded = load_functions(host, context.fn); !loaded) return loaded.error();
    // The shaders are SPIR-V 1.3 (--target-env vulkan1.1), which a 1.0 instance or device may not accept.
    if (host.instance_api_version != 0 && host.instance_api_version < VK_API_VERSION_1_1) {
        return unsupported("the instance was created for Vulkan " + version_text(host.instance_api_version) +
                           " (VkApplicationInfo.apiVersion); vksonar needs Vulkan 1.1");
    }
    const vk::Functions& fn = context.fn;
    fn.vkGetPhysicalDeviceProperties(host.physical_device, &context.properties);
    if (context.properties.apiVersion < VK_API_VERSION_1_1) {
        return unsupported(std::string("device ") + context.properties.deviceName + " supports Vulkan " +
                           version_text(context.properties.apiVersion) + "; vksonar needs Vulkan 1.1");
    }
    std::uint32_t family_count = 0;
    fn.vkGetPhysicalDeviceQueueFamilyProperties(host.physical_device, &family_count, nullptr);
    std::vector<VkQueueFamilyProperties> families(family_count);
    fn.vkGetPhysicalDeviceQueueFamilyProperties(host.physical_device, &family_count, families.data());
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
