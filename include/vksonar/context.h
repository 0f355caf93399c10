// Context: the Vulkan instance/device vksonar runs on, owned (create) or borrowed (adopt).
// Thread-safety: a Context may be shared by renderers on different threads (one Renderer per thread);
// its own calls are const and safe to make concurrently. vksonar's queue submissions are serialized
// through the host's queue lock (HostVulkan::lock_queue) if given, else an internal mutex.
//
// Requirements (checked by create and adopt, with an error naming what is missing): Vulkan 1.1 (instance
// and device), a queue family with compute (and graphics for Renderer::render's depth pass; process()
// needs compute only). Renderer::create checks that the device has D32_SFLOAT depth + R32_UINT colour
// attachments for its depth pass. No device extension and no optional device feature is required.
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

// The host's Vulkan entry points, optional in HostVulkan (as VMA's VmaVulkanFunctions). vksonar calls
// every Vulkan function through a table of pointers its context loads once: given these, from them
// (instance functions with vkGetInstanceProcAddr(HostVulkan::instance, ...), device functions with
// vkGetDeviceProcAddr(HostVulkan::device, ...)), so vksonar's calls go where the host's go: a host
// with its own or a statically linked loader, its own layers, or volk works. Context::adopt resolves
// every function vksonar calls before it calls any, and fails with ErrorCode::invalid_argument if a
// pointer here is null, or ErrorCode::unsupported naming the first function a getter returns null for.
// Left null (HostVulkan::functions == nullptr), adopt loads the table from the Vulkan loader vksonar
// links (libvulkan), which must then be the loader the host's instance and device come from.
// Thread-safety: a plain value, read only during adopt (the pointers it yields are kept).
struct VulkanFunctions {
    PFN_vkGetInstanceProcAddr vkGetInstanceProcAddr = nullptr; // required
    PFN_vkGetDeviceProcAddr vkGetDeviceProcAddr = nullptr;     // required
};

// A host engine's Vulkan objects, borrowed by Context::adopt. vksonar never destroys any of them; they
// must outlive the Context and every Renderer made from it. vksonar reaches them through the host's
// entry points if `functions` is given, else through the Vulkan loader it links (VulkanFunctions).
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
    // Optional: the host's entry points, through which vksonar makes every call on these objects
    // (VulkanFunctions). Borrowed: the struct is read only during adopt; the functions its getters
    // return must stay callable, from any thread that uses the Context, while it and its renderers
    // exist.
    const VulkanFunctions* functions = nullptr;
};

// The options `base` with what the environment asks for, for tools and tests; vksonar itself never
// reads the environment. VKSONAR_VALIDATION=1|true|on sets enable_validation; VKSONAR_DEVICE=N sets
// device_index when base.device_index is -1. Fails with ErrorCode::invalid_argument if VKSONAR_DEVICE
// is not a device index. Thread-safety: reads the environment (std::getenv).
[[nodiscard]] Result<ContextOptions> context_options_from_env(ContextOptions base = {});

struct VulkanContext; // internal
namespace detail {
struct Access; // internal: src/core/access.h
}
class AdoptedContext;

// The device vksonar runs on, as Renderer and HostDepthRenderer take it. Ownership is in the type:
// a Context made by create() owns its instance and device and destroys them with it; adopt() returns
// an AdoptedContext, which borrows the host's and destroys nothing of them. (An AdoptedContext is a
// Context for the renderers, but cannot be moved into a plain Context, which would hide that.)
// Thread-safety: shared by any number of threads (its calls are const); one Renderer per thread.
class Context {
public:
    // An empty context: no Vulkan, as cpu_only().
    Context();
    // Destroys the device and instance if create() made them (after vkDeviceWaitIdle); every Renderer
    // and HostDepthRenderer made from it must be destroyed first.
    ~Context();
    // Moves the instance and device (and what owning them means); the moved-from context is CPU-only.
    Context(Context&&) noexcept;
    Context& operator=(Context&&) noexcept;
    Context(AdoptedContext&&) = delete; // would drop the type that says the device is borrowed
    Context& operator=(AdoptedContext&&) = delete;

    // Creates and owns an instance and device (Vulkan 1.1, a graphics+compute queue), its functions
    // loaded through the linked loader's vkGetInstanceProcAddr (the one loader export vksonar calls).
    // Returns the context, or ErrorCode::no_device if no device is usable (the message suggests the
    // CPU backend) or device_index does not exist, ErrorCode::unsupported naming a function the loader
    // does not resolve, ErrorCode::vulkan if a Vulkan call fails, ErrorCode::invalid_argument for a
    // device_index below -1. options.vulkan == false gives
    // cpu_only(). Reads no environment variable (context_options_from_env does, for tools).
    // Thread-safety: may be called from any thread.
    [[nodiscard]] static Result<Context> create(const ContextOptions& options = {});
    // Wraps (borrows) the host's instance, device and queue: see AdoptedContext. Resolves every
    // function vksonar calls through HostVulkan::functions (or the linked loader; VulkanFunctions),
    // checks the requirements above and fails with ErrorCode::unsupported naming the first function
    // or requirement missing, or ErrorCode::invalid_argument for null handles, a half-given queue lock
    // or function table, or a queue family the device does not have. Thread-safety: may be called from
    // any thread; makes no Vulkan object and submits nothing.
    [[nodiscard]] static Result<AdoptedContext> adopt(const HostVulkan& host);
    // A context without Vulkan, for the CPU backend. Never fails, allocates nothing.
    static Context cpu_only();

    // True unless the context is CPU-only.
    bool has_vulkan() const;
    // The device name, driver and API version in one line ("CPU (no Vulkan)" for a CPU-only context).
    std::string device_description() const;
    // Number of validation-layer messages of severity warning or error seen so far (0 without
    // ContextOptions::enable_validation, and always 0 for an adopted context).
    std::uint32_t validation_messages() const;

private:
    friend struct detail::Access; // src/core/access.h
    friend class AdoptedContext;
    std::unique_ptr<VulkanContext> vk_;
};

// A Context on the host engine's own instance and device (Context::adopt). Borrowed: destroying it
// destroys no handle of the host's (only what vksonar made on the device, which the renderers own);
// the host's instance, device and queue must outlive it and every renderer made from it.
// Thread-safety: as Context.
class AdoptedContext final : public Context {
public:
    // An empty adopted context (no Vulkan): use Context::adopt. Moves as Context does.
    AdoptedContext() = default;
    AdoptedContext(AdoptedContext&&) noexcept = default;
    AdoptedContext& operator=(AdoptedContext&&) noexcept = default;
};

} // namespace vksonar
