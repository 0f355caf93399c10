// A host engine's own depth image as the input of a Renderer (Renderer::create_for_depth, process,
// record). vksonar then runs only its compute and host stages: the depth image replaces the depth pass.
// Every Vulkan handle here is borrowed: vksonar never creates, transitions for good, or destroys it.
#pragma once

#include <cstdint>

#include <vulkan/vulkan_core.h>

namespace vksonar {

// How the host's depth value d encodes view depth z (metres along the camera's forward axis).
enum class DepthEncoding : std::uint8_t {
    standard_z, // d = 0 at near_m, 1 at far_m (Vulkan/D3D [0, 1] projection); cleared to 1 = no hit
    reversed_z, // d = 1 at near_m, 0 at far_m (far_m may be +inf: infinite reversed-Z); cleared to 0 = no hit
    linear_m,   // d = z in metres (an R32_SFLOAT colour image); d <= 0, NaN or +inf = no hit
};

// What stays the same for every depth image the host will hand over; fixes the renderer's pixel grid.
// The camera is the sonar: it looks along the sonar's +x (forward); image row 0 is the top (up, sonar +z),
// column 0 the left (port, sonar +y). The image's pixel grid becomes the sonar's pixel grid, so the
// principal point must be the image centre (cx = width/2, cy = height/2) and the image must cover every
// beam centre horizontally and the -3 dB vertical beamwidth vertically (checked, with a clear error).
// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct HostDepthDesc {
    std::uint32_t width = 0, height = 0;
    // D32_SFLOAT, D16_UNORM, X8_D24_UNORM_PACK32, D24_UNORM_S8_UINT, D32_SFLOAT_S8_UINT (the view must
    // then select the depth aspect only), or R32_SFLOAT for linear_m. Must support SAMPLED_IMAGE.
    VkFormat format = VK_FORMAT_D32_SFLOAT;
    double fx_px = 0, fy_px = 0; // focal lengths in pixels (tan(half fov) = width / (2 fx))
    double cx_px = 0, cy_px = 0; // principal point in pixels (0, 0 = top-left corner of the image)
    DepthEncoding encoding = DepthEncoding::reversed_z;
    double near_m = 0.1, far_m = 1000.0; // the host projection's planes (unused for linear_m)
};

// One depth image, per frame. The image must have been created with VK_IMAGE_USAGE_SAMPLED_BIT and
// match HostDepthDesc; the view is a 2-D view of its depth aspect (or colour for R32_SFLOAT).
// Thread-safety: a plain value; the image itself is the host's to synchronize (see process and record).
struct HostDepthImage {
    VkImage image = VK_NULL_HANDLE;
    VkImageView view = VK_NULL_HANDLE;
    // The layout the image is in when vksonar's commands run, and stays in: GENERAL,
    // SHADER_READ_ONLY_OPTIMAL, DEPTH_STENCIL_READ_ONLY_OPTIMAL or DEPTH_READ_ONLY_STENCIL_ATTACHMENT_OPTIMAL.
    VkImageLayout layout = VK_IMAGE_LAYOUT_DEPTH_STENCIL_READ_ONLY_OPTIMAL;
    // The host's last writes to the image, made visible to vksonar by a barrier vksonar records.
    // 0 means the depth attachment writes of a render pass (early + late fragment tests).
    VkPipelineStageFlags src_stage = 0;
    VkAccessFlags src_access = 0;
    // process() only: a binary semaphore the host signalled when the image was ready (or null: the
    // image was rendered by work submitted earlier to the same queue, or already waited for).
    VkSemaphore wait_semaphore = VK_NULL_HANDLE;
};

// A buffer vksonar owns and the host may read (e.g. to draw the sonar image in the engine). Borrowed
// by the host: valid until the Renderer is destroyed; never destroy it.
// Thread-safety: a plain value; the buffer's contents change with each recorded ping of its Renderer,
// so the host reads it only between that ping's completion and the next record() or process().
struct GpuBufferView {
    VkBuffer buffer = VK_NULL_HANDLE;
    VkDeviceSize offset = 0, size = 0;
    std::uint32_t beams = 0, bins = 0; // float32[bins][beams], range-major, linear, relative to the source level
};

} // namespace vksonar
