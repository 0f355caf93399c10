// Context: the Vulkan instance/device vksonar runs on, owned (create) or borrowed (adopt).
// Thread-safety: a Context may be shared by renderers on different threads (one Renderer per thread);
// its own calls are const and safe to make concurrently. vksonar's queue submissions are serialized
// through the host's queue lock (HostVulkan::lock_queue) if given, else an internal mutex.
//
// Requirements (checked by create and adopt, with an error naming what is missing): Vulkan 1.1 (instance
// and device), a queue family with compute (and graphics for Renderer::render's depth pass; process()
// needs compute only), D32_SFLOAT depth + R32_UINT colour attachments for the depth pass. No device
// extension and no optional device feature is required.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include <vulkan/vulkan_core.h>

#include "vksonar/result.h"

namespace vksonar {

// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct ContextOptions {
    bool enable_validation = false; // VK_LAYER_KHRONOS_validation (skipped if the layer is not installed)
    int device_index = -1;          // -1: the first device with compute+graphics
    bool vulkan = true;             // false: a CPU-only context (no Vulkan at all)
    // Optional: the allocation callbacks for the instance, device and every object vksonar makes on
    // them (null: the implementation's). Borrowed: they must outlive the Context.
    const VkAllocationCallbacks* allocator = nullptr;
};

// A host engine's Vulkan objects, borrowed by Context::adopt. vksonar never destroys any of them; they
// must outlive the Context and every Renderer made from it. vksonar calls the Vulkan loader's exported
// functions (libvulkan), so the host must have created them through the same loader.
// Thread-safety: a plain value, read only during adopt; the callbacks and queue lock it names must be
// callable from every thread that uses the Context.
struct HostVulkan {
    VkInstance instance = VK_NULL_HANDLE;
    VkPhysicalDevice physical_device = VK_NULL_HANDLE;
    VkDevice device = VK_NULL_HANDLE;
    std::uint32_t queue_family = 0; // the family `queue` belongs to
    VkQueue queue = VK_NULL_HANDLE; // vksonar submits here (process, render; never in record)
    // The apiVersion the host gave VkApplicationInfo (0: unknown, then only the device's is checked).
    std::uint32_t instance_api_version = 0;
    // Optional queue lock: the host's queue is externally synchronized (Vulkan rule), so if the host
    // submits to it from other threads it passes a lock that vksonar takes around each vkQueueSubmit.
    void (*lock_queue)(void* user) = nullptr;
    void (*unlock_queue)(void* user) = nullptr;
    void* queue_lock_user = nullptr;
    // Optional: the host's allocation callbacks. vksonar passes them to every vkCreate*, vkDestroy*,
    // vkAllocateMemory and vkFreeMemory it calls on `device` (null: the implementation's allocator,
    // which Vulkan allows per object whatever the host's own objects use). Borrowed: the callbacks
    // (and their pUserData) must outlive the Context and every Renderer made from it, and be callable
    // from any thread that uses them.
    const VkAllocationCallbacks* allocator = nullptr;
};

// The options `base` with what the environment asks for, for tools and tests; vksonar itself never
// reads the environment. VKSONAR_VALIDATION=1|true|on sets enable_validation; VKSONAR_DEVICE=N sets
// device_index when base.device_index is -1. Fails with ErrorCode::invalid_argument if VKSONAR_DEVICE
// is not a device index. Thread-safety: reads the environment (std::getenv).
[[nodiscard]] Result<ContextOptions> context_options_from_env(ContextOptions base = {});

struct VulkanContext; // internal

// Thread-safety: shared by any number of threads (its calls are const); one Renderer per thread.
class Context {
public:
    Context();
    ~Context();
    Context(Context&&) noexcept;
    Context& operator=(Context&&) noexcept;

    // Creates (and owns) an instance and device. Fails with ErrorCode::no_device if none is usable.
    [[nodiscard]] static Result<Context> create(const ContextOptions& options = {});
    // Wraps (borrows) the host's instance, device and queue. Checks the requirements above and fails
    // with ErrorCode::unsupported naming the first one missing, or invalid_argument for null handles.
    [[nodiscard]] static Result<Context> adopt(const HostVulkan& host);
    // A context without Vulkan, for the CPU backend.
    static Context cpu_only();

    bool has_vulkan() const;
    // True if vksonar created the device (create), false if it is the host's (adopt) or there is none.
    bool owns_device() const;
    std::string device_description() const; // device name, driver, API version
    // Number of validation-layer messages of severity warning or error seen so far.
    std::uint32_t validation_messages() const;

    VulkanContext* vulkan() const { return vk_.get(); }

private:
    std::unique_ptr<VulkanContext> vk_;
};

} // namespace vksonar
