// Context: the Vulkan instance/device vksonar runs on, owned or borrowed.
// Thread-safety: a Context may be shared by renderers on different threads; queue submissions are
// serialized through the optional queue lock (borrowed devices) or an internal mutex (owned).
#pragma once

#include <memory>
#include <string>

#include <vulkan/vulkan_core.h>

#include "vksonar/result.h"

namespace vksonar {

struct ContextOptions {
    bool enable_validation = false; // VK_LAYER_KHRONOS_validation; also VKSONAR_VALIDATION=1
    int device_index = -1;          // -1: VKSONAR_DEVICE env var, else the first device with compute+graphics
    bool vulkan = true;             // false: a CPU-only context (no Vulkan at all)
};

struct VulkanContext; // internal

class Context {
public:
    Context();
    ~Context();
    Context(Context&&) noexcept;
    Context& operator=(Context&&) noexcept;

    // Creates (and owns) an instance and device. Fails with ErrorCode::no_device if none is usable.
    [[nodiscard]] static Result<Context> create(const ContextOptions& options = {});
    // A context without Vulkan, for the CPU backend.
    static Context cpu_only();

    bool has_vulkan() const;
    std::string device_description() const; // device name, driver, API version
    // Number of validation-layer messages of severity warning or error seen so far.
    std::uint32_t validation_messages() const;

    VulkanContext* vulkan() const { return vk_.get(); }

private:
    std::unique_ptr<VulkanContext> vk_;
};

} // namespace vksonar
