// VkResult -> Error, and the early-return macro the Vulkan code uses for every call that can fail.
#pragma once

#include <string>

#include <vulkan/vulkan_core.h>

#include "vksonar/result.h"

namespace vksonar::vk {

const char* result_name(VkResult result);

inline Error vk_error(VkResult result, const char* call) {
    return make_error(ErrorCode::vulkan, std::string(call) + " failed: " + result_name(result), result);
}

} // namespace vksonar::vk

// Evaluates a Vulkan call; on failure returns an Error naming the call and the VkResult.
#define VKS_VK_TRY(call)                                                                                               \
    do {                                                                                                               \
        VkResult vks_result_ = (call);                                                                                 \
        if (vks_result_ != VK_SUCCESS) {                                                                               \
            return ::vksonar::vk::vk_error(vks_result_, #call);                                                        \
        }                                                                                                              \
    } while (0)
