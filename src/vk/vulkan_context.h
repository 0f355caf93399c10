// The Vulkan objects behind a vksonar::Context. Owned objects are destroyed with it; borrowed ones
// (owns_instance / owns_device false: a host engine's device) never are.
#pragma once

#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>

#include <vulkan/vulkan_core.h>

#include "core/access.h"
#include "vk/functions.h"

namespace vksonar {

struct VulkanContext {
    // Every Vulkan function vksonar calls, loaded once by create / adopt (vk/functions.h). Only read
    // after that. Call sites spell it context.fn.vkCmdDispatch(...).
    vk::Functions fn;
    VkInstance instance = VK_NULL_HANDLE;
    VkPhysicalDevice physical_device = VK_NULL_HANDLE;
    VkDevice device = VK_NULL_HANDLE;
    std::uint32_t queue_family = 0; // supports graphics and compute
    VkQueue queue = VK_NULL_HANDLE;
    bool owns_instance = false;
    bool owns_device = false;
    bool graphics = true; // queue_family supports graphics (the depth pass); adopted compute-only queues do not
    // Passed to every vkCreate*/vkDestroy*/vkAllocateMemory/vkFreeMemory vksonar makes (null: the
    // implementation's). Borrowed: HostVulkan::allocator or ContextOptions::allocator; outlives the context.
    const VkAllocationCallbacks* allocator = nullptr;

    VkDebugUtilsMessengerEXT debug_messenger = VK_NULL_HANDLE; // always owned (created by vksonar)
    bool validation = false;                                   // the validation layer is enabled
    // Validation messages of severity warning or error (each is also printed to stderr as one line).
    std::atomic<std::uint32_t> validation_messages{0};

    std::mutex queue_mutex; // serializes vkQueueSubmit on `queue`
    // Adopted devices: the host's queue lock (HostVulkan::lock_queue), taken instead of queue_mutex so
    // vksonar's submissions are serialized with the host's own.
    void (*lock_queue)(void* user) = nullptr;
    void (*unlock_queue)(void* user) = nullptr;
    void* queue_lock_user = nullptr;

    VkPhysicalDeviceProperties properties{};
    std::uint32_t timestamp_valid_bits = 0; // of queue_family; 0: no timestamp queries
    std::string description;                // "name (driver info, Vulkan x.y.z)"

    VulkanContext() = default;
    VulkanContext(const VulkanContext&) = delete;
    VulkanContext& operator=(const VulkanContext&) = delete;
    ~VulkanContext(); // destroys only what it owns: device, messenger, instance (in that order)
};

} // namespace vksonar
