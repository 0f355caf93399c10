#include "vk/resources.h"

#include <cstring>

#include "vk/commands.h"
#include "vk/vk_error.h"
#include "vk/vulkan_context.h"

namespace vksonar::vk {
namespace {

// Picks the first memory type allowed by `type_bits` that has `required`, preferring one that also has
// `preferred`.
int find_memory_type(const VkPhysicalDeviceMemoryProperties& properties, std::uint32_t type_bits,
                     VkMemoryPropertyFlags required, VkMemoryPropertyFlags preferred) {
    int fallback = -1;
    for (std::uint32_t i = 0; i < properties.memoryTypeCount; ++i) {
        if ((type_bits & (1u << i)) == 0) {
            continue;
        }
        VkMemoryPropertyFlags flags = properties.memoryTypes[i].propertyFlags;
        if ((flags & required) != required) {
            continue;
        }
        if ((flags & preferred) == preferred) {
            return static_cast<int>(i);
        }
        if (fallback < 0) {
            fallback = static_cast<int>(i);
        }
    }
    return fallback;
}

Result<OwnedMemory> allocate(const VulkanContext& context, const VkMemoryRequirements& requirements,
                             VkMemoryPropertyFlags required, VkMemoryPropertyFlags preferred) {
    VkPhysicalDeviceMemoryProperties properties;
    context.fn.vkGetPhysicalDeviceMemoryProperties(context.physical_device, &properties);
    int type = find_memory_type(properties, requirements.memoryTypeBits, required, preferred);
    if (type < 0) {
        return make_error(ErrorCode::vulkan,
                          "no Vulkan memory type fits a buffer or image of " + std::to_string(requirements.size) +
                              " bytes",
                          VK_ERROR_OUT_OF_DEVICE_MEMORY);
    }
    VkMemoryAllocateInfo info{};
    info.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO;
    info.allocationSize = requirements.size;
    info.memoryTypeIndex = static_cast<std::uint32_t>(type);
    VkDeviceMemory memory = VK_NULL_HANDLE;
    VKS_VK_TRY(context.fn.vkAllocateMemory(context.device, &info, context.allocator, &memory));
    return OwnedMemory(context, memory);
}

} // namespace

Result<Buffer> create_buffer(const VulkanContext& context, VkDeviceSize size, VkBufferUsageFlags usage, MemoryUse use) {
    Buffer result;
    result.size = size < 16 ? 16 : size;
    VkBufferCreateInfo info{};
    info.sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO;
    info.size = result.size;
    info.usage = usage;
    info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
    VkBuffer buffer = VK_NULL_HANDLE;
    VKS_VK_TRY(context.fn.vkCreateBuffer(context.device, &info, context.allocator, &buffer));
    result.buffer = OwnedBuffer(context, buffer);

    VkMemoryRequirements requirements;
    context.fn.vkGetBufferMemoryRequirements(context.device, buffer, &requirements);
    VkMemoryPropertyFlags required = 0, preferred = VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT;
    if (use == MemoryUse::readback) {
        required = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
        preferred = required | VK_MEMORY_PROPERTY_HOST_CACHED_BIT;
    } else if (use == MemoryUse::upload) {
        required = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
        preferred = required;
    }
    auto memory = allocate(context, requirements, required, preferred);
    if (!memory) {
        return memory.error();
    }
    result.memory = std::move(memory.value());
    VKS_VK_TRY(context.fn.vkBindBufferMemory(context.device, buffer, result.memory.get(), 0));
    if (use != MemoryUse::device) {
        VKS_VK_TRY(context.fn.vkMapMemory(context.device, result.memory.get(), 0, VK_WHOLE_SIZE, 0, &result.mapped));
    }
    return result;
}

Result<Image> create_image_2d(const VulkanContext& context, std::uint32_t width, std::uint32_t height, VkFormat format,
                              VkImageUsageFlags usage, VkImageAspectFlags aspect) {
    Image result;
    result.format = format;
    VkImageCreateInfo info{};
    info.sType = VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO;
    info.imageType = VK_IMAGE_TYPE_2D;
    info.format = format;
    info.extent = {width, height, 1};
    info.mipLevels = 1;
    info.arrayLayers = 1;
    info.samples = VK_SAMPLE_COUNT_1_BIT;
    info.tiling = VK_IMAGE_TILING_OPTIMAL;
    info.usage = usage;
    info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
    info.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
    VkImage image = VK_NULL_HANDLE;
    VKS_VK_TRY(context.fn.vkCreateImage(context.device, &info, context.allocator, &image));
    result.image = OwnedImage(context, image);

    VkMemoryRequirements requirements;
    context.fn.vkGetImageMemoryRequirements(context.device, image, &requirements);
    auto memory = allocate(context, requirements, 0, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
    if (!memory) {
        return memory.error();
    }
    result.memory = std::move(memory.value());
    VKS_VK_TRY(context.fn.vkBindImageMemory(context.device, image, result.memory.get(), 0));

    VkImageViewCreateInfo view_info{};
    view_info.sType = VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO;
    view_info.image = image;
    view_info.viewType = VK_IMAGE_VIEW_TYPE_2D;
    view_info.format = format;
    view_info.subresourceRange = {aspect, 0, 1, 0, 1};
    VkImageView view = VK_NULL_HANDLE;
    VKS_VK_TRY(context.fn.vkCreateImageView(context.device, &view_info, context.allocator, &view));
    result.view = OwnedImageView(context, view);
    return result;
}

Result<void> upload_to_buffer(VulkanContext& context, const Buffer& destination, const void* data, std::size_t bytes) {
    if (bytes == 0) {
        return {};
    }
    auto staging = create_buffer(context, bytes, VK_BUFFER_USAGE_TRANSFER_SRC_BIT, MemoryUse::upload);
    if (!staging) {
        return staging.error();
    }
    std::memcpy(staging->mapped, data, bytes);
    return submit_once(context, [&](VkCommandBuffer commands) {
        VkBufferCopy region{0, 0, bytes};
        context.fn.vkCmdCopyBuffer(commands, staging->get(), destination.get(), 1, &region);
    });
}

} // namespace vksonar::vk
