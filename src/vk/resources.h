// Buffers and images with their own memory (plain vkAllocateMemory: vksonar allocates a few long-lived
// resources per renderer, never per frame).
#pragma once

#include <cstddef>
#include <cstdint>

#include "vk/handles.h"
#include "vksonar/result.h"

namespace vksonar {
struct VulkanContext;
}

namespace vksonar::vk {

enum class MemoryUse {
    device,   // device-local if the device has it (GPU-only data)
    readback, // host-visible, coherent, preferably cached (GPU writes, host reads)
    upload,   // host-visible, coherent (host writes once, GPU reads)
};

// Members are declared so that the buffer is destroyed before its memory.
struct Buffer {
    OwnedMemory memory;
    OwnedBuffer buffer;
    VkDeviceSize size = 0;
    void* mapped = nullptr; // persistently mapped for host-visible uses, else null

    VkBuffer get() const { return buffer.get(); }
};

struct Image {
    OwnedMemory memory;
    OwnedImage image;
    OwnedImageView view;
    VkFormat format = VK_FORMAT_UNDEFINED;

    VkImage get() const { return image.get(); }
};

// size 0 is rounded up to a small buffer so that every descriptor can stay valid.
[[nodiscard]] Result<Buffer> create_buffer(const VulkanContext& context, VkDeviceSize size, VkBufferUsageFlags usage,
                                           MemoryUse use);

[[nodiscard]] Result<Image> create_image_2d(const VulkanContext& context, std::uint32_t width, std::uint32_t height,
                                            VkFormat format, VkImageUsageFlags usage, VkImageAspectFlags aspect);

// Copies bytes into a device buffer through a temporary staging buffer and waits for it.
[[nodiscard]] Result<void> upload_to_buffer(VulkanContext& context, const Buffer& destination, const void* data,
                                            std::size_t bytes);

} // namespace vksonar::vk
