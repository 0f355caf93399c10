// The Vulkan StageBackend, per frame: kStageTable's record functions, defined here (depth pass, one
// render pass with one viewport per slice, copied to storage buffers -> normals -> echo -> profile ->
// resample -> far side lobes -> sidelobe), then the readback. Nothing is created here; render()
// records, submits, waits and copies out.
#include <chrono>
#include <cstring>
#include <string>

#include "core/half.h"
#include "vk/commands.h"
#include "vk/vk_error.h"
#include "vk/vulkan_backend_impl.h"
#include "vk/vulkan_context.h"

namespace vksonar::vk {

void VulkanBackend::bind_compute(VkCommandBuffer commands, VkPipeline pipeline) {
    context_.fn.vkCmdBindPipeline(commands, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline);
    context_.fn.vkCmdBindDescriptorSets(commands, VK_PIPELINE_BIND_POINT_COMPUTE, compute_layout_.get(), 0, 1,
                                        &descriptor_set_, 0, nullptr);
}

// A compute stage's output becomes readable by the next compute stage and by the readback copies.
void VulkanBackend::compute_barrier(VkCommandBuffer commands, const Buffer& written) {
    VkBufferMemoryBarrier barrier = buffer_barrier(written.get(), VK_ACCESS_SHADER_WRITE_BIT, kShaderOrTransferRead);
    pipeline_barrier(context_, commands, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, kComputeOrTransfer, 1, &barrier);
}

// The depth pass: one render pass, one viewport per slice, then its images copied to the buffers the
// compute stages read.
void record_depth(RecordContext& record) {
    VulkanBackend& b = record.backend;
    VkCommandBuffer commands = record.commands;
    const Functions& fn = b.context_.fn;
    std::array<VkClearValue, 3> clears{};
    clears[0].color.uint32[0] = shared::kNoMaterial;
    clears[1].depthStencil = {0.0f, 0}; // reversed-Z: 0 is the far plane / no hit
    clears[2].color.float32[0] = 0.0f;  // face normals (geometric only): 0 = none
    VkRenderPassBeginInfo begin{};
    begin.sType = VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO;
    begin.renderPass = b.render_pass_.get();
    begin.framebuffer = b.framebuffer_.get();
    begin.renderArea = {{0, 0}, {b.plan_.columns, b.plan_.rows}};
    begin.clearValueCount = b.face_normals_ ? 3u : 2u;
    begin.pClearValues = clears.data();
    fn.vkCmdBeginRenderPass(commands, &begin, VK_SUBPASS_CONTENTS_INLINE);
    const std::size_t draws = b.scene_.draws.size(), clusters = b.clusters_.size();
    if (clusters > 0) {
        fn.vkCmdBindPipeline(commands, VK_PIPELINE_BIND_POINT_GRAPHICS, b.depth_pipeline_.get());
        VkBuffer vertex_buffer = b.vertices_.get();
        VkDeviceSize zero = 0;
        fn.vkCmdBindVertexBuffers(commands, 0, 1, &vertex_buffer, &zero);
        fn.vkCmdBindIndexBuffer(commands, b.indices_.get(), 0, VK_INDEX_TYPE_UINT32);
        for (std::uint32_t s = 0; s < b.plan_.views; ++s) {
            const std::uint32_t first = view_first_column(b.plan_, s), width = view_columns(b.plan_, s);
            VkViewport viewport{float(first), 0.0f, float(width), float(b.plan_.rows), 0.0f, 1.0f};
            VkRect2D scissor{{static_cast<std::int32_t>(first), 0}, {width, b.plan_.rows}};
            fn.vkCmdSetViewport(commands, 0, 1, &viewport);
            fn.vkCmdSetScissor(commands, 0, 1, &scissor);
            std::uint32_t pushed_draw = ~0u; // clusters of one draw are consecutive: one push for them all
            for_each_depth_draw_call(
                b.clusters_, b.clusters_drawn_.data() + s * clusters, [&](const DepthDrawCall& call) {
                    const std::uint32_t draw = b.clusters_[call.cluster].draw;
                    if (draw != pushed_draw) {
                        fn.vkCmdPushConstants(commands, b.depth_layout_.get(),
                                              VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT, 0,
                                              sizeof(shared::DepthPush), &b.draw_pushes_[s * draws + draw]);
                        pushed_draw = draw;
                    }
                    fn.vkCmdDrawIndexed(commands, call.index_count, 1, call.first_index,
                                        static_cast<std::int32_t>(call.first_vertex), 0);
                });
        }
    }
    fn.vkCmdEndRenderPass(commands); // leaves both images in TRANSFER_SRC_OPTIMAL (render pass dependency 1)

    VkBufferImageCopy region{};
    region.imageSubresource = {VK_IMAGE_ASPECT_DEPTH_BIT, 0, 0, 1};
    region.imageExtent = {b.plan_.columns, b.plan_.rows, 1};
    fn.vkCmdCopyImageToBuffer(commands, b.depth_image_.get(), VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, b.depth_.get(), 1,
                              &region);
    region.imageSubresource.aspectMask = VK_IMAGE_ASPECT_COLOR_BIT;
    fn.vkCmdCopyImageToBuffer(commands, b.material_image_.get(), VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL,
                              b.material_id_.get(), 1, &region);
    std::uint32_t barrier_count = 2;
    std::array<VkBufferMemoryBarrier, 3> barriers{
        buffer_barrier(b.depth_.get(), VK_ACCESS_TRANSFER_WRITE_BIT, kShaderOrTransferRead),
        buffer_barrier(b.material_id_.get(), VK_ACCESS_TRANSFER_WRITE_BIT, kShaderOrTransferRead),
        {}};
    if (b.face_normals_) { // into the normals buffer, which the normals pass then orients in place
        fn.vkCmdCopyImageToBuffer(commands, b.face_normal_image_.get(), VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL,
                                  b.normals_.get(), 1, &region);
        barriers[barrier_count++] = buffer_barrier(b.normals_.get(), VK_ACCESS_TRANSFER_WRITE_BIT,
                                                   VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
    }
    pipeline_barrier(b.context_, commands, VK_PIPELINE_STAGE_TRANSFER_BIT, kComputeOrTransfer, barrier_count,
                     barriers.data());
}

void record_normals(RecordContext& record) {
    VulkanBackend& b = record.backend;
    b.bind_compute(record.commands, b.normals_pipeline_.get());
    b.dispatch(record.commands, record.dispatches[0]);
    b.compute_barrier(record.commands, b.normals_);
}

void record_echo(RecordContext& record) {
    VulkanBackend& b = record.backend;
    b.bind_compute(record.commands, b.echo_pipeline_.get());
    b.dispatch(record.commands, record.dispatches[0]);
    b.compute_barrier(record.commands, b.echo_);
}

void record_beamform(RecordContext& record) {
    using namespace stage_table; // the BeamformDispatch indices
    VulkanBackend& b = record.backend;
    VkCommandBuffer commands = record.commands;
    const Functions& fn = b.context_.fn;
    // profile.comp accumulates into zeroed profiles, and sets bits of a zeroed status word.
    fn.vkCmdFillBuffer(commands, b.profiles_.get(), 0, VK_WHOLE_SIZE, 0);
    fn.vkCmdFillBuffer(commands, b.status_.get(), 0, VK_WHOLE_SIZE, 0);
    const std::array<VkBufferMemoryBarrier, 2> zeroed{
        buffer_barrier(b.profiles_.get(), VK_ACCESS_TRANSFER_WRITE_BIT,
                       VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT),
        buffer_barrier(b.status_.get(), VK_ACCESS_TRANSFER_WRITE_BIT,
                       VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT)};
    pipeline_barrier(b.context_, commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                     std::uint32_t(zeroed.size()), zeroed.data());
    b.bind_compute(commands, b.profile_pipeline_.get());
    // the rows in bands, one dispatch each, each adding after the one before (profile_bands.h)
    for (const shared::ProfileRowBand& band : b.profile_bands_) {
        fn.vkCmdPushConstants(commands, b.compute_layout_.get(), VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof band, &band);
        b.dispatch(commands, record.dispatches[profile]);
        b.compute_barrier(commands, b.profiles_);
    }
    b.compute_barrier(commands, b.status_);
    b.pass_timestamp(commands, "bf:profile");

    fn.vkCmdBindPipeline(commands, VK_PIPELINE_BIND_POINT_COMPUTE, b.resample_pipeline_.get());
    b.dispatch(commands, record.dispatches[resample]);
    b.compute_barrier(commands, b.beam_profiles_);
    b.pass_timestamp(commands, "bf:resample");
    if (b.far_sidelobes_) { // sidelobe.comp reads the result
        fn.vkCmdBindPipeline(commands, VK_PIPELINE_BIND_POINT_COMPUTE, b.far_deposit_pipeline_.get());
        b.dispatch(commands, record.dispatches[far_deposit]);
        b.compute_barrier(commands, b.far_energy_);
        b.pass_timestamp(commands, "bf:far_deposit");
        fn.vkCmdBindPipeline(commands, VK_PIPELINE_BIND_POINT_COMPUTE, b.far_convolve_pipeline_.get());
        b.dispatch(commands, record.dispatches[far_convolve]);
        b.compute_barrier(commands, b.far_cells_);
        b.pass_timestamp(commands, "bf:far_convolve");
    }
    if (b.sidelobes_) {
        fn.vkCmdBindPipeline(commands, VK_PIPELINE_BIND_POINT_COMPUTE, b.sidelobe_pipeline_.get());
        b.dispatch(commands, record.dispatches[sidelobe]);
        b.compute_barrier(commands, b.polar_);
        b.pass_timestamp(commands, "bf:sidelobe");
    }
}

void VulkanBackend::pass_timestamp(VkCommandBuffer commands, const char* name) {
    if (!pass_timestamps_ || passes_recorded_ >= kMaxDispatches) return;
    pass_names_[passes_recorded_] = name;
    context_.fn.vkCmdWriteTimestamp(commands, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, query_pool_.get(),
                                    query_base_ + kPassQueryBase + passes_recorded_);
    ++passes_recorded_;
}

void VulkanBackend::reset_pass_queries(VkCommandBuffer commands) {
    if (!pass_timestamps_) return;
    query_base_ = 0;
    passes_recorded_ = 0;
    context_.fn.vkCmdResetQueryPool(commands, query_pool_.get(), 0, kQueryCount);
}

void VulkanBackend::mark_stage_start(VkCommandBuffer commands, std::uint32_t stage_query) {
    if (!pass_timestamps_) return;
    context_.fn.vkCmdWriteTimestamp(commands, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, query_pool_.get(), stage_query);
}

Result<void> VulkanBackend::add_pass_times(std::uint32_t stage_query, Frame& frame) const {
    if (!pass_timestamps_ || passes_recorded_ == 0) return {};
    std::array<std::uint64_t, kMaxDispatches> ticks{};
    std::uint64_t from = 0;
    VKS_VK_TRY(context_.fn.vkGetQueryPoolResults(context_.device, query_pool_.get(), stage_query, 1,
                                                 sizeof(std::uint64_t), &from, sizeof(std::uint64_t),
                                                 VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT));
    VKS_VK_TRY(context_.fn.vkGetQueryPoolResults(
        context_.device, query_pool_.get(), kPassQueryBase, passes_recorded_, sizeof(std::uint64_t) * passes_recorded_,
        ticks.data(), sizeof(std::uint64_t), VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT));
    const std::uint64_t mask = context_.timestamp_valid_bits >= 64
                                   ? ~std::uint64_t(0)
                                   : (std::uint64_t(1) << context_.timestamp_valid_bits) - 1;
    const double ns_per_tick = context_.properties.limits.timestampPeriod;
    for (std::uint32_t n = 0; n < passes_recorded_; ++n) { // each from the end of the one before
        const double ms = double(((ticks[n] & mask) - (from & mask)) & mask) * ns_per_tick * 1e-6;
        frame.times.push_back(StageTime{pass_names_[n], ms});
        from = ticks[n];
    }
    return {};
}

void VulkanBackend::dispatch(VkCommandBuffer commands, const Dispatch& groups) {
    context_.fn.vkCmdDispatch(commands, groups.x, groups.y, groups.z);
}

VulkanBackend::Saved VulkanBackend::saved_buffer(StageBuffers buffer) const {
    switch (buffer) {
    case StageBuffers::depth:
        return {&depth_, &depth_region_};
    case StageBuffers::material:
        return {&material_id_, &material_region_};
    case StageBuffers::normals:
        return {&normals_, &normals_region_};
    case StageBuffers::echo:
        return {&echo_, &echo_region_};
    case StageBuffers::profiles:
        return {&profiles_, &profiles_region_};
    case StageBuffers::beam_profiles:
        return {&beam_profiles_, &beam_profiles_region_};
    default:
        return {};
    }
}

void VulkanBackend::record_readback(VkCommandBuffer commands, SaveFlags save_mask, std::uint32_t slot) {
    VkBuffer target = readbacks_[slot].get();
    auto copy = [&](const Buffer& source, const Region& region) {
        if (region.bytes == 0) return;
        VkBufferCopy copy_region{0, region.offset, region.bytes};
        context_.fn.vkCmdCopyBuffer(commands, source.get(), target, 1, &copy_region);
    };
    copy(sidelobes_ ? polar_ : beam_profiles_, polar_region_);
    copy(status_, status_region_);
    for (const StageInfo& stage : kStageTable) {
        if (!any(save_mask & stage.saves) || !stage.runs(plan_)) continue; // copy_frame_out zeroes what did not run
        for_each_buffer(stage.saved, [&](StageBuffers buffer) {
            const Saved saved = saved_buffer(buffer);
            if (saved.buffer != nullptr) copy(*saved.buffer, *saved.region);
        });
    }
    VkBufferMemoryBarrier barrier = buffer_barrier(target, VK_ACCESS_TRANSFER_WRITE_BIT, VK_ACCESS_HOST_READ_BIT);
    pipeline_barrier(context_, commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 1, &barrier);
}

Result<void> VulkanBackend::submit(const VkCommandBuffer* command_buffers, std::uint32_t count, std::uint32_t slot,
                                   bool overlap, VkSemaphore wait_semaphore) {
    VkSubmitInfo submit{};
    submit.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    submit.commandBufferCount = count;
    submit.pCommandBuffers = command_buffers;
    const VkPipelineStageFlags wait_stage = VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT;
    if (wait_semaphore != VK_NULL_HANDLE) {
        submit.waitSemaphoreCount = 1;
        submit.pWaitSemaphores = &wait_semaphore;
        submit.pWaitDstStageMask = &wait_stage;
    }
    VkFence fence = fences_[slot].get();
    VKS_VK_TRY(context_.fn.vkResetFences(context_.device, 1, &fence));
    fence_submitted_[slot] = false; // unsignalled until a submission succeeds
    VKS_VK_TRY(queue_submit(context_, submit, fence));
    fence_submitted_[slot] = true;
    if (overlap && overlap_work_ != nullptr) overlap_work_(overlap_context_);
    return {};
}

Result<void> VulkanBackend::wait(std::uint32_t slot) {
    if (!fence_submitted_[slot]) {
        return make_error(ErrorCode::internal, "VulkanBackend::wait: nothing was submitted in frame slot " +
                                                   std::to_string(slot) + " (its submission failed)");
    }
    VkFence fence = fences_[slot].get();
    VKS_VK_TRY(context_.fn.vkWaitForFences(context_.device, 1, &fence, VK_TRUE, UINT64_MAX));
    return {};
}

void VulkanBackend::record_subpixel_upload(VkCommandBuffer commands, std::uint32_t slot) {
    const Functions& fn = context_.fn;
    // The frame before (queued ahead of this one) may still read subpixel_ in its profile pass (WAR:
    // an execution dependency suffices).
    fn.vkCmdPipelineBarrier(commands, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0,
                            nullptr, 0, nullptr, 0, nullptr);
    // the header and this frame's returns only (the list holds up to 4 MiB, and the upload buffer is
    // host memory the device reads across the bus)
    const VkBufferCopy region{0, 0, subpixel_returns_[slot].written_bytes(plan_)};
    fn.vkCmdCopyBuffer(commands, subpixel_uploads_[slot].get(), subpixel_.get(), 1, &region);
    VkBufferMemoryBarrier copied =
        buffer_barrier(subpixel_.get(), VK_ACCESS_TRANSFER_WRITE_BIT, VK_ACCESS_SHADER_READ_BIT);
    pipeline_barrier(context_, commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 1,
                     &copied);
}

Result<void> VulkanBackend::frame_status() const {
    std::uint32_t status = 0;
    copy_out(status_region_, &status);
    if ((status & shared::kStatusLoopLimit) != 0) // profile.comp loops_ran_out
        return make_error(ErrorCode::unsupported,
                          "Vulkan device: profile.comp's loops were ended before its rows were done (lavapipe ends an "
                          "invocation's loops after 65535 iterations): the frame would miss pixels; render with "
                          "--backend cpu (the same frame), or with fewer accuracy.rows_per_vfov or range bins, or a "
                          "larger accuracy.pixels_per_beam (a pixel's range footprint spans more of narrower bins, "
                          "and a wider pixel's more)");
    return {};
}

void VulkanBackend::copy_out(const Region& region, void* destination) const {
    std::memcpy(destination, static_cast<const char*>(readback().mapped) + region.offset, region.bytes);
}

void VulkanBackend::transpose_out(const Region& region, std::uint32_t outer, std::uint32_t inner, std::uint32_t stride,
                                  float* destination) const {
    // source[o * stride + i] -> destination[i * outer + o], i < inner
    const auto* source = reinterpret_cast<const float*>(static_cast<const char*>(readback().mapped) + region.offset);
    for (std::size_t o = 0; o < outer; ++o)
        for (std::size_t i = 0; i < inner; ++i)
            destination[i * outer + o] = source[o * stride + i];
}

namespace {

// Resizes only if the caller's frame was not made for this plan (then the first frame allocates).
template <class T> T* sized(std::vector<T>& v, std::size_t n) {
    if (v.size() != n) v.resize(n);
    return v.data();
}

} // namespace

namespace {

double ms_since(std::chrono::steady_clock::time_point& start) {
    const auto now = std::chrono::steady_clock::now();
    const double ms = std::chrono::duration<double, std::milli>(now - start).count();
    start = now;
    return ms;
}

} // namespace

Result<void> VulkanBackend::render(const Pose& pose, SaveFlags save_mask, Frame& frame) {
    if (auto r = start(pose, save_mask, false, true); !r) return r;
    return finish(frame);
}

// Prepares, records and submits one frame's work into a frame slot and returns without waiting (with
// host timing, the stages are submitted and waited one by one here). The slot: the other one while a
// frame is on the device, or while the host still reads the frame finished last (keep_last), else 0.
Result<void> VulkanBackend::start(const Pose& pose, SaveFlags save_mask, bool keep_last, bool overlap) {
    std::uint32_t slot = 0;
    if (in_flight_[oldest_].active) {
        if (in_flight_[1 - oldest_].active)
            return make_error(ErrorCode::invalid_argument, "VulkanBackend::start: two frames are on the device");
        slot = 1 - oldest_;
    } else {
        slot = keep_last ? 1 - read_slot_ : 0;
        oldest_ = slot;
    }
    InFlight& flight = in_flight_[slot];
    // StageTiming::passes: the host's own steps; otherwise the clock is not read
    if (pass_timestamps_) flight.host_clock = std::chrono::steady_clock::now();
    compose_depth_draws(plan_, scene_, pose, draw_pushes_);
    cull_depth_clusters(clusters_, scene_.draws.size(), draw_pushes_, clusters_drawn_);
    // the objects a few pixels across or less: their returns (profile.comp adds them) instead of their
    // pixels' echo
    SubpixelReturns& subpixel = subpixel_returns_[slot];
    subpixel.build(plan_, scene_, pose, clusters_, draw_pushes_, clusters_drawn_);
    if (plan_.subpixel_capacity > 0) subpixel.write_buffer(plan_, subpixel_uploads_[slot].mapped);

    // Record: one command buffer per stage of kStageTable that this plan runs, then one for the readback.
    std::array<const StageInfo*, kStageCount>& stages = flight.stages;
    std::uint32_t stage_total = 0;
    for (const StageInfo& stage : kStageTable)
        if (stage.runs(plan_)) stages[stage_total++] = &stage;
    flight.stage_total = stage_total;
    const std::uint32_t buffer_total = stage_total + 1; // the readback last

    if (pass_timestamps_) flight.host_ms[0] = ms_since(flight.host_clock);
    // Only the depth pass's commands change from frame to frame (its draws follow the pose); the other
    // stages' and the readback's are recorded once per slot and submitted again, until the save mask
    // changes.
    const bool keep = commands_kept_[slot] && kept_save_mask_[slot] == save_mask;
    // Re-recording: not kept until every buffer is recorded again, so that a Begin/End failing partway
    // leaves the slot to be recorded in full next time, not half of it submitted as kept.
    if (!keep) {
        passes_recorded_ = 0;
        commands_kept_[slot] = false;
    }
    query_base_ = slot * kQueryCount;
    const std::array<VkCommandBuffer, kCommandBufferCount>& recorded = command_buffers_[slot];
    for (std::uint32_t i = 0; i < buffer_total; ++i) {
        VkCommandBuffer commands = recorded[i];
        // the first buffer resets the queries and uploads the sub-pixel list; the depth pass draws this
        // frame's clusters
        const bool per_frame = i == 0 || (i < stage_total && stages[i]->vulkan.record == record_depth);
        if (keep && !per_frame) continue;
        VkCommandBufferBeginInfo begin{}; // resets the buffer (the pool lets each buffer reset alone)
        begin.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
        begin.flags = per_frame ? VkCommandBufferUsageFlags(VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT) : 0u;
        VKS_VK_TRY(context_.fn.vkBeginCommandBuffer(commands, &begin));
        if (timestamps_ && i == 0) {
            context_.fn.vkCmdResetQueryPool(commands, query_pool_.get(), query_base_, kQueryCount);
            context_.fn.vkCmdWriteTimestamp(commands, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, query_pool_.get(),
                                            query_base_);
        }
        if (i == 0 && subpixel.written_bytes(plan_) > 0) record_subpixel_upload(commands, slot);
        if (i < stage_total) {
            RecordContext record{*this, commands, stages[i]->vulkan.dispatches(plan_, shape_)};
            stages[i]->vulkan.record(record);
        } else {
            record_readback(commands, save_mask, slot);
        }
        if (timestamps_) {
            context_.fn.vkCmdWriteTimestamp(commands, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, query_pool_.get(),
                                            query_base_ + i + 1);
        }
        VKS_VK_TRY(context_.fn.vkEndCommandBuffer(commands));
    }
    commands_kept_[slot] = true;
    kept_save_mask_[slot] = save_mask;
    flight.save_mask = save_mask;

    // Submit: all at once with timestamps, else one command buffer at a time, timed on the host.
    if (pass_timestamps_) flight.host_ms[1] = ms_since(flight.host_clock);
    if (timestamps_) {
        if (auto r = submit(recorded.data(), buffer_total, slot, overlap); !r) return r;
    } else {
        for (std::uint32_t i = 0; i < buffer_total; ++i) {
            const auto begin = std::chrono::steady_clock::now();
            // the overlap work while the readback (last, not a reported stage) copies
            if (auto r = submit(&recorded[i], 1, slot, overlap && i + 1 == buffer_total); !r) return r;
            if (auto r = wait(slot); !r) return r;
            flight.stage_ms[i] =
                std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - begin).count();
        }
    }
    flight.active = true;
    return {};
}

// Waits for the oldest frame start() submitted and fills `frame` from its readback slot.
Result<void> VulkanBackend::finish(Frame& frame) {
    const std::uint32_t slot = oldest_;
    InFlight& flight = in_flight_[slot];
    if (!flight.active) return make_error(ErrorCode::invalid_argument, "VulkanBackend::finish: no frame started");
    flight.active = false;
    if (in_flight_[1 - slot].active) oldest_ = 1 - slot;
    frame.times.clear();
    frame.stages_run.clear();
    const std::uint32_t stage_total = flight.stage_total, buffer_total = stage_total + 1;
    std::array<double, kMaxDispatches> pass_ms{};
    if (timestamps_) {
        if (auto r = wait(slot); !r) return r;
        if (pass_timestamps_) flight.host_ms[2] = ms_since(flight.host_clock);
        const std::uint32_t base = slot * kQueryCount;
        std::array<std::uint64_t, kQueryCount> ticks{};
        VKS_VK_TRY(context_.fn.vkGetQueryPoolResults(
            context_.device, query_pool_.get(), base, buffer_total + 1, sizeof(std::uint64_t) * ticks.size(),
            ticks.data(), sizeof(std::uint64_t), VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT));
        if (passes_recorded_ > 0) {
            VKS_VK_TRY(context_.fn.vkGetQueryPoolResults(context_.device, query_pool_.get(), base + kPassQueryBase,
                                                         passes_recorded_, sizeof(std::uint64_t) * passes_recorded_,
                                                         ticks.data() + kPassQueryBase, sizeof(std::uint64_t),
                                                         VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT));
        }
        const std::uint64_t mask = context_.timestamp_valid_bits >= 64
                                       ? ~std::uint64_t(0)
                                       : (std::uint64_t(1) << context_.timestamp_valid_bits) - 1;
        const double ns_per_tick = context_.properties.limits.timestampPeriod;
        auto interval_ms = [&](std::uint64_t from, std::uint64_t to) {
            return double(((to & mask) - (from & mask)) & mask) * ns_per_tick * 1e-6;
        };
        for (std::uint32_t i = 0; i < buffer_total; ++i)
            flight.stage_ms[i] = interval_ms(ticks[i], ticks[i + 1]);
        // The passes of the beamform stage, each from the end of the one before (the first from the end
        // of the command buffer before the stage's).
        for (std::uint32_t i = 0; i < stage_total && passes_recorded_ > 0; ++i) {
            if (std::strcmp(flight.stages[i]->name, "beamform") != 0) continue;
            std::uint64_t from = ticks[i];
            for (std::uint32_t n = 0; n < passes_recorded_; ++n) {
                pass_ms[n] = interval_ms(from, ticks[kPassQueryBase + n]);
                from = ticks[kPassQueryBase + n];
            }
        }
    }
    read_slot_ = slot;
    if (auto r = frame_status(); !r) return r; // refused, not passed on with rows missing
    // the readback is a transfer, not a stage of the pipeline: not reported
    for (std::uint32_t i = 0; i < stage_total; ++i) {
        const char* name = flight.stages[i]->name;
        frame.times.push_back(StageTime{name, flight.stage_ms[i]});
        frame.stages_run.emplace_back(name);
    }

    copy_frame_out(flight.save_mask, frame, !defer_clean_);
    if (pass_timestamps_) { // the names fit std::string's inline buffer: no allocation
        for (std::uint32_t n = 0; n < passes_recorded_; ++n)
            frame.times.push_back(StageTime{pass_names_[n], pass_ms[n]});
        flight.host_ms[3] = ms_since(flight.host_clock);
        const std::array<const char*, 4> host_steps{"host:prepare", "host:record", "host:gpu_wait", "host:copy"};
        for (std::size_t s = 0; s < host_steps.size(); ++s)
            frame.times.push_back(StageTime{host_steps[s], flight.host_ms[s]});
    }
    return {};
}

// Copies what this frame saved out of the (coherent) readback buffer into `frame`, converting the GPU
// layouts to the public ones. Also used by the host-depth pass (host_depth.cpp).
const float* VulkanBackend::pending_clean() const {
    return defer_clean_
               ? reinterpret_cast<const float*>(static_cast<const char*>(readback().mapped) + polar_region_.offset)
               : nullptr;
}

void VulkanBackend::copy_frame_out(SaveFlags save_mask, Frame& frame, bool copy_clean) const {
    const std::size_t pixels = std::size_t(plan_.columns) * plan_.rows;
    const std::size_t cells = std::size_t(plan_.bins) * plan_.beams;
    frame.beams = plan_.beams;
    frame.bins = plan_.bins;
    frame.columns = plan_.columns;
    frame.profile_columns = plan_.profile_columns;
    frame.rows = plan_.rows;
    if (copy_clean) {
        copy_out(polar_region_, sized(frame.clean, cells));
    } else {
        sized(frame.clean, cells); // filled by the noise stage from pending_clean()
    }
    if (any(save_mask & SaveFlags::depth)) {
        copy_out(depth_region_, sized(frame.depth, pixels));
        copy_out(material_region_, sized(frame.material, pixels));
    }
    if (any(save_mask & SaveFlags::normals)) {
        float* normals = sized(frame.normals, pixels * 4);
        if (incidence_) {
            copy_out(normals_region_, normals);
        } else {
            std::memset(normals, 0, pixels * 4 * sizeof(float)); // the normals pass did not run
        }
    }
    if (any(save_mask & SaveFlags::echo)) {
        float* echo = sized(frame.echo, pixels * 2);
        if (plan_.params.echo_half != 0u) { // two halves per pixel: (energy * echo_scale, range)
            const auto* halves = reinterpret_cast<const std::uint16_t*>(static_cast<const char*>(readback().mapped) +
                                                                        echo_region_.offset);
            for (std::size_t p = 0; p < pixels; ++p) {
                echo[2 * p] = half_to_float(halves[2 * p]) / plan_.params.echo_scale;
                echo[2 * p + 1] = half_to_float(halves[2 * p + 1]);
            }
        } else {
            copy_out(echo_region_, echo);
        }
    }
    if (any(save_mask & SaveFlags::profiles)) {
        // The GPU keeps profiles column-major (contiguous loads in resample.comp); the Frame holds the
        // public range-major layout.
        const std::uint32_t padded = gpu_params_.bins_padded;
        transpose_out(profiles_region_, plan_.profile_columns, plan_.bins, padded,
                      sized(frame.profiles, std::size_t(plan_.bins) * plan_.profile_columns));
        if (sidelobes_) { // beam-major, padded (resample.comp's layout when the side-lobe pass follows)
            transpose_out(beam_profiles_region_, plan_.beams, plan_.bins, padded, sized(frame.beam_profiles, cells));
        } else {
            copy_out(beam_profiles_region_, sized(frame.beam_profiles, cells));
        }
    }
}

} // namespace vksonar::vk
