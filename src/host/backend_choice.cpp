#include "host/backend_choice.h"

#include <utility>

#include "core/access.h"
#include "vk/vulkan_context.h"

namespace vksonar::host {

Result<Context> choose_backend(Result<Context> vulkan, bool device_named, Backend& backend, std::string& why) {
    if (!vulkan && device_named)
        return make_error(ErrorCode::invalid_argument,
                          vulkan.error().message + " (VKSONAR_DEVICE names it: unset it to let --backend auto choose)");
    if (!vulkan) {
        backend = Backend::cpu;
        why = "auto: no usable Vulkan device (" + vulkan.error().message + "): the CPU backend";
        return Context::cpu_only();
    }
    Context context = std::move(vulkan.value());
    const VulkanContext* vk = context_vulkan(context);
    if (vk != nullptr && vk->properties.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU) {
        backend = Backend::cpu;
        why = "auto: the Vulkan device is a CPU implementation (" + context.device_description() +
              "), where the CPU backend is as fast or faster (docs/benchmarks.md, 'How cost grows')";
        return Context::cpu_only();
    }
    backend = Backend::vulkan;
    why = "auto: a GPU (" + context.device_description() + ")";
    return context;
}

} // namespace vksonar::host
