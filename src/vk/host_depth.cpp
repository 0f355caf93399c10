// HostDepthPass: the Vulkan backend's compute stages on a host engine's depth image. The backend is
// created without its depth pass (no scene, no render pass); this file adds the import pass and the
// three ways to run: process (vksonar submits and waits), record (into the host's command buffer) and
// read_back (after the host's submission finished, detected through an event vksonar sets).
#include "vk/host_depth.h"

#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <string>
#include <utility>

#include "host_depth_shared.h"
#include "scene/scene_data.h"
#include "vk/commands.h"
#include "vk/handles.h"
#include "vk/pipelines.h"
#include "vk/vk_error.h"
#include "vk/vulkan_backend_impl.h"
#include "vk/vulkan_context.h"

#include "import_depth.comp.spv.h"

namespace vksonar::vk {

using OwnedEvent = Owned<VkEvent, &Functions::vkDestroyEvent>;

// Destroyed in reverse order of declaration; nothing is in use by then (see ~HostDepthPass), so the
// order only has to keep no_scene alive as long as the backend that references it.
struct HostDepthPass::Objects {
    SceneData no_scene; // the backend keeps a reference; it has no depth pass to draw it with
    std::unique_ptr<VulkanBackend> backend;
    HostDepthDesc desc;
    shared::ImportDepthPush push{};
    VkImageAspectFlags barrier_aspect = VK_IMAGE_ASPECT_DEPTH_BIT;
    OwnedDescriptorSetLayout image_set_layout;
    OwnedPipelineLayout import_layout;
    OwnedPipeline import_pipeline;
    OwnedDescriptorPool image_pool;
    VkDescriptorSet image_set = VK_NULL_HANDLE; // freed with image_pool
    OwnedEvent done;                            // set by the last command record() records
    bool recorded = false;
    SaveFlags recorded_mask = SaveFlags::none;
    std::uint32_t stage_query = 0; // record(): the query with the beamform stage's start
    enum class Armed { none, process, read_back } armed = Armed::none;
    HostDepthImage armed_image;
};

namespace {

bool is_depth_format(VkFormat format) {
    switch (format) {
    case VK_FORMAT_D16_UNORM:
    case VK_FORMAT_X8_D24_UNORM_PACK32:
    case VK_FORMAT_D32_SFLOAT:
    case VK_FORMAT_D16_UNORM_S8_UINT:
    case VK_FORMAT_D24_UNORM_S8_UINT:
    case VK_FORMAT_D32_SFLOAT_S8_UINT:
        return true;
    default:
        return false;
    }
}

bool has_stencil(VkFormat format) {
    return format == VK_FORMAT_D16_UNORM_S8_UINT || format == VK_FORMAT_D24_UNORM_S8_UINT ||
           format == VK_FORMAT_D32_SFLOAT_S8_UINT;
}

// Single-channel formats a host may keep depth in as colour (a G-buffer's linear depth, a depth copy).
bool is_colour_depth_format(VkFormat format) {
    return format == VK_FORMAT_R32_SFLOAT || format == VK_FORMAT_R16_SFLOAT || format == VK_FORMAT_R16_UNORM;
}

bool readable_layout(VkImageLayout layout) {
    return layout == VK_IMAGE_LAYOUT_GENERAL || layout == VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL ||
           layout == VK_IMAGE_LAYOUT_DEPTH_STENCIL_READ_ONLY_OPTIMAL ||
           layout == VK_IMAGE_LAYOUT_DEPTH_READ_ONLY_STENCIL_ATTACHMENT_OPTIMAL;
}

} // namespace

HostDepthPass::HostDepthPass() : objects_(std::make_unique<Objects>()) {}

HostDepthPass::~HostDepthPass() {
    // process() waits for its own work. Work recorded into the host's command buffer may still be
    // pending: the host must have finished it (documented on HostDepthRenderer); waiting for the event would
    // hang forever on a command buffer that was never submitted, so nothing is waited for here.
}

Result<std::unique_ptr<HostDepthPass>> HostDepthPass::create(VulkanContext& context, const Plan& plan,
                                                             const HostDepthDesc& desc,
                                                             const RendererOptions& options) {
    std::unique_ptr<HostDepthPass> pass(new HostDepthPass());
    if (auto r = pass->init(context, plan, desc, options); !r) return r.error();
    return pass;
}

Result<void> HostDepthPass::init(VulkanContext& context, const Plan& plan, const HostDepthDesc& desc,
                                 const RendererOptions& options) {
    Objects& o = *objects_;
    o.desc = desc;
    const bool depth_format = is_depth_format(desc.format);
    if (!depth_format && !is_colour_depth_format(desc.format)) {
        return make_error(ErrorCode::unsupported, "HostDepthDesc.format = " + std::to_string(desc.format) +
                                                      " is not a depth format nor R32_SFLOAT/R16_SFLOAT/R16_UNORM");
    }
    if (desc.encoding == DepthEncoding::linear_m && desc.format != VK_FORMAT_R32_SFLOAT &&
        desc.format != VK_FORMAT_R16_SFLOAT) {
        return make_error(ErrorCode::invalid_argument,
                          "HostDepthDesc: encoding linear_m needs a float colour format (R32_SFLOAT or R16_SFLOAT), "
                          "format = " +
                              std::to_string(desc.format));
    }
    VkFormatProperties properties;
    context.fn.vkGetPhysicalDeviceFormatProperties(context.physical_device, desc.format, &properties);
    if ((properties.optimalTilingFeatures & VK_FORMAT_FEATURE_SAMPLED_IMAGE_BIT) == 0) {
        return make_error(ErrorCode::unsupported, "Vulkan device " + context.description + " cannot sample format " +
                                                      std::to_string(desc.format) +
                                                      " (VK_FORMAT_FEATURE_SAMPLED_IMAGE_BIT missing)");
    }
    o.barrier_aspect = depth_format ? VK_IMAGE_ASPECT_DEPTH_BIT : VK_IMAGE_ASPECT_COLOR_BIT;
    // Without separateDepthStencilLayouts a barrier on a combined format names both aspects.
    if (has_stencil(desc.format)) o.barrier_aspect |= VK_IMAGE_ASPECT_STENCIL_BIT;

    o.push.near_m = static_cast<float>(desc.near_m);
    const double near_over_far = std::isinf(desc.far_m) ? 0.0 : desc.near_m / desc.far_m;
    switch (desc.encoding) {
    case DepthEncoding::standard_z:
        o.push.encoding = shared::kHostDepthStandard;
        o.push.z_a = 1.0f;
        o.push.z_b = static_cast<float>(-(1.0 - near_over_far));
        break;
    case DepthEncoding::reversed_z:
        o.push.encoding = shared::kHostDepthReversed;
        o.push.z_a = static_cast<float>(near_over_far);
        o.push.z_b = static_cast<float>(1.0 - near_over_far);
        break;
    case DepthEncoding::linear_m:
        o.push.encoding = shared::kHostDepthLinear;
        o.push.z_a = 1.0f;
        o.push.z_b = 0.0f;
        break;
    }

    // The backend without its depth pass: compute stages, tables, readback and command buffers only.
    o.backend = std::make_unique<VulkanBackend>(context, plan, o.no_scene, options);
    VulkanBackend& b = *o.backend;
    b.resolve_passes();
    const std::uint64_t pixels = std::uint64_t(plan.columns) * plan.rows;
    const VkPhysicalDeviceLimits& limits = context.properties.limits;
    if (!dispatches_fit(plan, b.shape_, limits, true) || pixels * 16 > limits.maxStorageBufferRange) {
        return make_error(ErrorCode::unsupported, "HostDepthDesc: " + std::to_string(plan.columns) + " x " +
                                                      std::to_string(plan.rows) +
                                                      " pixels exceed the device's compute limits");
    }
    if (auto r = b.create_compute(); !r) return r;
    if (auto r = b.create_commands(); !r) return r;

    VkDevice device = context.device;
    const VkAllocationCallbacks* allocator = context.allocator;

    VkDescriptorSetLayoutBinding binding{};
    binding.binding = shared::kBindingHostDepthImage;
    binding.descriptorType = VK_DESCRIPTOR_TYPE_SAMPLED_IMAGE;
    binding.descriptorCount = 1;
    binding.stageFlags = VK_SHADER_STAGE_COMPUTE_BIT;
    VkDescriptorSetLayoutCreateInfo set_layout_info{};
    set_layout_info.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO;
    set_layout_info.bindingCount = 1;
    set_layout_info.pBindings = &binding;
    VkDescriptorSetLayout set_layout = VK_NULL_HANDLE;
    VKS_VK_TRY(context.fn.vkCreateDescriptorSetLayout(device, &set_layout_info, allocator, &set_layout));
    o.image_set_layout = OwnedDescriptorSetLayout(context, set_layout);

    // Set 0 is the backend's compute set (params, depth, material id), set 1 the host image.
    const std::array<VkDescriptorSetLayout, 2> set_layouts{b.set_layout_.get(), set_layout};
    VkPushConstantRange push_range{VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(shared::ImportDepthPush)};
    VkPipelineLayoutCreateInfo layout_info{};
    layout_info.sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO;
    layout_info.setLayoutCount = static_cast<std::uint32_t>(set_layouts.size());
    layout_info.pSetLayouts = set_layouts.data();
    layout_info.pushConstantRangeCount = 1;
    layout_info.pPushConstantRanges = &push_range;
    VkPipelineLayout layout = VK_NULL_HANDLE;
    VKS_VK_TRY(context.fn.vkCreatePipelineLayout(device, &layout_info, allocator, &layout));
    o.import_layout = OwnedPipelineLayout(context, layout);

    auto module = create_shader_module(context, import_depth_comp_spv, sizeof(import_depth_comp_spv));
    if (!module) return module.error();
    auto pipeline = create_compute_pipeline(context, layout, module->get(), nullptr, 0);
    if (!pipeline) return pipeline.error();
    o.import_pipeline = std::move(pipeline.value());

    VkDescriptorPoolSize pool_size{VK_DESCRIPTOR_TYPE_SAMPLED_IMAGE, 1};
    VkDescriptorPoolCreateInfo pool_info{};
    pool_info.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO;
    pool_info.maxSets = 1;
    pool_info.poolSizeCount = 1;
    pool_info.pPoolSizes = &pool_size;
    VkDescriptorPool pool = VK_NULL_HANDLE;
    VKS_VK_TRY(context.fn.vkCreateDescriptorPool(device, &pool_info, allocator, &pool));
    o.image_pool = OwnedDescriptorPool(context, pool);
    VkDescriptorSetAllocateInfo set_info{};
    set_info.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO;
    set_info.descriptorPool = pool;
    set_info.descriptorSetCount = 1;
    set_info.pSetLayouts = &set_layout;
    VKS_VK_TRY(context.fn.vkAllocateDescriptorSets(device, &set_info, &o.image_set));

    VkEventCreateInfo event_info{};
    event_info.sType = VK_STRUCTURE_TYPE_EVENT_CREATE_INFO;
    VkEvent event = VK_NULL_HANDLE;
    VKS_VK_TRY(context.fn.vkCreateEvent(device, &event_info, allocator, &event));
    o.done = OwnedEvent(context, event);
    return {};
}

Result<void> HostDepthPass::check_image(const HostDepthImage& image) const {
    if (image.image == VK_NULL_HANDLE || image.view == VK_NULL_HANDLE) {
        return make_error(ErrorCode::invalid_argument, "HostDepthImage: image and view must be set");
    }
    if (!readable_layout(image.layout)) {
        return make_error(ErrorCode::invalid_argument,
                          "HostDepthImage.layout = " + std::to_string(image.layout) +
                              " cannot be sampled; use GENERAL, SHADER_READ_ONLY_OPTIMAL, "
                              "DEPTH_STENCIL_READ_ONLY_OPTIMAL or DEPTH_READ_ONLY_STENCIL_ATTACHMENT_OPTIMAL");
    }
    return {};
}

// The set is rewritten for every ping instead of cached per view: a host may destroy a view and get
// the same handle back for a new one. Rewriting is legal because the previous ping has finished
// (process waits; record's contract is one ping in flight).
void HostDepthPass::bind_image(const HostDepthImage& image) {
    VkDescriptorImageInfo info{VK_NULL_HANDLE, image.view, image.layout};
    VkWriteDescriptorSet write{};
    write.sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
    write.dstSet = objects_->image_set;
    write.dstBinding = shared::kBindingHostDepthImage;
    write.descriptorCount = 1;
    write.descriptorType = VK_DESCRIPTOR_TYPE_SAMPLED_IMAGE;
    write.pImageInfo = &info;
    const VulkanContext& context = objects_->backend->context_;
    context.fn.vkUpdateDescriptorSets(context.device, 1, &write, 0, nullptr);
}

// The depth entry of kStageTable on the host-depth path.
void record_import(RecordContext& record) {
    record.host_depth->record_import_pass(record.commands, *record.image, record.dispatches[0]);
}

void HostDepthPass::record_import_pass(VkCommandBuffer commands, const HostDepthImage& image, const Dispatch& groups) {
    Objects& o = *objects_;
    VulkanBackend& b = *o.backend;
    const VulkanContext& context = b.context_;
    // The host's writes (by default its depth attachment writes) -> this pass's sampled reads. The
    // layout stays the host's: vksonar only reads the image.
    VkImageMemoryBarrier barrier{};
    barrier.sType = VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER;
    barrier.srcAccessMask =
        image.src_access != 0 ? image.src_access : VkAccessFlags(VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT);
    barrier.dstAccessMask = VK_ACCESS_SHADER_READ_BIT;
    barrier.oldLayout = image.layout;
    barrier.newLayout = image.layout;
    barrier.srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    barrier.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    barrier.image = image.image;
    barrier.subresourceRange = {o.barrier_aspect, 0, VK_REMAINING_MIP_LEVELS, 0, VK_REMAINING_ARRAY_LAYERS};
    const VkPipelineStageFlags src_stage = image.src_stage != 0
                                               ? image.src_stage
                                               : VkPipelineStageFlags(VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT |
                                                                      VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT);
    context.fn.vkCmdPipelineBarrier(commands, src_stage, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, 0, nullptr, 0,
                                    nullptr, 1, &barrier);

    // The previous ping's stages read depth_/material_id_; make them wait before this one overwrites.
    std::array<VkBufferMemoryBarrier, 2> reuse{
        buffer_barrier(b.depth_.get(), kShaderOrTransferRead, VK_ACCESS_SHADER_WRITE_BIT),
        buffer_barrier(b.material_id_.get(), kShaderOrTransferRead, VK_ACCESS_SHADER_WRITE_BIT)};
    pipeline_barrier(context, commands, kComputeOrTransfer, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 2, reuse.data());

    context.fn.vkCmdBindPipeline(commands, VK_PIPELINE_BIND_POINT_COMPUTE, o.import_pipeline.get());
    const std::array<VkDescriptorSet, 2> sets{b.descriptor_set_, o.image_set};
    context.fn.vkCmdBindDescriptorSets(commands, VK_PIPELINE_BIND_POINT_COMPUTE, o.import_layout.get(), 0,
                                       static_cast<std::uint32_t>(sets.size()), sets.data(), 0, nullptr);
    context.fn.vkCmdPushConstants(commands, o.import_layout.get(), VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(o.push),
                                  &o.push);
    b.dispatch(commands, groups);
    std::array<VkBufferMemoryBarrier, 2> written{
        buffer_barrier(b.depth_.get(), VK_ACCESS_SHADER_WRITE_BIT, kShaderOrTransferRead),
        buffer_barrier(b.material_id_.get(), VK_ACCESS_SHADER_WRITE_BIT, kShaderOrTransferRead)};
    pipeline_barrier(context, commands, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, kComputeOrTransfer, 2, written.data());
}

Result<void> HostDepthPass::process(const HostDepthImage& image, SaveFlags save_mask, Frame& frame) {
    if (auto r = check_image(image); !r) return r;
    Objects& o = *objects_;
    VulkanBackend& b = *o.backend;
    VulkanContext& context = b.context_;
    frame.times.clear();
    frame.stages_run.clear();
    bind_image(image);

    // One command buffer per stage of kStageTable (its host_depth side: the import of the host's image
    // in the depth pass's place) and one for the readback, submitted one at a time and timed on the
    // host (the backend's timestamp path is tied to its own render(); a submit costs ~10 us against
    // stages of ms).
    std::array<const StageInfo*, kStageCount> stages{};
    std::uint32_t stage_total = 0;
    for (const StageInfo& stage : kStageTable)
        if (stage.runs(b.plan_)) stages[stage_total++] = &stage;
    VKS_VK_TRY(context.fn.vkResetCommandPool(context.device, b.command_pool_.get(), 0));
    b.commands_kept_ = {}; // render()'s kept buffers are gone
    // StageTiming::passes: the beamform stage's passes on timestamps (queries reset by the first
    // buffer, the stage's start in query `stage_query`), the stages themselves on host clocks.
    std::uint32_t stage_query = 0;
    for (std::uint32_t i = 0; i <= stage_total; ++i) {
        VkCommandBuffer commands = b.command_buffers_[0][i];
        VkCommandBufferBeginInfo begin{};
        begin.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
        begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
        VKS_VK_TRY(context.fn.vkBeginCommandBuffer(commands, &begin));
        if (i == 0) b.reset_pass_queries(commands);
        if (i < stage_total && std::strcmp(stages[i]->name, "beamform") == 0) {
            stage_query = i;
            b.mark_stage_start(commands, stage_query);
        }
        if (i < stage_total) {
            RecordContext record{b, commands, stages[i]->host_depth.dispatches(b.plan_, b.shape_), this, &image};
            stages[i]->host_depth.record(record);
        } else {
            b.record_readback(commands, save_mask);
        }
        VKS_VK_TRY(context.fn.vkEndCommandBuffer(commands));

        const auto start = std::chrono::steady_clock::now();
        // the first stage reads the host's image (stage_table_test): it waits for the host's semaphore
        if (auto r = b.submit(&commands, 1, 0, false, i == 0 ? image.wait_semaphore : VK_NULL_HANDLE); !r) return r;
        if (auto r = b.wait(0); !r) return r;
        const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
        if (i < stage_total) { // the readback is a transfer, not a stage
            frame.times.push_back(StageTime{stages[i]->host_depth_name, ms});
            frame.stages_run.emplace_back(stages[i]->host_depth_name);
        }
    }
    if (auto r = b.frame_status(); !r) return r; // refused, not passed on with rows missing
    copy_frame_out(save_mask, frame);
    return b.add_pass_times(stage_query, frame);
}

Result<void> HostDepthPass::record(VkCommandBuffer commands, const HostDepthImage& image, SaveFlags save_mask) {
    if (commands == VK_NULL_HANDLE) {
        return make_error(ErrorCode::invalid_argument, "HostDepthRenderer::record: command buffer is null");
    }
    if (auto r = check_image(image); !r) return r;
    if (auto r = refuse_while_recorded_pending("record"); !r) return r;
    Objects& o = *objects_;
    VulkanBackend& b = *o.backend;
    const VulkanContext& context = b.context_;
    // The previous ping has finished (one ping in flight), so the event can be reset from the host.
    VKS_VK_TRY(context.fn.vkResetEvent(context.device, o.done.get()));
    bind_image(image);
    // StageTiming::passes: as process(), in the host's command buffer (read by read_back)
    b.reset_pass_queries(commands);
    std::uint32_t position = 0;
    for (const StageInfo& stage : kStageTable) {
        if (!stage.runs(b.plan_)) continue;
        if (std::strcmp(stage.name, "beamform") == 0) {
            o.stage_query = position;
            b.mark_stage_start(commands, o.stage_query);
        }
        ++position;
        RecordContext stage_record{b, commands, stage.host_depth.dispatches(b.plan_, b.shape_), this, &image};
        stage.host_depth.record(stage_record);
    }
    b.record_readback(commands, save_mask);
    // The polar scan stays readable by whatever the host records next (e.g. a fragment shader drawing it).
    const Buffer& polar = b.sidelobes_ ? b.polar_ : b.beam_profiles_;
    VkBufferMemoryBarrier visible = buffer_barrier(polar.get(), VK_ACCESS_SHADER_WRITE_BIT,
                                                   VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_TRANSFER_READ_BIT);
    pipeline_barrier(context, commands, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, 1,
                     &visible);
    context.fn.vkCmdSetEvent(commands, o.done.get(), VK_PIPELINE_STAGE_TRANSFER_BIT);
    o.recorded = true;
    o.recorded_mask = save_mask;
    return {};
}

// One ping in flight: record() and process() rewrite the descriptor sets and buffers a recorded ping's
// command buffer uses, which would invalidate it (or change its results) before it runs. The ping's
// last command sets the event; until the host's queue has run it, both are refused.
Result<void> HostDepthPass::refuse_while_recorded_pending(const char* call) const {
    const Objects& o = *objects_;
    if (!o.recorded) return {};
    const VulkanContext& context = o.backend->context_;
    const VkResult status = context.fn.vkGetEventStatus(context.device, o.done.get());
    if (status == VK_EVENT_SET) return {};
    if (status != VK_EVENT_RESET) return vk_error(status, "vkGetEventStatus");
    return make_error(ErrorCode::invalid_argument,
                      std::string("HostDepthRenderer::") + call +
                          ": the command buffer given to the last record() has not finished executing (one ping "
                          "in flight: wait for the host's fence of that submission first; one that will never be "
                          "submitted: discard_recorded())");
}

Result<void> HostDepthPass::read_back(SaveFlags save_mask, Frame& frame) {
    Objects& o = *objects_;
    if (!o.recorded) {
        return make_error(ErrorCode::invalid_argument,
                          "HostDepthRenderer::read_back: nothing was recorded (call record first)");
    }
    const VulkanContext& context = o.backend->context_;
    const VkResult status = context.fn.vkGetEventStatus(context.device, o.done.get());
    if (status == VK_EVENT_RESET) {
        return make_error(
            ErrorCode::invalid_argument,
            "HostDepthRenderer::read_back: the command buffer given to record() has not finished executing "
            "(wait for the host's fence of that submission first)");
    }
    if (status != VK_EVENT_SET) return vk_error(status, "vkGetEventStatus");
    frame.times.clear();
    frame.stages_run.clear();
    if (auto r = o.backend->frame_status(); !r) return r; // refused, not passed on with rows missing
    copy_frame_out(save_mask & o.recorded_mask, frame);
    return o.backend->add_pass_times(o.stage_query, frame);
}

void HostDepthPass::arm_process(const HostDepthImage& image) {
    objects_->armed = Objects::Armed::process;
    objects_->armed_image = image;
}

void HostDepthPass::discard_recorded() {
    objects_->recorded = false;
}

void HostDepthPass::arm_read_back() {
    objects_->armed = Objects::Armed::read_back;
}

Result<void> HostDepthPass::render(const Pose& /*pose: the host's camera is the sonar*/, SaveFlags save_mask,
                                   Frame& frame) {
    const Objects::Armed armed = std::exchange(objects_->armed, Objects::Armed::none);
    switch (armed) {
    case Objects::Armed::process:
        if (auto r = refuse_while_recorded_pending("process"); !r) return r;
        return process(objects_->armed_image, save_mask, frame);
    case Objects::Armed::read_back:
        return read_back(save_mask, frame);
    case Objects::Armed::none:
        break;
    }
    return make_error(ErrorCode::invalid_argument,
                      "render: the host-depth pass runs only through HostDepthRenderer::process or read_back");
}

GpuBufferView HostDepthPass::polar_buffer() const {
    const VulkanBackend& b = *objects_->backend;
    const Buffer& polar = b.sidelobes_ ? b.polar_ : b.beam_profiles_;
    return GpuBufferView{polar.get(), 0, VkDeviceSize(b.plan_.bins) * b.plan_.beams * sizeof(float), b.plan_.beams,
                         b.plan_.bins};
}

// The backend's own copy-out: same regions, same layout conversions.
void HostDepthPass::copy_frame_out(SaveFlags save_mask, Frame& frame) const {
    objects_->backend->copy_frame_out(save_mask, frame);
}

} // namespace vksonar::vk
