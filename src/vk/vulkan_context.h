// The Vulkan objects behind a vksonar::Context. The plain handles are borrowed views, used by every
// call site; what vksonar created itself is also held by an owner (vk::OwnedRoot below), destroyed
// with the context. A host engine's instance and device (Context::adopt) have no owner here.
#pragma once

#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>
#include <type_traits>

#include <vulkan/vulkan_core.h>

#include "core/access.h"
#include "vk/functions.h"

namespace vksonar {
namespace vk {

// Owner of an object above the device level that vksonar created: the instance, the device or the
// debug messenger (handles.h's Owned<> is for what a device makes). It keeps the destroy function
// and the allocation callbacks the object was made with; a null destroy function (a dispatch table
// that failed to load before it) destroys nothing. Never moves: it lives in a VulkanContext, which
// lives on the heap. `Parent` is the instance a messenger belongs to; void for the others.
template <class Handle, class Destroy, class Parent = void> class OwnedRoot {
public:
    OwnedRoot() = default;
    ~OwnedRoot() {
        if (handle_ == VK_NULL_HANDLE || destroy_ == nullptr) return;
        if constexpr (std::is_void_v<Parent>) {
            destroy_(handle_, allocator_);
        } else {
            destroy_(parent_, handle_, allocator_);
        }
    }
    OwnedRoot(const OwnedRoot&) = delete;
    OwnedRoot& operator=(const OwnedRoot&) = delete;

    // Takes `handle` (the owner must be empty); a messenger also takes the instance it belongs to.
    void take(Handle handle, const VkAllocationCallbacks* allocator, Destroy destroy) {
        static_assert(std::is_void_v<Parent>, "this owner's destroy function needs the parent");
        handle_ = handle;
        allocator_ = allocator;
        destroy_ = destroy;
    }
    template <class P> void take(P parent, Handle handle, const VkAllocationCallbacks* allocator, Destroy destroy) {
        static_assert(std::is_same_v<P, Parent>, "the parent is the instance the messenger belongs to");
        parent_ = parent;
        handle_ = handle;
        allocator_ = allocator;
        destroy_ = destroy;
    }
    Handle get() const { return handle_; }
    explicit operator bool() const { return handle_ != VK_NULL_HANDLE; }

private:
    struct NoParent {};
    std::conditional_t<std::is_void_v<Parent>, NoParent, Parent> parent_{};
    Handle handle_ = VK_NULL_HANDLE;
    const VkAllocationCallbacks* allocator_ = nullptr;
    Destroy destroy_ = nullptr;
};

using OwnedInstance = OwnedRoot<VkInstance, PFN_vkDestroyInstance>;
using OwnedDevice = OwnedRoot<VkDevice, PFN_vkDestroyDevice>;
using OwnedDebugMessenger = OwnedRoot<VkDebugUtilsMessengerEXT, PFN_vkDestroyDebugUtilsMessengerEXT, VkInstance>;

} // namespace vk

struct VulkanContext {
    // Every Vulkan function vksonar calls, loaded once by create / adopt (vk/functions.h). Only read
    // after that. Call sites spell it context.fn.vkCmdDispatch(...).
    vk::Functions fn;
    VkInstance instance = VK_NULL_HANDLE; // borrowed view (owned_instance holds it when vksonar made it)
    VkPhysicalDevice physical_device = VK_NULL_HANDLE;
    VkDevice device = VK_NULL_HANDLE; // borrowed view (owned_device holds it when vksonar made it)
    std::uint32_t queue_family = 0;   // supports graphics and compute
    VkQueue queue = VK_NULL_HANDLE;
    bool graphics = true; // queue_family supports graphics (the depth pass); adopted compute-only queues do not
    // Passed to every vkCreate*/vkDestroy*/vkAllocateMemory/vkFreeMemory vksonar makes (null: the
    // implementation's). Borrowed: HostVulkan::allocator or ContextOptions::allocator; outlives the context.
    const VkAllocationCallbacks* allocator = nullptr;

    bool validation = false; // the validation layer is enabled
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
    ~VulkanContext(); // waits for an owned device to go idle; the owners below then destroy

    // What vksonar created, destroyed with the context in the reverse order of these lines: the
    // device, then the messenger, then the instance. All empty for Context::adopt (a host engine's
    // instance and device are borrowed through the plain handles above); the messenger is always
    // vksonar's own, and only exists with the validation layer.
    vk::OwnedInstance owned_instance;
    vk::OwnedDebugMessenger debug_messenger;
    vk::OwnedDevice owned_device;
};

} // namespace vksonar
