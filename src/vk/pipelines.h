// Pipelines of the stages: the depth-pass render pass + graphics pipeline, and the compute pipelines.
// All compute stages share one descriptor set layout (binding numbers: sonar_shared.h).
#pragma once

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
    // The same four tables as uniform blocks (below): bound to the same buffers.
    binding_materials_uniform = shared::kBindingMaterialsUniform,
    binding_column_table_uniform = shared::kBindingColumnTableUniform,
    binding_beam_table_uniform = shared::kBindingBeamTableUniform,
    binding_sidelobe_weight_uniform = shared::kBindingSidelobeWeightUniform,
    binding_count = shared::kBindingCount,
};

// Small read-only tables live in uniform blocks where they fit the device's maxUniformBufferRange: a
// GPU serves them from its constant cache, and lavapipe (Mesa 22's llvmpipe) turns a uniform-block
// load at a workgroup-uniform index into one scalar load and a divergent one into a vector gather,
// where every storage-buffer load is a branchy loop over the lanes. A table that does not fit is read
// through its storage binding instead; specialization constant 3 tells the shader which (Specialization).
constexpr VkDescriptorType descriptor_type(std::uint32_t binding) {
    return binding == binding_params || binding == binding_slice_info || binding >= binding_materials_uniform
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

[[nodiscard]] Result<OwnedShaderModule> create_shader_module(VkDevice device, const VkAllocationCallbacks* allocator,
                                                             const std::uint32_t* code, std::size_t bytes);

[[nodiscard]] Result<OwnedDescriptorSetLayout> create_compute_set_layout(VkDevice device,
                                                                         const VkAllocationCallbacks* allocator);

// Specialization constants of the compute shaders: member i is constant_id i (shared::kSpec*, checked
// in pipelines.cpp).
struct Specialization {
    std::uint32_t effect_flags = 0;        // 0: shared::kEffect* bits
    std::uint32_t per_invocation = 1;      // 1: pixels / beams one invocation handles, where the shader has it
    std::uint32_t variant = 0;             // 2: a per-shader switch, e.g. resample.comp's output layout
    std::uint32_t uniform_tables = 0;      // 3: 1 = read the tables through their uniform blocks
    std::uint32_t table_vec4s[2] = {1, 1}; // 4, 5: sizes of those uniform blocks in vec4s (>= 1)
    std::uint32_t echo_half = 0;           // 6: SonarParams::echo_half (echo.comp, profile.comp)
};
// Switches that the shaders could read from the uniform SonarParams are specialization constants
// instead: lavapipe runs both sides of a branch under a lane mask, loads and stores included, so a
// uniform branch costs the memory traffic of every path; a constant compiles the others out.

[[nodiscard]] Result<OwnedPipeline> create_compute_pipeline(VkDevice device, const VkAllocationCallbacks* allocator,
                                                            VkPipelineLayout layout, VkShaderModule module,
                                                            const Specialization& constants);

// Render pass of the depth pass: attachment 0 = material id (R32_UINT), 1 = depth (D32), and with
// face_normals 2 = face normal (RGBA32F, colour location 1), all cleared and left in
// TRANSFER_SRC_OPTIMAL for the copy to storage buffers.
[[nodiscard]] Result<OwnedRenderPass> create_depth_render_pass(VkDevice device, const VkAllocationCallbacks* allocator,
                                                               bool face_normals);

// Graphics pipeline of the depth pass: vec3 positions, reversed-Z (GREATER), no culling, dynamic
// viewport/scissor (one per slice), DepthPush push constants in both stages. colour_attachments: 1
// (material id), or 2 with the face-normal attachment (depth_geometric.vert/.frag).
[[nodiscard]] Result<OwnedPipeline> create_depth_pipeline(VkDevice device, const VkAllocationCallbacks* allocator,
                                                          VkRenderPass render_pass, VkPipelineLayout layout,
                                                          VkShaderModule vertex, VkShaderModule fragment,
                                                          std::uint32_t colour_attachments);

} // namespace vksonar::vk
