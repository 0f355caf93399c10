// The embedding path of the Vulkan backend: a host engine's depth image in place of the depth pass.
// An import pass (shaders/import_depth.comp) converts the host image into vksonar's depth and material
// buffers; then the backend's own normals, echo and beamform stages run unchanged on the host plan
// (core/host_plan.h). Every object here is created once; process/record allocate nothing.
#pragma once

#include <memory>

#include "core/plan.h"
#include "stages/stage_backend.h"
#include "stages/stage_table.h"
#include "vksonar/frame.h"
#include "vksonar/host_depth.h"
#include "vksonar/renderer.h"
#include "vksonar/result.h"

namespace vksonar {
struct VulkanContext;
}

namespace vksonar::vk {

struct RecordContext;

// A StageBackend so that Renderer::render's frame checks and host stages serve process() and
// read_back() too: Renderer arms the pass (arm_process / arm_read_back), then calls render().
class HostDepthPass final : public StageBackend {
public:
    // Checks the host image's format against the device (SAMPLED_IMAGE support, encoding) and creates
    // the backend's compute stages for `plan` plus the import pass.
    [[nodiscard]] static Result<std::unique_ptr<HostDepthPass>>
    create(VulkanContext& context, const Plan& plan, const HostDepthDesc& desc, const RendererOptions& options);
    ~HostDepthPass() override;
    HostDepthPass(const HostDepthPass&) = delete;
    HostDepthPass& operator=(const HostDepthPass&) = delete;

    // Records, submits (after the image's wait semaphore), waits and copies out: frame.clean, the
    // intermediates in save_mask, frame.times.
    [[nodiscard]] Result<void> process(const HostDepthImage& image, SaveFlags save_mask, Frame& frame);
    // Records import .. beamform and the readback copies into the host's command buffer; no submit.
    [[nodiscard]] Result<void> record(VkCommandBuffer commands, const HostDepthImage& image, SaveFlags save_mask);
    // After the command buffer given to record() has finished: copies the readback out (as process).
    [[nodiscard]] Result<void> read_back(SaveFlags save_mask, Frame& frame);
    // HostDepthRenderer::discard_recorded: the last recording will never run.
    void discard_recorded();
    // ErrorCode::invalid_argument while a recorded ping has not run yet (`call` names the caller).
    [[nodiscard]] Result<void> refuse_while_recorded_pending(const char* call) const;
    GpuBufferView polar_buffer() const;

    // The next render() runs process(image) / read_back(); render() without either fails.
    void arm_process(const HostDepthImage& image);
    void arm_read_back();
    [[nodiscard]] Result<void> render(const Pose& pose, SaveFlags save_mask, Frame& frame) override;
    const char* name() const override { return "vulkan (host depth)"; }
    const SubpixelReturns* subpixel_returns() const override { return nullptr; } // no scene, no objects

    struct Objects; // internal

private:
    HostDepthPass();
    Result<void> init(VulkanContext& context, const Plan& plan, const HostDepthDesc& desc,
                      const RendererOptions& options);
    Result<void> check_image(const HostDepthImage& image) const;
    void bind_image(const HostDepthImage& image);
    // The import pass, preceded by the barrier that makes the host's writes to the image visible.
    friend void record_import(RecordContext& record);
    void record_import_pass(VkCommandBuffer commands, const HostDepthImage& image, const Dispatch& groups);
    void copy_frame_out(SaveFlags save_mask, Frame& frame) const;

    std::unique_ptr<Objects> objects_;
};

} // namespace vksonar::vk
