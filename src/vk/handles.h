// Move-only owners for device-level Vulkan handles. A handle held by Owned<> is destroyed with the
// device it came from, the allocation callbacks it was created with and the context's destroy function
// (VulkanContext::fn) when the owner dies; a plain Vk* handle is borrowed and never destroyed.
#pragma once

#include <type_traits>
#include <utility>

#include <vulkan/vulkan_core.h>

#include "vk/vulkan_context.h"

namespace vksonar::vk {

// `Destroy`: the member of Functions that destroys a Handle, e.g. &Functions::vkDestroyBuffer.
template <class Handle, auto Destroy> class Owned {
    using DestroyFunction = std::decay_t<decltype(std::declval<const Functions&>().*Destroy)>;

public:
    Owned() = default;
    // Takes `handle`, made on context.device with context.allocator; keeps the destroy function, so it
    // needs nothing of the context later (the context must outlive it all the same: its device does).
    Owned(const VulkanContext& context, Handle handle)
        : device_(context.device), handle_(handle), allocator_(context.allocator), destroy_(context.fn.*Destroy) {}
    ~Owned() { reset(); }
    Owned(const Owned&) = delete;
    Owned& operator=(const Owned&) = delete;
    Owned(Owned&& other) noexcept
        : device_(other.device_), handle_(std::exchange(other.handle_, Handle(VK_NULL_HANDLE))),
          allocator_(other.allocator_), destroy_(other.destroy_) {}
    Owned& operator=(Owned&& other) noexcept {
        if (this != &other) {
            reset();
            device_ = other.device_;
            handle_ = std::exchange(other.handle_, Handle(VK_NULL_HANDLE));
            allocator_ = other.allocator_;
            destroy_ = other.destroy_;
        }
        return *this;
    }

    Handle get() const { return handle_; }
    explicit operator bool() const { return handle_ != VK_NULL_HANDLE; }
    void reset() {
        if (handle_ != VK_NULL_HANDLE) {
            destroy_(device_, handle_, allocator_);
            handle_ = VK_NULL_HANDLE;
        }
    }

private:
    VkDevice device_ = VK_NULL_HANDLE;
    Handle handle_ = VK_NULL_HANDLE;
    const VkAllocationCallbacks* allocator_ = nullptr;
    DestroyFunction destroy_ = nullptr;
};

using OwnedBuffer = Owned<VkBuffer, &Functions::vkDestroyBuffer>;
using OwnedMemory = Owned<VkDeviceMemory, &Functions::vkFreeMemory>;
using OwnedImage = Owned<VkImage, &Functions::vkDestroyImage>;
using OwnedImageView = Owned<VkImageView, &Functions::vkDestroyImageView>;
using OwnedRenderPass = Owned<VkRenderPass, &Functions::vkDestroyRenderPass>;
using OwnedFramebuffer = Owned<VkFramebuffer, &Functions::vkDestroyFramebuffer>;
using OwnedShaderModule = Owned<VkShaderModule, &Functions::vkDestroyShaderModule>;
using OwnedPipeline = Owned<VkPipeline, &Functions::vkDestroyPipeline>;
using OwnedPipelineLayout = Owned<VkPipelineLayout, &Functions::vkDestroyPipelineLayout>;
using OwnedDescriptorSetLayout = Owned<VkDescriptorSetLayout, &Functions::vkDestroyDescriptorSetLayout>;
using OwnedDescriptorPool = Owned<VkDescriptorPool, &Functions::vkDestroyDescriptorPool>; // frees its sets
using OwnedCommandPool = Owned<VkCommandPool, &Functions::vkDestroyCommandPool>;          // frees its buffers
using OwnedFence = Owned<VkFence, &Functions::vkDestroyFence>;
using OwnedQueryPool = Owned<VkQueryPool, &Functions::vkDestroyQueryPool>;

} // namespace vksonar::vk
