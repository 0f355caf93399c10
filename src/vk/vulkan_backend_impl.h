// The Vulkan StageBackend's class, shared by its creation (vulkan_backend.cpp) and its per-frame
// recording and readback (vulkan_frame.cpp). Internal to src/vk.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <vector>

#include "core/plan.h"
#include "core/subpixel.h"
#include "scene/scene_data.h"
#include "sonar_shared.h"
#include "stages/stage_backend.h"
#include "stages/stage_table.h"
#include "vk/handles.h"
#include "vk/resources.h"
#include "vksonar/renderer.h"

namespace vksonar {
struct VulkanContext;
struct HostDepthImage;
} // namespace vksonar

namespace vksonar::vk {

// The timed stages, in order. Each is recorded into its own command buffer so that, without
// timestamp queries, they can be submitted and timed one by one.
// One command buffer per stage of kStageTable, and one for the readback, in each frame slot.
constexpr std::uint32_t kCommandBufferCount = static_cast<std::uint32_t>(kStageCount) + 1;
// Frame slots: render-ahead has up to two frames on the device (start() twice, then finish()), each
// with its own command buffers, fence, queries, sub-pixel upload and readback buffer.
constexpr std::uint32_t kFrameSlots = 2;
// Timestamps, per slot (from slot * kQueryCount): one before the first command buffer and one after
// each, then (StageTiming::passes) one after each pass of the beamform stage.
constexpr std::uint32_t kPassQueryBase = kCommandBufferCount + 1;
constexpr std::uint32_t kQueryCount = kPassQueryBase + static_cast<std::uint32_t>(kMaxDispatches);

constexpr VkPipelineStageFlags kComputeOrTransfer =
    VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT;
constexpr VkAccessFlags kShaderOrTransferRead = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_TRANSFER_READ_BIT;

// Whether every dispatch of the stages the plan runs (kStageTable's, on the backend's own path or on
// the host-depth path) fits the device's workgroup counts.
bool dispatches_fit(const Plan& plan, const DeviceShape& shape, const VkPhysicalDeviceLimits& limits, bool host_depth);

template <class T> std::size_t bytes_of(const std::vector<T>& v) {
    return v.size() * sizeof(T);
}

// Where each array lives inside the single readback buffer.
struct Region {
    VkDeviceSize offset = 0;
    VkDeviceSize bytes = 0;
};

class HostDepthPass; // host_depth.cpp: runs these stages on a host engine's depth image
class VulkanBackend;

// What a stage's record function (kStageTable's vulkan / host_depth) records into.
struct RecordContext {
    VulkanBackend& backend;
    VkCommandBuffer commands;
    Dispatches dispatches;                 // the stage's, for the backend's plan
    HostDepthPass* host_depth = nullptr;   // the host-depth path: its import pass ...
    const HostDepthImage* image = nullptr; // ... and the host's image of this ping
};

class VulkanBackend final : public StageBackend {
    friend class HostDepthPass; // reuses the compute stages, buffers and readback without the depth pass
    friend void record_depth(RecordContext& record);
    friend void record_normals(RecordContext& record);
    friend void record_echo(RecordContext& record);
    friend void record_beamform(RecordContext& record);

public:
    VulkanBackend(VulkanContext& context, const Plan& plan, const SceneData& scene, const RendererOptions& options)
        : context_(context), plan_(plan), scene_(scene), options_(options) {}
    ~VulkanBackend() override;

    Result<void> init();
    Result<void> render(const Pose& pose, SaveFlags save_mask, Frame& frame) override;
    bool renders_ahead() const override { return true; }
    Result<void> start(const Pose& pose, SaveFlags save_mask, bool keep_last, bool overlap) override;
    Result<void> finish(Frame& frame) override;
    const char* name() const override { return "vulkan"; }
    const SubpixelReturns* subpixel_returns() const override { return &subpixel_returns_[read_slot_]; }
    void defer_clean(bool defer) override { defer_clean_ = defer; }
    void set_gpu_overlap(void (*work)(void*), void* context) override {
        overlap_work_ = work;
        overlap_context_ = context;
    }
    const float* pending_clean() const override;

private:
    Result<void> create_scene_buffers();
    Result<void> create_depth_pass();
    Result<void> create_compute(); // the steps below, in order
    // Each table's uniform view in vec4s (0: read through its storage binding; pipelines.h).
    struct TableViews {
        std::uint32_t materials = 0, column_table = 0, beam_table = 0, sidelobe = 0, far_table = 0;
    };
    Result<void> create_working_buffers();
    Result<TableViews> upload_tables();
    Result<void> create_readback();
    Result<void> create_descriptors(const TableViews& views);
    Result<void> create_compute_pipelines(const TableViews& views);
    Result<void> create_commands();

    // (The stages' commands are kStageTable's record functions, the friends above.)
    // The polar scan, then the buffers of the saved images (kStageTable's saved), into readbacks_[slot].
    void record_readback(VkCommandBuffer commands, SaveFlags save_mask, std::uint32_t slot = 0);
    // The slot's sub-pixel list (written by the host) into subpixel_, which profile.comp reads.
    void record_subpixel_upload(VkCommandBuffer commands, std::uint32_t slot);
    struct Saved {
        const Buffer* buffer = nullptr; // null: not one of the Frame's images
        const Region* region = nullptr;
    };
    Saved saved_buffer(StageBuffers buffer) const;
    void bind_compute(VkCommandBuffer commands, VkPipeline pipeline);
    void compute_barrier(VkCommandBuffer commands, const Buffer& written);
    void dispatch(VkCommandBuffer commands, const Dispatch& groups);

    // Submits on the slot's fence; overlap: then runs overlap_work_ (before anyone waits); wait_semaphore
    // (not null): the submission's compute work waits for it (a host depth image's). wait: for the slot's
    // fence.
    Result<void> submit(const VkCommandBuffer* command_buffers, std::uint32_t count, std::uint32_t slot,
                        bool overlap = false, VkSemaphore wait_semaphore = VK_NULL_HANDLE);
    Result<void> wait(std::uint32_t slot);
    void copy_out(const Region& region, void* destination) const;
    // The read-back frame's status word (sonar_shared.h kBindingStatus): an error where a shader found its
    // work cut short, for render() to refuse the frame.
    [[nodiscard]] Result<void> frame_status() const;
    // copy_clean = false: frame.clean is left to the noise stage (defer_clean, pending_clean)
    void copy_frame_out(SaveFlags save_mask, Frame& frame, bool copy_clean = true) const;
    // Copies an outer x inner float array (rows `stride` apart) out of the readback buffer as inner x outer.
    void transpose_out(const Region& region, std::uint32_t outer, std::uint32_t inner, std::uint32_t stride,
                       float* destination) const;

    VulkanContext& context_;
    Plan plan_; // a copy: the backend must not depend on where the caller keeps its plan
    const SceneData& scene_;
    RendererOptions options_; // the Vulkan paths (tables, resample, layout, stage_timing)
    DeviceShape shape_;       // from the device type and options_.layout (resolve_passes)
    // Which optional passes run, from the plan's effects (init and the host-depth path both call it).
    void resolve_passes();
    bool incidence_ = false, sidelobes_ = false;
    bool far_sidelobes_ = false; // plan_.far_cells > 0: far_sidelobe.comp runs before sidelobe.comp
    bool face_normals_ = false;  // plan_.face_normals: the depth pass has the face-normal attachment
    bool timestamps_ = false;
    bool defer_clean_ = false;
    // start() keeps each slot's stage command buffers but the depth pass's from frame to frame (recorded
    // with this save mask); the host-depth path, which records its own into slot 0's, clears them
    std::array<bool, kFrameSlots> commands_kept_{};
    std::array<SaveFlags, kFrameSlots> kept_save_mask_{};
    void (*overlap_work_)(void*) = nullptr; // set_gpu_overlap: run between the submission and the wait
    void* overlap_context_ = nullptr;
    // StageTiming::passes: a timestamp after each beamform pass (pass_timestamp), host clocks around the
    // host's steps; Frame::times gets both as extra entries.
    bool pass_timestamps_ = false;
    std::uint32_t passes_recorded_ = 0;
    std::uint32_t query_base_ = 0; // the slot being recorded: its first query
    std::array<const char*, kMaxDispatches> pass_names_{};
    void pass_timestamp(VkCommandBuffer commands, const char* name);
    // The host-depth path (host_depth.cpp) records the beamform stage outside start(), into slot 0's
    // queries: reset_pass_queries resets them (before any pass_timestamp of the ping), mark_stage_start
    // writes the stage's start into query `stage_query`, and add_pass_times appends the passes' times
    // to frame.times once the recorded work has finished. Without pass timestamps all three do nothing.
    void reset_pass_queries(VkCommandBuffer commands);
    void mark_stage_start(VkCommandBuffer commands, std::uint32_t stage_query);
    Result<void> add_pass_times(std::uint32_t stage_query, Frame& frame) const;

    std::vector<DepthCluster> clusters_;         // the scene's draws as runs of triangles (core/plan.h)
    std::vector<shared::DepthPush> draw_pushes_; // slices * draws, refilled every frame
    std::vector<std::uint8_t> clusters_drawn_;   // slices * clusters: 0 = culled this frame
    // each slot's frame's sub-pixel returns (core/subpixel.h)
    std::array<SubpixelReturns, kFrameSlots> subpixel_returns_;

    Buffer vertices_, indices_;
    Image depth_image_, material_image_;
    Image face_normal_image_; // normal_method = geometric only
    OwnedRenderPass render_pass_;
    OwnedFramebuffer framebuffer_;
    OwnedPipelineLayout depth_layout_;
    OwnedPipeline depth_pipeline_;

    Buffer params_, depth_, material_id_, normals_, echo_, profiles_, beam_profiles_, polar_;
    Buffer slice_info_, materials_, column_table_, beam_table_, sidelobe_weight_;
    Buffer cone_coord_;                         // line_array: Plan::pixel_cone_coord (a 16-byte stand-in when planar)
    Buffer far_table_, far_energy_, far_cells_; // far side lobes (16-byte stand-ins without them)
    Buffer status_; // the frame's status word (sonar_shared.h kBindingStatus), read back with the frame
    // subpixel_returns_'s list: written by the host into the slot's upload buffer, copied by the slot's
    // first command buffer into subpixel_ (so a frame queued behind another cannot overwrite what that
    // one reads); 16 bytes each without any
    Buffer subpixel_;
    std::array<Buffer, kFrameSlots> subpixel_uploads_;
    // Host-visible: what a frame reads back (Region), per slot: while the host still reads the frame
    // finished last (read_slot_), the next one renders into the other. Slot 1 is touched only by
    // render-ahead.
    std::array<Buffer, kFrameSlots> readbacks_;
    std::uint32_t read_slot_ = 0; // the slot of the frame finished last: copy_out, pending_clean
    const Buffer& readback() const { return readbacks_[read_slot_]; }
    Region polar_region_, depth_region_, material_region_, normals_region_, echo_region_, profiles_region_,
        beam_profiles_region_, status_region_;

    OwnedDescriptorSetLayout set_layout_;
    OwnedPipelineLayout compute_layout_;
    // profile.comp's dispatches: the rows of each (profile_bands.h), at least one band
    std::vector<shared::ProfileRowBand> profile_bands_;
    OwnedDescriptorPool descriptor_pool_;
    VkDescriptorSet descriptor_set_ = VK_NULL_HANDLE; // freed with the pool
    shared::SonarParams gpu_params_{};                // plan_.params plus the GPU-only layout fields
    OwnedPipeline normals_pipeline_, echo_pipeline_, profile_pipeline_, resample_pipeline_, sidelobe_pipeline_;
    OwnedPipeline far_deposit_pipeline_, far_convolve_pipeline_;

    OwnedCommandPool command_pool_;
    // per slot; freed with the pool
    std::array<std::array<VkCommandBuffer, kCommandBufferCount>, kFrameSlots> command_buffers_{};
    std::array<OwnedFence, kFrameSlots> fences_;
    // Whether the slot's fence guards a submission (set by a successful submit). submit() resets the
    // fence before vkQueueSubmit; if that fails, nothing will ever signal it, so wait() and the
    // destructor wait only on a fence that has work behind it.
    std::array<bool, kFrameSlots> fence_submitted_{};
    // Between start() and finish(): the frame on the device in slot i (in_flight_[i]), and what finish()
    // reports of it.
    struct InFlight {
        bool active = false;
        std::uint32_t stage_total = 0;
        SaveFlags save_mask = SaveFlags::none;
        std::array<const StageInfo*, kStageCount> stages{};
        std::array<double, kCommandBufferCount> stage_ms{}; // host-timed: measured by start()
        std::array<double, 4> host_ms{};                    // prepare, record, gpu_wait, copy
        std::chrono::steady_clock::time_point host_clock{};
    };
    std::array<InFlight, kFrameSlots> in_flight_;
    std::uint32_t oldest_ = 0; // the slot finish() finishes next, when in flight
    OwnedQueryPool query_pool_;
};

} // namespace vksonar::vk
