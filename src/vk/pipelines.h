// Pipelines of the stages: the depth-pass render pass + graphics pipeline, and the compute pipelines.
// All compute stages share one descriptor set layout (binding numbers: sonar_shared.h).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "sonar_shared.h"
#include "vk/handles.h"
#include "vksonar/result.h"

namespace vksonar::vk {

// Descriptor bindings of the compute stages (set 0): the shaders' names (sonar_shared.h) as host enums.
enum Binding : std::uint32_t {
    binding_params = shared::kBindingParams,
    binding_depth = shared::kBindingDepth,
    binding_material_id = shared::kBindingMaterialId,
    binding_normals = shared::kBindingNormals,
    binding_echo = shared::kBindingEcho,
    binding_profiles = shared::kBindingProfiles,
    binding_beam_profiles = shared::kBindingBeamProfiles,
    binding_polar = shared::kBindingPolar,
    binding_slice_info = shared::kBindingSliceInfo,
    binding_materials = shared::kBindingMaterials,
    binding_column_table = shared::kBindingColumnTable,
    binding_beam_table = shared::kBindingBeamTable,
    binding_sidelobe_weight = shared::kBindingSidelobeWeight,
    binding_cone_coord = shared::kBindingConeCoord,
    binding_far_table = shared::kBindingFarTable,
    binding_far_energy = shared::kBindingFarEnergy,
    binding_far_cells = shared::kBindingFarCells,
    // The same five tables as uniform blocks (below): bound to the same buffers.
    binding_materials_uniform = shared::kBindingMaterialsUniform,
    binding_column_table_uniform = shared::kBindingColumnTableUniform,
    binding_beam_table_uniform = shared::kBindingBeamTableUniform,
    binding_sidelobe_weight_uniform = shared::kBindingSidelobeWeightUniform,
    binding_far_table_uniform = shared::kBindingFarTableUniform,
    binding_subpixel = shared::kBindingSubpixel, // after the uniform views (sonar_shared.h)
    binding_status = shared::kBindingStatus,
    binding_count = shared::kBindingCount,
};

// Small read-only tables live in uniform blocks where they fit the device's maxUniformBufferRange: a
// GPU serves them from its constant cache, and lavapipe (Mesa 22's llvmpipe) turns a uniform-block
// load at a workgroup-uniform index into one scalar load and a divergent one into a vector gather,
// where every storage-buffer load is a branchy loop over the lanes. A table that does not fit is read
// through its storage binding instead; specialization constant kSpecUniformTables tells the shader which.
constexpr VkDescriptorType descriptor_type(std::uint32_t binding) {
    return binding == binding_params || binding == binding_slice_info ||
                   (binding >= binding_materials_uniform && binding <= binding_far_table_uniform)
               ? VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER
               : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
}
constexpr std::uint32_t count_uniform_bindings() {
    std::uint32_t n = 0;
    for (std::uint32_t i = 0; i < binding_count; ++i)
        n += descriptor_type(i) == VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER;
    return n;
}
constexpr std::uint32_t kUniformBindings = count_uniform_bindings(); // for the descriptor pool

constexpr VkFormat kDepthFormat = VK_FORMAT_D32_SFLOAT;
constexpr VkFormat kMaterialFormat = VK_FORMAT_R32_UINT;
constexpr VkFormat kFaceNormalFormat = VK_FORMAT_R32G32B32A32_SFLOAT; // colour attachment + copy: mandatory

[[nodiscard]] Result<OwnedShaderModule> create_shader_module(const VulkanContext& context, const std::uint32_t* code,
                                                             std::size_t bytes);

[[nodiscard]] Result<OwnedDescriptorSetLayout> create_compute_set_layout(const VulkanContext& context);

// One specialization constant: its id (shared::kSpec*) and value.
struct SpecConstant {
    std::uint32_t id = 0, value = 0;
};

// Each compute shader's specialization constants, one struct per shader, member by member as the
// shader declares them. Switches that the shaders could read from the uniform SonarParams are
// specialization constants instead: lavapipe runs both sides of a branch under a lane mask, loads and
// stores included, so a uniform branch costs the memory traffic of every path; a constant compiles the
// others out. Where a stage reads a table through a uniform block (uniform_tables), the block's size in
// vec4s is a constant too (>= 1).
struct NormalsSpecialization {
    std::uint32_t pixels_per_invocation = 8;
    std::uint32_t normal_method = shared::kNormalsSobel3;
    std::uint32_t tier_views = 0; // Plan::views > Plan::slices: else only the slices' code is compiled in
    std::array<SpecConstant, 3> constants() const {
        return {{{shared::kSpecPerInvocation, pixels_per_invocation},
                 {shared::kSpecNormalMethod, normal_method},
                 {shared::kSpecTierViews, tier_views}}};
    }
};
struct EchoSpecialization {
    std::uint32_t effect_flags = 0;
    std::uint32_t pixels_per_invocation = 4;
    std::uint32_t rough_materials = 0;
    std::uint32_t vertical_shape = shared::kPatternSinc;
    std::uint32_t uniform_tables = 0;
    std::uint32_t material_vec4s = 1;
    std::uint32_t echo_half = 0;
    std::uint32_t tier_views = 0;
    std::array<SpecConstant, 8> constants() const {
        return {{{shared::kSpecTierViews, tier_views},
                 {shared::kSpecEffectFlags, effect_flags},
                 {shared::kSpecPerInvocation, pixels_per_invocation},
                 {shared::kSpecRoughMaterials, rough_materials},
                 {shared::kSpecVerticalShape, vertical_shape},
                 {shared::kSpecUniformTables, uniform_tables},
                 {shared::kSpecTableVec4s0, material_vec4s},
                 {shared::kSpecEchoHalf, echo_half}}};
    }
};
struct ProfileSpecialization {
    std::uint32_t range_kernel = shared::kRangeKernelFootprint;
    std::uint32_t echo_half = 0;
    std::uint32_t line_array = 0;
    std::uint32_t cones_per_invocation = 4; // line_array
    std::uint32_t subpixel = 0;             // Plan::subpixel_capacity > 0
    std::uint32_t tier_views = 0;
    std::uint32_t bin_lanes = 1;      // invocations per column (DeviceShape)
    std::uint32_t gather_rows = 0;    // line_array: a block of rows at once (profile.comp gather_block_rows)
    std::uint32_t row_candidates = 1; // its most pixels of one row for one cone column
    std::uint32_t shared_bins = 1;    // its accumulators' length (bins_padded)
    std::array<SpecConstant, 10> constants() const {
        return {{{shared::kSpecTierViews, tier_views},
                 {shared::kSpecBinLanes, bin_lanes},
                 {shared::kSpecGatherRows, gather_rows},
                 {shared::kSpecRowCandidates, row_candidates},
                 {shared::kSpecSharedBins, shared_bins},
                 {shared::kSpecRangeKernel, range_kernel},
                 {shared::kSpecEchoHalf, echo_half},
                 {shared::kSpecLineArray, line_array},
                 {shared::kSpecPerInvocation, cones_per_invocation},
                 {shared::kSpecSubpixel, subpixel}}};
    }
};
struct ResampleSpecialization {
    std::uint32_t beams_per_invocation = 16;
    std::uint32_t beam_major_out = 1; // the side-lobe pass follows
    std::uint32_t walk = 0;           // src/vk/resample_walk.h
    std::uint32_t uniform_tables = 0;
    std::uint32_t column_vec4s = 1, beam_vec4s = 1;
    std::array<SpecConstant, 6> constants() const {
        return {{{shared::kSpecPerInvocation, beams_per_invocation},
                 {shared::kSpecBeamMajorOut, beam_major_out},
                 {shared::kSpecResampleWalk, walk},
                 {shared::kSpecUniformTables, uniform_tables},
                 {shared::kSpecTableVec4s0, column_vec4s},
                 {shared::kSpecTableVec4s1, beam_vec4s}}};
    }
};
struct SidelobeSpecialization {
    std::uint32_t beams_per_invocation = 16; // a multiple of 4
    std::uint32_t vec4_out = 0;
    std::uint32_t uniform_tables = 0;
    std::uint32_t weight_vec4s = 1;
    std::uint32_t far_sidelobes = 0; // Plan::far_cells > 0
    std::uint32_t far_table_vec4s = 1;
    std::uint32_t near_bands = 1; // Plan::near_bands
    std::array<SpecConstant, 7> constants() const {
        return {{{shared::kSpecPerInvocation, beams_per_invocation},
                 {shared::kSpecVec4Out, vec4_out},
                 {shared::kSpecUniformTables, uniform_tables},
                 {shared::kSpecTableVec4s0, weight_vec4s},
                 {shared::kSpecFarSidelobes, far_sidelobes},
                 {shared::kSpecTableVec4s1, far_table_vec4s},
                 {shared::kSpecNearBands, near_bands}}};
    }
};
struct FarSidelobeSpecialization {
    std::uint32_t pass = 0; // 0: deposit, 1: convolve, 2: convolve one cell per workgroup row
    std::uint32_t uniform_tables = 0;
    std::uint32_t far_table_vec4s = 1;
    std::array<SpecConstant, 3> constants() const {
        return {{{shared::kSpecFarPass, pass},
                 {shared::kSpecUniformTables, uniform_tables},
                 {shared::kSpecTableVec4s0, far_table_vec4s}}};
    }
};

// constants: count specialization constants (none: nullptr, 0), e.g. EchoSpecialization::constants().
[[nodiscard]] Result<OwnedPipeline> create_compute_pipeline(const VulkanContext& context, VkPipelineLayout layout,
                                                            VkShaderModule module, const SpecConstant* constants,
                                                            std::uint32_t count);
template <std::size_t N>
[[nodiscard]] Result<OwnedPipeline> create_compute_pipeline(const VulkanContext& context, VkPipelineLayout layout,
                                                            VkShaderModule module,
                                                            const std::array<SpecConstant, N>& constants) {
    return create_compute_pipeline(context, layout, module, constants.data(), static_cast<std::uint32_t>(N));
}

// Render pass of the depth pass: attachment 0 = material id (R32_UINT), 1 = depth (D32), and with
// face_normals 2 = face normal (RGBA32F, colour location 1), all cleared and left in
// TRANSFER_SRC_OPTIMAL for the copy to storage buffers.
[[nodiscard]] Result<OwnedRenderPass> create_depth_render_pass(const VulkanContext& context, bool face_normals);

// Graphics pipeline of the depth pass: vec3 positions, reversed-Z (GREATER), no culling, dynamic
// viewport/scissor (one per slice), DepthPush push constants in both stages. colour_attachments: 1
// (material id), or 2 with the face-normal attachment (depth_geometric.vert/.frag).
[[nodiscard]] Result<OwnedPipeline> create_depth_pipeline(const VulkanContext& context, VkRenderPass render_pass,
                                                          VkPipelineLayout layout, VkShaderModule vertex,
                                                          VkShaderModule fragment, std::uint32_t colour_attachments);

} // namespace vksonar::vk
