// Loading the dispatch table (functions.h), group by group.
#include "vk/functions.h"

namespace vksonar::vk {
namespace {

Error missing(const std::string& whose, const char* getter, const char* name) {
    return make_error(ErrorCode::unsupported, whose + getter + " returns null for " + name);
}

} // namespace

// Each VKSONAR_VK_LOAD_* sets one member and returns the error naming it if the getter gave null.
#define VKSONAR_VK_LOAD_GLOBAL(name)                                                                                   \
    fn.name = reinterpret_cast<PFN_##name>(fn.vkGetInstanceProcAddr(VK_NULL_HANDLE, #name));                           \
    if (fn.name == nullptr) return missing(whose, "vkGetInstanceProcAddr", #name);
#define VKSONAR_VK_LOAD_INSTANCE(name)                                                                                 \
    fn.name = reinterpret_cast<PFN_##name>(fn.vkGetInstanceProcAddr(instance, #name));                                 \
    if (fn.name == nullptr) return missing(whose, "vkGetInstanceProcAddr", #name);
#define VKSONAR_VK_LOAD_DEVICE(name)                                                                                   \
    fn.name = reinterpret_cast<PFN_##name>(fn.vkGetDeviceProcAddr(device, #name));                                     \
    if (fn.name == nullptr) return missing(whose, "vkGetDeviceProcAddr", #name);

Result<void> load_global_functions(Functions& fn, const std::string& whose) {
    VKSONAR_VK_GLOBAL_FUNCTIONS(VKSONAR_VK_LOAD_GLOBAL)
    return {};
}

Result<void> load_instance_functions(Functions& fn, VkInstance instance, bool own, const std::string& whose) {
    if (own) {
        VKSONAR_VK_OWN_INSTANCE_FUNCTIONS(VKSONAR_VK_LOAD_INSTANCE)
    }
    VKSONAR_VK_INSTANCE_FUNCTIONS(VKSONAR_VK_LOAD_INSTANCE)
    if (fn.vkGetDeviceProcAddr == nullptr) {
        VKSONAR_VK_LOAD_INSTANCE(vkGetDeviceProcAddr)
    }
    return {};
}

Result<void> load_device_functions(Functions& fn, VkDevice device, bool own, const std::string& whose) {
    if (own) {
        VKSONAR_VK_OWN_DEVICE_FUNCTIONS(VKSONAR_VK_LOAD_DEVICE)
    }
    VKSONAR_VK_DEVICE_FUNCTIONS(VKSONAR_VK_LOAD_DEVICE)
    return {};
}

void load_debug_utils_functions(Functions& fn, VkInstance instance) {
#define VKSONAR_VK_LOAD_OPTIONAL(name)                                                                                 \
    fn.name = reinterpret_cast<PFN_##name>(fn.vkGetInstanceProcAddr(instance, #name));
    VKSONAR_VK_DEBUG_UTILS_FUNCTIONS(VKSONAR_VK_LOAD_OPTIONAL)
#undef VKSONAR_VK_LOAD_OPTIONAL
}

#undef VKSONAR_VK_LOAD_GLOBAL
#undef VKSONAR_VK_LOAD_INSTANCE
#undef VKSONAR_VK_LOAD_DEVICE

} // namespace vksonar::vk
