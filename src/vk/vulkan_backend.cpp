// The Vulkan StageBackend, creation: every pipeline, buffer, image, descriptor set, command buffer,
// fence and query pool is made here once (make_backend) and the scene is uploaded. The per-frame
// work (record, submit, read back) is in vulkan_frame.cpp.

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "core/tier_extent.h"
#include "vk/commands.h"
#include "vk/handles.h"
#include "vk/pipelines.h"
#include "vk/profile_bands.h"
#include "vk/resample_walk.h"
#include "vk/resources.h"
#include "vk/vk_error.h"
#include "vk/vulkan_backend_impl.h"
#include "vk/vulkan_context.h"

#include "depth.frag.spv.h"
#include "depth.vert.spv.h"
#include "depth_geometric.frag.spv.h"
#include "depth_geometric.vert.spv.h"
#include "echo.comp.spv.h"
#include "far_sidelobe.comp.spv.h"
#include "normals.comp.spv.h"
#include "profile.comp.spv.h"
#include "resample.comp.spv.h"
#include "sidelobe.comp.spv.h"

namespace vksonar::vk {

namespace {

// profile.comp's gather_block_rows lists each row's pixels for a cone column in shared memory: at most
// this many a row (the default grid gives 7).
constexpr std::uint32_t kMaxRowCandidates = 16;

// The most pixels one row gives one cone column c (line_array): those of every view whose cone coordinate
// x has c - 1 < x < c + 1 (a tier view's: widened by Plan::tier_cone_reach, and with a share of c, as
// profile.comp's list_view takes them), compared in float as profile.comp compares them.
std::uint32_t most_row_candidates(const Plan& plan) {
    const std::uint32_t count = plan.profile_columns;
    std::vector<std::uint32_t> per_cone(count);
    std::uint32_t most = 0;
    for (std::uint32_t row = 0; row < plan.rows && !plan.pixel_cone_coord.empty(); ++row) {
        std::fill(per_cone.begin(), per_cone.end(), 0u);
        const float* x = plan.pixel_cone_coord.data() + std::size_t(row) * plan.columns;
        for (std::uint32_t view = 0; view < plan.views; ++view) {
            const bool tier = view >= plan.slices;
            const float reach = tier ? plan.tier_cone_reach : 0.0f;
            const std::uint32_t first = view_first_column(plan, view), end = first + view_columns(plan, view);
            for (std::uint32_t column = first; column < end; ++column) {
                if (!(x[column] > -1.0f - reach && x[column] < float(count) + reach)) continue; // NaN too
                const ConeExtent extent = tier ? tier_cone_extent(x, column, first, end) : ConeExtent{};
                const auto below = static_cast<std::int64_t>(std::floor(x[column] - reach));
                const auto above = static_cast<std::int64_t>(std::floor(x[column] + reach)) + 1;
                for (std::int64_t c = std::max<std::int64_t>(below, 0); c <= above && c < count; ++c) {
                    if (!(x[column] > float(c) - 1.0f - reach && x[column] < float(c) + 1.0f + reach)) continue;
                    if (tier && !(math_f32::cone_extent_share(x[column], extent.lo, extent.hi, static_cast<int>(c),
                                                              static_cast<int>(count)) > 0.0f))
                        continue;
                    most = std::max(most, ++per_cone[c]);
                }
            }
        }
    }
    return most;
}

} // namespace

VulkanBackend::~VulkanBackend() {
    // Frames started (start()) and never finished, or a failed wait. Not a fence whose submission
    // failed: nothing would ever signal it.
    for (std::uint32_t slot = 0; slot < kFrameSlots; ++slot) {
        if (!fences_[slot] || !fence_submitted_[slot]) continue;
        VkFence fence = fences_[slot].get();
        context_.fn.vkWaitForFences(context_.device, 1, &fence, VK_TRUE, UINT64_MAX);
    }
}

bool dispatches_fit(const Plan& plan, const DeviceShape& shape, const VkPhysicalDeviceLimits& limits, bool host_depth) {
    for (const StageInfo& stage : kStageTable) {
        if (!stage.runs(plan)) continue;
        for (const Dispatch& d : (host_depth ? stage.host_depth : stage.vulkan).dispatches(plan, shape)) {
            if (d.shader != nullptr &&
                (d.x > limits.maxComputeWorkGroupCount[0] || d.y > limits.maxComputeWorkGroupCount[1] ||
                 d.z > limits.maxComputeWorkGroupCount[2]))
                return false;
        }
    }
    return true;
}

void VulkanBackend::resolve_passes() {
    incidence_ = plan_.effects.incidence;
    sidelobes_ = plan_.effects.horizontal_pattern;
    far_sidelobes_ = sidelobes_ && plan_.far_cells > 0;
    face_normals_ = plan_.face_normals;
    const bool cpu_device = context_.properties.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU;
    switch (options_.layout) {
    case WorkLayout::automatic:
        shape_ = cpu_device ? kCpuDeviceShape : kGpuDeviceShape;
        break;
    case WorkLayout::cpu_device:
        shape_ = kCpuDeviceShape;
        break;
    case WorkLayout::gpu:
        shape_ = kGpuDeviceShape;
        break;
    }
}

Result<void> VulkanBackend::init() {
    resolve_passes();
    if (plan_.columns == 0 || plan_.rows == 0 || plan_.beams == 0 || plan_.bins == 0) {
        return make_error(ErrorCode::internal, "vulkan backend: plan has an empty pixel grid or polar scan");
    }
    const VkPhysicalDeviceLimits& limits = context_.properties.limits;
    if (plan_.columns > limits.maxFramebufferWidth || plan_.rows > limits.maxFramebufferHeight ||
        plan_.columns > limits.maxImageDimension2D || plan_.rows > limits.maxImageDimension2D) {
        return make_error(
            ErrorCode::unsupported,
            "vulkan backend: depth image of " + std::to_string(plan_.columns) + " x " + std::to_string(plan_.rows) +
                " pixels exceeds the device limit of " + std::to_string(limits.maxFramebufferWidth) + " x " +
                std::to_string(limits.maxFramebufferHeight) +
                " (lower accuracy.pixels_per_beam or accuracy.rows_per_vfov, or render with --backend cpu)");
    }
    const std::uint64_t pixels = std::uint64_t(plan_.columns) * plan_.rows;
    if (!dispatches_fit(plan_, shape_, limits, false) || pixels * 16 > limits.maxStorageBufferRange) {
        return make_error(ErrorCode::unsupported, "vulkan backend: " + std::to_string(plan_.columns) + " x " +
                                                      std::to_string(plan_.rows) +
                                                      " pixels exceed the device's compute limits");
    }
    // The largest polar-side storage buffers (bins padded to 4, as create_compute makes them): the
    // range profiles, one per pixel column, and the beam profiles. Refused before any allocation.
    const std::uint64_t bins_padded = (std::uint64_t(plan_.bins) + 3u) & ~std::uint64_t(3);
    const std::uint64_t profile_bytes = bins_padded * std::max(plan_.profile_columns, plan_.beams) * sizeof(float);
    if (profile_bytes > limits.maxStorageBufferRange) {
        return make_error(ErrorCode::unsupported,
                          "vulkan backend: the range-profile buffer would hold " + std::to_string(profile_bytes) +
                              " bytes (" + std::to_string(plan_.bins) + " bins x " +
                              std::to_string(std::max(plan_.profile_columns, plan_.beams)) +
                              " columns), past the device's limit of " + std::to_string(limits.maxStorageBufferRange) +
                              " bytes (lower bins or accuracy.pixels_per_beam, or use --backend cpu)");
    }
    // The near side-lobe kernel's weights (Plan::near_column_weight): a beam's columns within the reach,
    // up to every column for a kernel across the fan.
    const std::uint64_t near_bytes = (std::uint64_t(plan_.near_column_weight.size()) + 3u * plan_.beams +
                                      (plan_.near_bands > 1 ? bins_padded : 0u)) *
                                     sizeof(float);
    if (near_bytes > limits.maxStorageBufferRange) {
        return make_error(ErrorCode::unsupported,
                          "vulkan backend: the side-lobe kernel's column table would hold " +
                              std::to_string(near_bytes) + " bytes (" + std::to_string(plan_.beams) + " beams x " +
                              std::to_string(plan_.near_column_taps) + " columns" +
                              (plan_.near_bands > 1 ? " x " + std::to_string(plan_.near_bands) + " focus bands" : "") +
                              "), past the device's limit of " + std::to_string(limits.maxStorageBufferRange) +
                              (plan_.near_bands > 1 ? " bytes (raise range_min or move focus_range into the range "
                                                      "window, or use --backend cpu)"
                                                    : " bytes (lower accuracy.sidelobe_kernel_beamwidths, or use "
                                                      "--backend cpu)"));
    }
    if (auto r = create_scene_buffers(); !r) return r;
    if (auto r = create_depth_pass(); !r) return r;
    if (auto r = create_compute(); !r) return r;
    return create_commands();
}

Result<void> VulkanBackend::create_scene_buffers() {
    const SceneData& scene = scene_;
    for (std::size_t i = 0; i < scene.draws.size(); ++i) {
        const SceneDraw& draw = scene.draws[i];
        if (draw.mesh >= scene.meshes.size()) {
            return make_error(ErrorCode::invalid_argument, "scene draw " + std::to_string(i) + ": mesh " +
                                                               std::to_string(draw.mesh) + " does not exist");
        }
        const MeshRange& mesh = scene.meshes[draw.mesh];
        if (std::uint64_t(mesh.first_index) + mesh.index_count > scene.indices.size() ||
            (std::uint64_t(mesh.first_vertex) + mesh.vertex_count) * 3 > scene.positions.size() ||
            mesh.first_vertex > std::uint32_t(std::numeric_limits<std::int32_t>::max())) {
            return make_error(ErrorCode::invalid_argument,
                              "scene mesh " + std::to_string(draw.mesh) + ": index or vertex range out of bounds");
        }
    }
    build_depth_clusters(scene, clusters_);
    draw_pushes_.resize(std::size_t(plan_.views) * scene.draws.size());
    clusters_drawn_.resize(std::size_t(plan_.views) * clusters_.size());
    for (SubpixelReturns& returns : subpixel_returns_)
        returns.prepare(plan_);

    const VkBufferUsageFlags dst = VK_BUFFER_USAGE_TRANSFER_DST_BIT;
    auto vertices =
        create_buffer(context_, bytes_of(scene.positions), VK_BUFFER_USAGE_VERTEX_BUFFER_BIT | dst, MemoryUse::device);
    if (!vertices) return vertices.error();
    vertices_ = std::move(vertices.value());
    auto indices =
        create_buffer(context_, bytes_of(scene.indices), VK_BUFFER_USAGE_INDEX_BUFFER_BIT | dst, MemoryUse::device);
    if (!indices) return indices.error();
    indices_ = std::move(indices.value());
    if (auto r = upload_to_buffer(context_, vertices_, scene.positions.data(), bytes_of(scene.positions)); !r) return r;
    return upload_to_buffer(context_, indices_, scene.indices.data(), bytes_of(scene.indices));
}

Result<void> VulkanBackend::create_depth_pass() {
    VkDevice device = context_.device;
    const VkAllocationCallbacks* allocator = context_.allocator;
    VkFormatProperties depth_format, material_format;
    context_.fn.vkGetPhysicalDeviceFormatProperties(context_.physical_device, kDepthFormat, &depth_format);
    context_.fn.vkGetPhysicalDeviceFormatProperties(context_.physical_device, kMaterialFormat, &material_format);
    const VkFormatFeatureFlags copy = VK_FORMAT_FEATURE_TRANSFER_SRC_BIT;
    if ((depth_format.optimalTilingFeatures & (VK_FORMAT_FEATURE_DEPTH_STENCIL_ATTACHMENT_BIT | copy)) !=
            (VK_FORMAT_FEATURE_DEPTH_STENCIL_ATTACHMENT_BIT | copy) ||
        (material_format.optimalTilingFeatures & (VK_FORMAT_FEATURE_COLOR_ATTACHMENT_BIT | copy)) !=
            (VK_FORMAT_FEATURE_COLOR_ATTACHMENT_BIT | copy)) {
        return make_error(ErrorCode::unsupported,
                          "Vulkan device " + context_.description + " cannot render to D32_SFLOAT + R32_UINT");
    }
    auto depth_image = create_image_2d(context_, plan_.columns, plan_.rows, kDepthFormat,
                                       VK_IMAGE_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT,
                                       VK_IMAGE_ASPECT_DEPTH_BIT);
    if (!depth_image) return depth_image.error();
    depth_image_ = std::move(depth_image.value());
    auto material_image = create_image_2d(context_, plan_.columns, plan_.rows, kMaterialFormat,
                                          VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT,
                                          VK_IMAGE_ASPECT_COLOR_BIT);
    if (!material_image) return material_image.error();
    material_image_ = std::move(material_image.value());
    if (face_normals_) { // normal_method = geometric: the face-normal attachment, only then
        VkFormatProperties normal_format;
        context_.fn.vkGetPhysicalDeviceFormatProperties(context_.physical_device, kFaceNormalFormat, &normal_format);
        if ((normal_format.optimalTilingFeatures & (VK_FORMAT_FEATURE_COLOR_ATTACHMENT_BIT | copy)) !=
            (VK_FORMAT_FEATURE_COLOR_ATTACHMENT_BIT | copy)) {
            return make_error(ErrorCode::unsupported, "Vulkan device " + context_.description +
                                                          " cannot render to R32G32B32A32_SFLOAT "
                                                          "(accuracy.normal_method = geometric)");
        }
        auto normal_image = create_image_2d(context_, plan_.columns, plan_.rows, kFaceNormalFormat,
                                            VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT,
                                            VK_IMAGE_ASPECT_COLOR_BIT);
        if (!normal_image) return normal_image.error();
        face_normal_image_ = std::move(normal_image.value());
    }

    auto render_pass = create_depth_render_pass(context_, face_normals_);
    if (!render_pass) return render_pass.error();
    render_pass_ = std::move(render_pass.value());

    std::array<VkImageView, 3> views{material_image_.view.get(), depth_image_.view.get(),
                                     face_normals_ ? face_normal_image_.view.get() : VK_NULL_HANDLE};
    VkFramebufferCreateInfo framebuffer_info{};
    framebuffer_info.sType = VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO;
    framebuffer_info.renderPass = render_pass_.get();
    framebuffer_info.attachmentCount = face_normals_ ? 3u : 2u;
    framebuffer_info.pAttachments = views.data();
    framebuffer_info.width = plan_.columns;
    framebuffer_info.height = plan_.rows;
    framebuffer_info.layers = 1;
    VkFramebuffer framebuffer = VK_NULL_HANDLE;
    VKS_VK_TRY(context_.fn.vkCreateFramebuffer(device, &framebuffer_info, allocator, &framebuffer));
    framebuffer_ = OwnedFramebuffer(context_, framebuffer);

    VkPushConstantRange push_range{VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT, 0,
                                   sizeof(shared::DepthPush)};
    VkPipelineLayoutCreateInfo layout_info{};
    layout_info.sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO;
    layout_info.pushConstantRangeCount = 1;
    layout_info.pPushConstantRanges = &push_range;
    VkPipelineLayout layout = VK_NULL_HANDLE;
    VKS_VK_TRY(context_.fn.vkCreatePipelineLayout(device, &layout_info, allocator, &layout));
    depth_layout_ = OwnedPipelineLayout(context_, layout);

    auto vertex = face_normals_
                      ? create_shader_module(context_, depth_geometric_vert_spv, sizeof(depth_geometric_vert_spv))
                      : create_shader_module(context_, depth_vert_spv, sizeof(depth_vert_spv));
    if (!vertex) return vertex.error();
    auto fragment = face_normals_
                        ? create_shader_module(context_, depth_geometric_frag_spv, sizeof(depth_geometric_frag_spv))
                        : create_shader_module(context_, depth_frag_spv, sizeof(depth_frag_spv));
    if (!fragment) return fragment.error();
    auto pipeline = create_depth_pipeline(context_, render_pass_.get(), depth_layout_.get(), vertex->get(),
                                          fragment->get(), face_normals_ ? 2u : 1u);
    if (!pipeline) return pipeline.error();
    depth_pipeline_ = std::move(pipeline.value());
    return {};
}

Result<void> VulkanBackend::create_compute() {
    // Beamform intermediates are bin-fastest with bins padded to a multiple of 4, so resample and
    // sidelobe can load four range bins as one vec4 (see resample.comp).
    gpu_params_ = plan_.params;
    gpu_params_.bins_padded = (plan_.bins + 3u) & ~3u;
    if (auto r = create_working_buffers(); !r) return r;
    auto views = upload_tables();
    if (!views) return views.error();
    if (auto r = create_readback(); !r) return r;
    if (auto r = create_descriptors(views.value()); !r) return r;
    return create_compute_pipelines(views.value());
}

Result<void> VulkanBackend::create_working_buffers() {
    const std::size_t pixels = std::size_t(plan_.columns) * plan_.rows;
    const std::size_t cells = std::size_t(plan_.bins) * plan_.beams;
    const std::size_t padded_cells = std::size_t(gpu_params_.bins_padded) * plan_.beams;
    const std::size_t profile_cells = std::size_t(gpu_params_.bins_padded) * plan_.profile_columns;
    const std::size_t far_floats = std::size_t(gpu_params_.bins_padded) * plan_.far_cells * plan_.far_channels;
    const VkBufferUsageFlags storage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT;
    const VkBufferUsageFlags in = storage | VK_BUFFER_USAGE_TRANSFER_DST_BIT;
    const VkBufferUsageFlags out = storage | VK_BUFFER_USAGE_TRANSFER_SRC_BIT;

    // Working buffers (GPU-only). Disabled stages keep a small buffer so every descriptor is valid.
    struct Working {
        Buffer* buffer;
        std::size_t bytes;
        VkBufferUsageFlags usage;
    };
    const std::array<Working, 10> working{{
        {&depth_, pixels * sizeof(float), in | VK_BUFFER_USAGE_TRANSFER_SRC_BIT},
        {&material_id_, pixels * sizeof(std::uint32_t), in | VK_BUFFER_USAGE_TRANSFER_SRC_BIT},
        // geometric: the depth pass copies its face normals in, the normals pass orients them in place
        {&normals_, incidence_ ? pixels * 4 * sizeof(float) : 16,
         face_normals_ ? out | VK_BUFFER_USAGE_TRANSFER_DST_BIT : out},
        {&echo_, pixels * 2 * sizeof(float), out},
        {&profiles_, profile_cells * sizeof(float),
         out | VK_BUFFER_USAGE_TRANSFER_DST_BIT}, // zeroed by vkCmdFillBuffer
        {&beam_profiles_, padded_cells * sizeof(float), out},
        {&polar_, sidelobes_ ? cells * sizeof(float) : 16, out},
        {&far_energy_, far_sidelobes_ ? far_floats * sizeof(float) : 16, storage},
        {&far_cells_, far_sidelobes_ ? far_floats * sizeof(float) : 16, storage},
        {&status_, 16, out | VK_BUFFER_USAGE_TRANSFER_DST_BIT}, // zeroed by vkCmdFillBuffer
    }};
    for (const Working& w : working) {
        auto buffer = create_buffer(context_, w.bytes, w.usage, MemoryUse::device);
        if (!buffer) return buffer.error();
        *w.buffer = std::move(buffer.value());
    }
    // The sub-pixel returns, sized once for the plan's capacity: written by the host into the frame
    // slot's upload buffer before the submit, copied on the device into subpixel_.
    const std::size_t subpixel_bytes = SubpixelReturns::buffer_bytes(plan_);
    auto subpixel = create_buffer(context_, subpixel_bytes, in, MemoryUse::device);
    if (!subpixel) return subpixel.error();
    subpixel_ = std::move(subpixel.value());
    { // zeros: no returns listed (what the host-depth path, which lists none, reads)
        const std::vector<std::uint8_t> zeros(subpixel_bytes, 0);
        if (auto r = upload_to_buffer(context_, subpixel_, zeros.data(), subpixel_bytes); !r) return r.error();
    }
    for (Buffer& upload : subpixel_uploads_) {
        auto made = create_buffer(context_, subpixel_bytes, VK_BUFFER_USAGE_TRANSFER_SRC_BIT, MemoryUse::upload);
        if (!made) return made.error();
        upload = std::move(made.value());
        if (upload.mapped != nullptr) std::memset(upload.mapped, 0, subpixel_bytes);
    }

    return {};
}

Result<VulkanBackend::TableViews> VulkanBackend::upload_tables() {
    const VkBufferUsageFlags storage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT;
    // Tables, uploaded once. Resample's per-column (beam, weight) and per-beam (first, end column)
    // pairs are interleaved so one load brings both.
    std::vector<shared::MaterialGpu> materials = plan_.materials;
    if (materials.empty()) {
        materials.push_back(shared::MaterialGpu{0.0f, shared::kScatterConstant, 0.0f, 0.0f}); // nothing reflects
    }
    // The view table is a uniform block of kMaxViews entries (normals.comp); the plan has <= that many.
    std::vector<shared::SliceInfo> slice_info = plan_.slice_info;
    slice_info.resize(shared::kMaxViews, shared::SliceInfo{});
    std::vector<std::uint32_t> column_table(2 * std::size_t(plan_.profile_columns));
    for (std::size_t c = 0; c < plan_.profile_columns; ++c) {
        column_table[2 * c] = plan_.column_beam[c];
        std::memcpy(&column_table[2 * c + 1], &plan_.column_weight[c], sizeof(float));
    }
    std::vector<std::uint32_t> beam_table(2 * std::size_t(plan_.beams));
    for (std::size_t j = 0; j < plan_.beams; ++j) {
        beam_table[2 * j] = plan_.beam_column_begin[j];
        beam_table[2 * j + 1] = plan_.beam_column_end[j];
    }
    // A table's uniform view: its size in vec4s, or 0 where it exceeds the device's uniform range.
    // TableAccess::storage reads every table through its storage binding (tests compare the paths).
    const bool storage_only = options_.tables == TableAccess::storage;
    auto uniform_vec4s = [&](std::size_t bytes) -> std::uint32_t {
        const std::size_t vec4s = (bytes + 15) / 16;
        return storage_only || vec4s * 16 > context_.properties.limits.maxUniformBufferRange
                   ? 0u
                   : static_cast<std::uint32_t>(vec4s);
    };
    const std::uint32_t materials_vec4s = uniform_vec4s(bytes_of(materials));
    const std::uint32_t column_table_vec4s = uniform_vec4s(bytes_of(column_table));
    const std::uint32_t beam_table_vec4s = uniform_vec4s(bytes_of(beam_table));
    // The near kernel's table (Plan::near_column_*): the weights, then per run of shape_.beams_per_invocation
    // beams the first and last source column any of its beams hears, then each beam's first column (as
    // floats, exact below 2^24; unwrapped, as the plan keeps them): sidelobe.comp loops over the run's
    // columns only, and a zero weight adds exactly +0, so the columns a beam does not hear change no bit.
    std::vector<float> sidelobe_table = plan_.near_column_weight;
    if (sidelobe_table.empty()) sidelobe_table.push_back(0.0f); // the pattern off: no side-lobe pass
    const bool near_kernel = !plan_.near_column_begin.empty();
    for (std::uint32_t first = 0; first < plan_.beams && near_kernel; first += shape_.beams_per_invocation) {
        const NearColumnSpan span = near_column_span(plan_, first, first + shape_.beams_per_invocation);
        // first and last; no column at all gives last = first - 1, an empty loop
        sidelobe_table.push_back(static_cast<float>(span.first));
        sidelobe_table.push_back(static_cast<float>(span.first + std::int64_t(span.count) - 1));
    }
    for (std::uint32_t j = 0; j < plan_.beams && near_kernel; ++j)
        sidelobe_table.push_back(static_cast<float>(plan_.near_column_begin[j]));
    if (near_kernel && plan_.near_bands > 1) // each bin's focus band, the padding bins band 0
        for (std::uint32_t k = 0; k < gpu_params_.bins_padded; ++k)
            sidelobe_table.push_back(k < plan_.bins ? static_cast<float>(plan_.near_band_of_bin[k]) : 0.0f);
    const std::uint32_t sidelobe_vec4s = uniform_vec4s(bytes_of(sidelobe_table));
    // The far side lobes' table, as far_sidelobe.comp and sidelobe.comp read it: beam cells (read back),
    // column cells (deposit), cell spans of columns, weights.
    std::vector<float> far_table = plan_.far_beam_cell;
    far_table.insert(far_table.end(), plan_.far_column_cell.begin(), plan_.far_column_cell.end());
    for (std::uint32_t column : plan_.far_cell_columns)
        far_table.push_back(static_cast<float>(column)); // exact: columns < 2^24
    far_table.insert(far_table.end(), plan_.far_weight.begin(), plan_.far_weight.end());
    if (far_table.empty()) far_table.assign(4, 0.0f);
    const std::uint32_t far_table_vec4s = uniform_vec4s(bytes_of(far_table));

    struct Table {
        Buffer* buffer;
        const void* data;
        std::size_t bytes;
        VkBufferUsageFlags usage;
    };
    const VkBufferUsageFlags uniform = VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT;
    const float no_cone_coord[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    const bool cones = !plan_.pixel_cone_coord.empty();
    const std::array<Table, 8> tables{{
        {&params_, &gpu_params_, sizeof(gpu_params_), uniform},
        {&slice_info_, slice_info.data(), bytes_of(slice_info), uniform},
        {&materials_, materials.data(), bytes_of(materials), storage | uniform},
        {&column_table_, column_table.data(), bytes_of(column_table), storage | uniform},
        {&beam_table_, beam_table.data(), bytes_of(beam_table), storage | uniform},
        {&sidelobe_weight_, sidelobe_table.data(), bytes_of(sidelobe_table), storage | uniform},
        {&cone_coord_, cones ? plan_.pixel_cone_coord.data() : no_cone_coord,
         cones ? bytes_of(plan_.pixel_cone_coord) : sizeof no_cone_coord, storage},
        {&far_table_, far_table.data(), bytes_of(far_table), storage | uniform},
    }};
    for (const Table& t : tables) {
        // Rounded up to whole vec4s: a uniform view covers whole std140 array elements.
        const std::size_t size = (t.bytes + 15) & ~std::size_t(15);
        auto buffer = create_buffer(context_, size, t.usage | VK_BUFFER_USAGE_TRANSFER_DST_BIT, MemoryUse::device);
        if (!buffer) return buffer.error();
        *t.buffer = std::move(buffer.value());
        if (auto r = upload_to_buffer(context_, *t.buffer, t.data, t.bytes); !r) return r.error();
    }

    return TableViews{materials_vec4s, column_table_vec4s, beam_table_vec4s, sidelobe_vec4s, far_table_vec4s};
}

Result<void> VulkanBackend::create_readback() {
    const std::size_t pixels = std::size_t(plan_.columns) * plan_.rows;
    const std::size_t cells = std::size_t(plan_.bins) * plan_.beams;
    const std::size_t padded_cells = std::size_t(gpu_params_.bins_padded) * plan_.beams;
    const std::size_t profile_cells = std::size_t(gpu_params_.bins_padded) * plan_.profile_columns;
    // One host-visible buffer receives everything a frame may read back.
    VkDeviceSize readback_bytes = 0;
    auto place = [&](Region& region, std::size_t bytes) {
        region.offset = readback_bytes;
        region.bytes = bytes;
        readback_bytes += (bytes + 15) & ~VkDeviceSize(15);
    };
    place(polar_region_, cells * sizeof(float));
    place(depth_region_, pixels * sizeof(float));
    place(material_region_, pixels * sizeof(std::uint32_t));
    place(normals_region_, incidence_ ? pixels * 4 * sizeof(float) : 0);
    place(echo_region_, pixels * 2 * sizeof(float));
    place(profiles_region_, profile_cells * sizeof(float));
    place(beam_profiles_region_, (sidelobes_ ? padded_cells : cells) * sizeof(float));
    place(status_region_, sizeof(std::uint32_t));
    for (Buffer& slot : readbacks_) { // slot 1: for render-ahead (start() with keep_last)
        auto readback = create_buffer(context_, readback_bytes, VK_BUFFER_USAGE_TRANSFER_DST_BIT, MemoryUse::readback);
        if (!readback) return readback.error();
        slot = std::move(readback.value());
    }

    return {};
}

Result<void> VulkanBackend::create_descriptors(const TableViews& views) {
    VkDevice device = context_.device;
    const VkAllocationCallbacks* allocator = context_.allocator;
    const std::uint32_t materials_vec4s = views.materials, column_table_vec4s = views.column_table,
                        beam_table_vec4s = views.beam_table, sidelobe_vec4s = views.sidelobe,
                        far_table_vec4s = views.far_table;
    // Descriptors: one set for every compute stage.
    auto set_layout = create_compute_set_layout(context_);
    if (!set_layout) return set_layout.error();
    set_layout_ = std::move(set_layout.value());
    VkDescriptorSetLayout set_layout_handle = set_layout_.get();
    // profile.comp's rows of one dispatch (profile_bands.h) are its push constants.
    const VkPushConstantRange profile_rows{VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof(shared::ProfileRowBand)};
    VkPipelineLayoutCreateInfo layout_info{};
    layout_info.sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO;
    layout_info.setLayoutCount = 1;
    layout_info.pSetLayouts = &set_layout_handle;
    layout_info.pushConstantRangeCount = 1;
    layout_info.pPushConstantRanges = &profile_rows;
    VkPipelineLayout layout = VK_NULL_HANDLE;
    VKS_VK_TRY(context_.fn.vkCreatePipelineLayout(device, &layout_info, allocator, &layout));
    compute_layout_ = OwnedPipelineLayout(context_, layout);

    std::array<VkDescriptorPoolSize, 2> pool_sizes{
        {{VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER, kUniformBindings},
         {VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, binding_count - kUniformBindings}}};
    VkDescriptorPoolCreateInfo pool_info{};
    pool_info.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO;
    pool_info.maxSets = 1;
    pool_info.poolSizeCount = static_cast<std::uint32_t>(pool_sizes.size());
    pool_info.pPoolSizes = pool_sizes.data();
    VkDescriptorPool pool = VK_NULL_HANDLE;
    VKS_VK_TRY(context_.fn.vkCreateDescriptorPool(device, &pool_info, allocator, &pool));
    descriptor_pool_ = OwnedDescriptorPool(context_, pool);
    VkDescriptorSetAllocateInfo set_info{};
    set_info.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO;
    set_info.descriptorPool = pool;
    set_info.descriptorSetCount = 1;
    set_info.pSetLayouts = &set_layout_handle;
    VKS_VK_TRY(context_.fn.vkAllocateDescriptorSets(device, &set_info, &descriptor_set_));

    const std::array<const Buffer*, binding_count> bound{
        &params_,          &depth_,      &material_id_,     &normals_,    &echo_,         &profiles_,
        &beam_profiles_,   &polar_,      &slice_info_,      &materials_,  &column_table_, &beam_table_,
        &sidelobe_weight_, &cone_coord_, &far_table_,       &far_energy_, &far_cells_,    &materials_,
        &column_table_,    &beam_table_, &sidelobe_weight_, &far_table_,  &subpixel_,     &status_};
    // A uniform view spans its table's vec4s, or only the first when the table is read through its
    // storage binding (the shader then declares a one-vec4 block and never reads it).
    const std::array<std::uint32_t, binding_far_table_uniform + 1 - binding_materials_uniform> uniform_views{
        materials_vec4s, column_table_vec4s, beam_table_vec4s, sidelobe_vec4s, far_table_vec4s};
    std::array<VkDescriptorBufferInfo, binding_count> infos{};
    std::array<VkWriteDescriptorSet, binding_count> writes{};
    for (std::uint32_t i = 0; i < binding_count; ++i) {
        VkDeviceSize range = VK_WHOLE_SIZE;
        if (descriptor_type(i) == VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER && i >= binding_materials_uniform)
            range = 16 * VkDeviceSize(std::max(uniform_views[i - binding_materials_uniform], 1u));
        infos[i] = {bound[i]->get(), 0, range};
        writes[i] = {};
        writes[i].sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET;
        writes[i].dstSet = descriptor_set_;
        writes[i].dstBinding = i;
        writes[i].descriptorCount = 1;
        writes[i].descriptorType = descriptor_type(i);
        writes[i].pBufferInfo = &infos[i];
    }
    context_.fn.vkUpdateDescriptorSets(device, binding_count, writes.data(), 0, nullptr);

    return {};
}

Result<void> VulkanBackend::create_compute_pipelines(const TableViews& views) {
    const std::uint32_t materials_vec4s = views.materials, column_table_vec4s = views.column_table,
                        beam_table_vec4s = views.beam_table, sidelobe_vec4s = views.sidelobe,
                        far_table_vec4s = views.far_table;
    // Pipelines, specialized on the resolved effects: a disabled term is compiled out.
    auto make = [&](OwnedPipeline& pipeline, const std::uint32_t* code, std::size_t bytes,
                    const auto& constants) -> Result<void> {
        auto module = create_shader_module(context_, code, bytes);
        if (!module) return module.error();
        auto created = create_compute_pipeline(context_, compute_layout_.get(), module->get(), constants);
        if (!created) return created.error();
        pipeline = std::move(created.value());
        return {};
    };
    // Where a stage reads two tables, both go through their uniform views or neither does.
    auto both_uniform = [](std::uint32_t a, std::uint32_t b = 1) { return a > 0 && b > 0 ? 1u : 0u; };
    if (incidence_) { // only its own stencil is compiled in (shaders/normals.comp)
        NormalsSpecialization normals;
        normals.pixels_per_invocation = kNormalsRun;
        normals.normal_method = plan_.params.normal_method;
        normals.tier_views = plan_.views > plan_.slices ? 1u : 0u;
        if (auto r = make(normals_pipeline_, normals_comp_spv, sizeof(normals_comp_spv), normals.constants()); !r)
            return r;
    }
    EchoSpecialization echo;
    echo.effect_flags = plan_.effects.shader_flags();
    echo.pixels_per_invocation = kEchoPixels;
    echo.rough_materials = plan_.rough_materials ? 1u : 0u; // else the facet term is compiled out
    echo.vertical_shape = plan_.params.vpattern_shape;      // only its code is compiled in
    echo.uniform_tables = both_uniform(materials_vec4s);
    echo.material_vec4s = echo.uniform_tables ? materials_vec4s : 1u;
    echo.echo_half = gpu_params_.echo_half;
    echo.tier_views = plan_.views > plan_.slices ? 1u : 0u;
    if (auto r = make(echo_pipeline_, echo_comp_spv, sizeof(echo_comp_spv), echo.constants()); !r) return r;
    ProfileSpecialization profile;
    profile.range_kernel = plan_.params.range_kernel;
    profile.echo_half = gpu_params_.echo_half;
    profile.line_array = plan_.line_array ? 1u : 0u;
    profile.cones_per_invocation = shape_.cones_per_invocation;
    profile.bin_lanes = shape_.bin_lanes;
    profile.subpixel = plan_.subpixel_capacity > 0 ? 1u : 0u; // else its loop is compiled out
    profile.tier_views = plan_.views > plan_.slices ? 1u : 0u;
    if (shape_.gather_rows && (!plan_.line_array || shape_.cones_per_invocation == 1) &&
        shape_.bin_lanes == kProfileBinLanes) {
        // planar: one pixel a row (the lists are not used)
        const std::uint32_t candidates = plan_.line_array ? most_row_candidates(plan_) : 1u;
        const std::uint32_t bins_padded = gpu_params_.bins_padded;
        // profile.comp's shared arrays, in words: accumulators, pixel lists, counts, first columns, and one
        // round's spreads (12 words), energies and first shares (4)
        const std::size_t shared_bytes = 4 * (2 * std::size_t(bins_padded) + 2 * 32 * std::size_t(candidates) + 64 +
                                              4 * (shared::kMaxViews + 1) + 64 * (12 + 1 + 4));
        if (candidates > 0 && candidates <= kMaxRowCandidates &&
            shared_bytes <= context_.properties.limits.maxComputeSharedMemorySize) {
            profile.gather_rows = 1;
            profile.row_candidates = candidates;
            profile.shared_bins = bins_padded;
        }
    }
    if (auto r = make(profile_pipeline_, profile_comp_spv, sizeof(profile_comp_spv), profile.constants()); !r) return r;
    profile_bands_ =
        profile_row_bands(plan_, shape_, profile.gather_rows != 0 || options_.profile_rows == ProfileRows::whole);
    // resample.comp walks each run's columns once where that adds the same terms in the same order as
    // the gather (src/vk/resample_walk.h). ResampleMethod::gather keeps the gather (tests compare the two).
    const bool force_gather = options_.resample == ResampleMethod::gather;
    ResampleSpecialization resample;
    resample.beams_per_invocation = shape_.beams_per_invocation;
    resample.beam_major_out = sidelobes_ ? 1u : 0u; // only read back then (Frame::beam_profiles)
    resample.walk = !force_gather && resample_can_walk(plan_, shape_.beams_per_invocation) ? 1u : 0u;
    resample.uniform_tables = both_uniform(column_table_vec4s, beam_table_vec4s);
    resample.column_vec4s = resample.uniform_tables ? column_table_vec4s : 1u;
    resample.beam_vec4s = resample.uniform_tables ? beam_table_vec4s : 1u;
    if (auto r = make(resample_pipeline_, resample_comp_spv, sizeof(resample_comp_spv), resample.constants()); !r)
        return r;
    if (sidelobes_) {
        SidelobeSpecialization sidelobe;
        sidelobe.beams_per_invocation = shape_.beams_per_invocation;
        sidelobe.vec4_out = plan_.beams % 4 == 0 ? 1u : 0u;
        sidelobe.uniform_tables = both_uniform(sidelobe_vec4s, far_table_vec4s);
        sidelobe.weight_vec4s = sidelobe.uniform_tables ? sidelobe_vec4s : 1u;
        sidelobe.far_sidelobes = far_sidelobes_ ? 1u : 0u;
        sidelobe.near_bands = plan_.near_bands;
        sidelobe.far_table_vec4s = sidelobe.uniform_tables ? far_table_vec4s : 1u;
        if (auto r = make(sidelobe_pipeline_, sidelobe_comp_spv, sizeof(sidelobe_comp_spv), sidelobe.constants()); !r)
            return r;
    }
    if (far_sidelobes_) {
        FarSidelobeSpecialization far;
        far.uniform_tables = both_uniform(far_table_vec4s);
        far.far_table_vec4s = far.uniform_tables ? far_table_vec4s : 1u;
        for (OwnedPipeline* pipeline : {&far_deposit_pipeline_, &far_convolve_pipeline_}) {
            if (auto r = make(*pipeline, far_sidelobe_comp_spv, sizeof(far_sidelobe_comp_spv), far.constants()); !r)
                return r;
            far.pass = stage_table::far_cell_groups(plan_, shape_) ? 2u : 1u;
        }
    }
    return {};
}

Result<void> VulkanBackend::create_commands() {
    VkDevice device = context_.device;
    const VkAllocationCallbacks* allocator = context_.allocator;
    VkCommandPoolCreateInfo pool_info{};
    pool_info.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
    pool_info.queueFamilyIndex = context_.queue_family;
    pool_info.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT; // render() records the depth pass's alone
    VkCommandPool pool = VK_NULL_HANDLE;
    VKS_VK_TRY(context_.fn.vkCreateCommandPool(device, &pool_info, allocator, &pool));
    command_pool_ = OwnedCommandPool(context_, pool);
    VkCommandBufferAllocateInfo allocate_info{};
    allocate_info.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO;
    allocate_info.commandPool = pool;
    allocate_info.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    allocate_info.commandBufferCount = kCommandBufferCount;
    for (auto& slot : command_buffers_)
        VKS_VK_TRY(context_.fn.vkAllocateCommandBuffers(device, &allocate_info, slot.data()));

    VkFenceCreateInfo fence_info{};
    fence_info.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO;
    // Signalled, as a fence whose work is done (every submit resets it first).
    fence_info.flags = VK_FENCE_CREATE_SIGNALED_BIT;
    for (OwnedFence& owned : fences_) {
        VkFence fence = VK_NULL_HANDLE;
        VKS_VK_TRY(context_.fn.vkCreateFence(device, &fence_info, allocator, &fence));
        owned = OwnedFence(context_, fence);
    }

    // Stage times: timestamp queries where the queue has them, except on CPU devices. lavapipe's
    // timestamps do not bracket compute dispatches (a dispatch's time shows up in a neighbouring
    // interval), and there one submission per stage costs ~10 us against stages of milliseconds.
    // RendererOptions::stage_timing = host | timestamps overrides the choice.
    const bool can_timestamp = context_.timestamp_valid_bits > 0 && context_.properties.limits.timestampPeriod > 0.0f;
    timestamps_ = can_timestamp && context_.properties.deviceType != VK_PHYSICAL_DEVICE_TYPE_CPU;
    if (options_.stage_timing == StageTiming::host) timestamps_ = false;
    if (options_.stage_timing == StageTiming::timestamps || options_.stage_timing == StageTiming::passes)
        timestamps_ = can_timestamp;
    pass_timestamps_ = timestamps_ && options_.stage_timing == StageTiming::passes;
    if (timestamps_) {
        VkQueryPoolCreateInfo query_info{};
        query_info.sType = VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO;
        query_info.queryType = VK_QUERY_TYPE_TIMESTAMP;
        query_info.queryCount = kQueryCount * kFrameSlots;
        VkQueryPool query_pool = VK_NULL_HANDLE;
        VKS_VK_TRY(context_.fn.vkCreateQueryPool(device, &query_info, allocator, &query_pool));
        query_pool_ = OwnedQueryPool(context_, query_pool);
    }
    return {};
}

Result<std::unique_ptr<StageBackend>> make_backend(VulkanContext& context, const Plan& plan, const SceneData& scene,
                                                   const RendererOptions& options) {
    auto backend = std::make_unique<VulkanBackend>(context, plan, scene, options);
    if (auto r = backend->init(); !r) {
        return r.error();
    }
    return std::unique_ptr<StageBackend>(std::move(backend));
}

} // namespace vksonar::vk
