// Move-only owners for device-level Vulkan handles. A handle held by Owned<> is destroyed with the
// device it came from, and the allocation callbacks it was created with, when the owner dies; a plain
// Vk* handle is borrowed and never destroyed.
#pragma once

#include <utility>

#include <vulkan/vulkan_core.h>

namespace vksonar::vk {

template <class Handle, void (*Destroy)(VkDevice, Handle, const VkAllocationCallbacks*)> class Owned {
public:
    Owned() = default;
    // `allocator`: the callbacks the handle was created with (VulkanContext::allocator; may be null).
    Owned(VkDevice device, Handle handle, const VkAllocationCallbacks* allocator)
        : device_(device), handle_(handle), allocator_(allocator) {}
    ~Owned() { reset(); }
    Owned(const Owned&) = delete;
    Owned& operator=(const Owned&) = delete;
    Owned(Owned&& other) noexcept
        : device_(other.device_), handle_(std::exchange(other.handle_, Handle(VK_NULL_HANDLE))),
          allocator_(other.allocator_) {}
    Owned& operator=(Owned&& other) noexcept {
        if (this != &other) {
            reset();
            device_ = other.device_;
            handle_ = std::exchange(other.handle_, Handle(VK_NULL_HANDLE));
            allocator_ = other.allocator_;
        }
        return *this;
    }

    Handle get() const { return handle_; }
    explicit operator bool() const { return handle_ != VK_NULL_HANDLE; }
    void reset() {
        if (handle_ != VK_NULL_HANDLE) {
            Destroy(device_, handle_, allocator_);
            handle_ = VK_NULL_HANDLE;
        }
    }

private:
    VkDevice device_ = VK_NULL_HANDLE;
    Handle handle_ = VK_NULL_HANDLE;
    const VkAllocationCallbacks* allocator_ = nullptr;
};

using OwnedBuffer = Owned<VkBuffer, vkDestroyBuffer>;
using OwnedMemory = Owned<VkDeviceMemory, vkFreeMemory>;
using OwnedImage = Owned<VkImage, vkDestroyImage>;
using OwnedImageView = Owned<VkImageView, vkDestroyImageView>;
using OwnedRenderPass = Owned<VkRenderPass, vkDestroyRenderPass>;
using OwnedFramebuffer = Owned<VkFramebuffer, vkDestroyFramebuffer>;
using OwnedShaderModule = Owned<VkShaderModule, vkDestroyShaderModule>;
using OwnedPipeline = Owned<VkPipeline, vkDestroyPipeline>;
using OwnedPipelineLayout = Owned<VkPipelineLayout, vkDestroyPipelineLayout>;
using OwnedDescriptorSetLayout = Owned<VkDescriptorSetLayout, vkDestroyDescriptorSetLayout>;
using OwnedDescriptorPool = Owned<VkDescriptorPool, vkDestroyDescriptorPool>; // frees its sets
using OwnedCommandPool = Owned<VkCommandPool, vkDestroyCommandPool>;          // frees its buffers
using OwnedFence = Owned<VkFence, vkDestroyFence>;
using OwnedQueryPool = Owned<VkQueryPool, vkDestroyQueryPool>;

} // namespace vksonar::vk
