// Pipelines of the stages: the depth-pass render pass + graphics pipeline, and the compute pipelines.
// All compute stages share one descriptor set layout (binding numbers below, mirrored in each shader).
#pragma once

#include <cstddef>
#include <cstdint>

#include "vk/handles.h"
#include "vksonar/result.h"

namespace vksonar::vk {

// Descriptor bindings of the compute stages (set 0). Each shader declares the ones it uses.
enum Binding : std::uint32_t {
    binding_params = 0, // uniform SonarParams (std140)
    binding_depth = 1,
    binding_material_id = 2,
    binding_normals = 3,
    binding_echo = 4,
    binding_profiles = 5,
    binding_beam_profiles = 6,
    binding_polar = 7,
    binding_slice_info = 8,
    binding_materials = 9,
    binding_column_beam = 10,
    binding_column_weight = 11,
    binding_beam_column_begin = 12,
    binding_beam_column_end = 13,
    binding_sidelobe_weight = 14,
    binding_count = 15,
};

constexpr VkFormat kDepthFormat = VK_FORMAT_D32_SFLOAT;
constexpr VkFormat kMaterialFormat = VK_FORMAT_R32_UINT;
constexpr VkFormat kFaceNormalFormat = VK_FORMAT_R32G32B32A32_SFLOAT; // colour attachment + copy: mandatory

[[nodiscard]] Result<OwnedShaderModule> create_shader_module(VkDevice device, const VkAllocationCallbacks* allocator,
                                                             const std::uint32_t* code, std::size_t bytes);

[[nodiscard]] Result<OwnedDescriptorSetLayout> create_compute_set_layout(VkDevice device,
                                                                         const VkAllocationCallbacks* allocator);

// A compute pipeline specialized with constant 0 = `effect_flags` (shared::kEffect* bits) and
// constant 1 = `per_invocation` (how many pixels/beams one invocation handles, where the shader has it)
// and constant 2 = `variant` (a per-shader switch, e.g. resample.comp's output layout).
[[nodiscard]] Result<OwnedPipeline> create_compute_pipeline(VkDevice device, const VkAllocationCallbacks* allocator,
                                                            VkPipelineLayout layout, VkShaderModule module,
                                                            std::uint32_t effect_flags, std::uint32_t per_invocation,
                                                            std::uint32_t variant = 0);

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
