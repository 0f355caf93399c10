// HostDepthRenderer: a host engine's own depth image as the input of the sonar (docs/embedding.md).
// vksonar then runs only its compute and host stages: the depth image replaces the depth pass.
// Every Vulkan handle the host passes here is borrowed: vksonar never creates, transitions for good,
// or destroys it.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include <vulkan/vulkan_core.h>

#include "vksonar/config.h"
#include "vksonar/context.h"
#include "vksonar/frame.h"
#include "vksonar/renderer.h"
#include "vksonar/result.h"
#include "vksonar/validity.h"

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
    // A depth format: D32_SFLOAT, D16_UNORM, X8_D24_UNORM_PACK32, D16_UNORM_S8_UINT, D24_UNORM_S8_UINT,
    // D32_SFLOAT_S8_UINT (with a stencil the view must select the depth aspect only); or depth kept as
    // colour: R32_SFLOAT, R16_SFLOAT, R16_UNORM (linear_m needs R32_SFLOAT or R16_SFLOAT). Must support
    // SAMPLED_IMAGE.
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
// by the host: valid until the HostDepthRenderer is destroyed; never destroy it.
// Thread-safety: a plain value; the buffer's contents change with each recorded ping of its Renderer,
// so the host reads it only between that ping's completion and the next record() or process().
struct GpuBufferView {
    VkBuffer buffer = VK_NULL_HANDLE;
    VkDeviceSize offset = 0, size = 0;
    std::uint32_t beams = 0, bins = 0; // float32[bins][beams], range-major, linear, relative to the source level
};

// One simulated sonar on a host engine's depth images (Vulkan backend only): the host renders the
// depth, vksonar turns it into a sonar frame. Its own type, apart from Renderer (which renders a
// Scene), so that a scene render on it, or a host-depth call on a Renderer, does not compile.
// The renderer's pixel grid is the host image's (HostDepthDesc); the camera is the sonar. A depth image
// carries no material ids: every hit pixel scatters with config.default_backscatter_db and Lambert.
// Thread-safety: not thread-safe: one thread at a time; renderers sharing a Context are independent.
class HostDepthRenderer {
public:
    // An empty renderer (no call but destruction and assignment is valid): use create().
    HostDepthRenderer();
    // Waits for nothing: the host must have seen its last recorded ping finish (see record()).
    ~HostDepthRenderer();
    HostDepthRenderer(HostDepthRenderer&&) noexcept;
    HostDepthRenderer& operator=(HostDepthRenderer&&) noexcept;

    // Validates the config, builds the plan on the host image's grid, and creates the compute stages,
    // their buffers and the import pass on `context`'s device. Needs a Vulkan context (created or
    // adopted; a compute queue is enough) and options.backend == Backend::vulkan. Fails with
    // ErrorCode::invalid_argument for a CPU context, the CPU backend or a bad config or desc, and with
    // ErrorCode::unsupported if the image does not cover the sonar, its principal point is not the image
    // centre, the format is none of HostDepthDesc's or cannot be sampled, or the config asks for
    // accuracy.normal_method = geometric (which needs the triangles, not a depth image), or host memory
    // runs out or a host thread cannot start.
    // `context` must outlive the renderer; `config`, `desc` and `options` are copied. Thread-safety:
    // may be called from any thread, also while other renderers on the same context work.
    [[nodiscard]] static Result<HostDepthRenderer>
    create(Context& context, const SonarConfig& config, const HostDepthDesc& desc, const RendererOptions& options = {});

    // A new frame sized for this renderer and its save_mask (the only allocation; reuse it for every
    // ping). Owned by the caller.
    Frame make_frame() const;

    // The noise seed (RendererOptions::seed): (seed, frame_index) key the noise of every frame.
    void set_seed(std::uint64_t seed);
    std::uint64_t seed() const;

    // Converts the host's image (in depth.layout, after depth.wait_semaphore) into vksonar's depth
    // buffer, runs normals/echo/beamform on the context's queue, waits for them, then the host
    // stages: fills `frame` (made by make_frame) as Renderer::render does. The host must not write the
    // image until process() returns. Allocates nothing. Fails with ErrorCode::invalid_argument for a
    // frame of another size or an image without image/view or in a layout that cannot be sampled,
    // ErrorCode::vulkan if a Vulkan call fails.
    [[nodiscard]] Result<void> process(const HostDepthImage& depth, std::uint64_t frame_index, Frame& frame);
    // Records the same GPU work into the host's command buffer (primary, recording, outside a render
    // pass, from a pool of the context's queue family) with the barriers it needs, and returns without
    // submitting: the host submits it with its own semaphores and fence, and the sonar runs inside the
    // host's frame without a CPU wait. One ping in flight: the host must have seen the previous
    // recorded ping finish before calling record() or process() again (both refuse until it has run),
    // and before destroying the renderer. Allocates nothing. Fails with ErrorCode::invalid_argument for a
    // null command buffer, an image process() would refuse or a recorded ping that has not run yet,
    // ErrorCode::vulkan if a Vulkan call fails; on failure nothing is recorded.
    [[nodiscard]] Result<void> record(VkCommandBuffer commands, const HostDepthImage& depth);
    // The command buffer given to the last record() will never run: the host freed or reset it without
    // submitting it (a swapchain rebuild, a frame it dropped). record() and process() go on; read_back()
    // then says nothing was recorded. Only for a command buffer that was never submitted.
    void discard_recorded();
    // After the command buffer given to record() has finished executing (the host waited for its
    // fence): copies the result to host memory and runs the host stages (noise, gain) into `frame`.
    // Fails with ErrorCode::invalid_argument, without touching `frame`'s arrays (its stage lists, times
    // and stages_run, start over empty), if nothing was recorded or the GPU work has not finished.
    [[nodiscard]] Result<void> read_back(std::uint64_t frame_index, Frame& frame);
    // The clean polar scan on the GPU after a recorded ping (before speckle, noise and gain, which are
    // host stages), for drawing it in the engine. Owned by the renderer: the host borrows it. The same
    // buffer for the renderer's life; never fails.
    GpuBufferView polar_buffer() const;

    // The config as validated (copied at create).
    const SonarConfig& config() const;
    // Each model this renderer's frames use, checked against its validity domain (validity.h).
    const std::vector<ModelValidity>& validity() const;

private:
    friend struct detail::Access; // src/core/access.h
    std::unique_ptr<RendererImpl> impl_;
};

} // namespace vksonar
