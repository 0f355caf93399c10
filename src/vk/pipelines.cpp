#include "vk/pipelines.h"

#include <array>

#include "vk/vk_error.h"

namespace vksonar::vk {

Result<OwnedShaderModule> create_shader_module(const VulkanContext& context, const std::uint32_t* code,
                                               std::size_t bytes) {
    VkShaderModuleCreateInfo info{};
    info.sType = VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO;
    info.codeSize = bytes;
    info.pCode = code;
    VkShaderModule module = VK_NULL_HANDLE;
    VKS_VK_TRY(context.fn.vkCreateShaderModule(context.device, &info, context.allocator, &module));
    return OwnedShaderModule(context, module);
}

Result<OwnedDescriptorSetLayout> create_compute_set_layout(const VulkanContext& context) {
    std::array<VkDescriptorSetLayoutBinding, binding_count> bindings{};
    for (std::uint32_t i = 0; i < binding_count; ++i) {
        bindings[i].binding = i;
        bindings[i].descriptorType = descriptor_type(i);
        bindings[i].descriptorCount = 1;
        bindings[i].stageFlags = VK_SHADER_STAGE_COMPUTE_BIT;
    }
    VkDescriptorSetLayoutCreateInfo info{};
    info.sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO;
    info.bindingCount = binding_count;
    info.pBindings = bindings.data();
    VkDescriptorSetLayout layout = VK_NULL_HANDLE;
    VKS_VK_TRY(context.fn.vkCreateDescriptorSetLayout(context.device, &info, context.allocator, &layout));
    return OwnedDescriptorSetLayout(context, layout);
}

Result<OwnedPipeline> create_compute_pipeline(const VulkanContext& context, VkPipelineLayout layout,
                                              VkShaderModule module, const SpecConstant* constants,
                                              std::uint32_t count) {
    // The values are laid out as the constants come; each map entry points at its own.
    std::array<VkSpecializationMapEntry, 16> entries{};
    std::array<std::uint32_t, 16> values{};
    if (count > entries.size()) {
        return make_error(ErrorCode::internal, "create_compute_pipeline: more than 16 specialization constants");
    }
    for (std::uint32_t i = 0; i < count; ++i) {
        values[i] = constants[i].value;
        entries[i] = {constants[i].id, static_cast<std::uint32_t>(i * sizeof(std::uint32_t)), sizeof(std::uint32_t)};
    }
    VkSpecializationInfo specialization{count, entries.data(), count * sizeof(std::uint32_t), values.data()};
    VkComputePipelineCreateInfo info{};
    info.sType = VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO;
    info.stage.sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    info.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
    info.stage.module = module;
    info.stage.pName = "main";
    info.stage.pSpecializationInfo = count > 0 ? &specialization : nullptr;
    info.layout = layout;
    VkPipeline pipeline = VK_NULL_HANDLE;
    VKS_VK_TRY(
        context.fn.vkCreateComputePipelines(context.device, VK_NULL_HANDLE, 1, &info, context.allocator, &pipeline));
    return OwnedPipeline(context, pipeline);
}

Result<OwnedRenderPass> create_depth_render_pass(const VulkanContext& context, bool face_normals) {
    std::array<VkAttachmentDescription, 3> attachments{};
    for (auto& attachment : attachments) {
        attachment.samples = VK_SAMPLE_COUNT_1_BIT;
        attachment.loadOp = VK_ATTACHMENT_LOAD_OP_CLEAR;
        attachment.storeOp = VK_ATTACHMENT_STORE_OP_STORE;
        attachment.stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
        attachment.stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
        attachment.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED; // fully cleared every frame
        attachment.finalLayout = VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL;
    }
    attachments[0].format = kMaterialFormat;
    attachments[1].format = kDepthFormat;
    attachments[2].format = kFaceNormalFormat;

    const std::array<VkAttachmentReference, 2> colour_refs{
        {{0, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL}, {2, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL}}};
    VkAttachmentReference depth_ref{1, VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL};
    VkSubpassDescription subpass{};
    subpass.pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
    subpass.colorAttachmentCount = face_normals ? 2u : 1u;
    subpass.pColorAttachments = colour_refs.data();
    subpass.pDepthStencilAttachment = &depth_ref;

    constexpr VkPipelineStageFlags attachment_stages = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT |
                                                       VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT |
                                                       VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT;
    constexpr VkAccessFlags attachment_writes =
        VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT | VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT;
    std::array<VkSubpassDependency, 2> dependencies{};
    // The previous frame's copy out of the images must finish before this frame clears them (WAR).
    dependencies[0].srcSubpass = VK_SUBPASS_EXTERNAL;
    dependencies[0].dstSubpass = 0;
    dependencies[0].srcStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT;
    dependencies[0].dstStageMask = attachment_stages;
    dependencies[0].srcAccessMask = 0;
    dependencies[0].dstAccessMask = attachment_writes | VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_READ_BIT;
    // Attachment writes (and the transition to TRANSFER_SRC) before the copy to storage buffers.
    dependencies[1].srcSubpass = 0;
    dependencies[1].dstSubpass = VK_SUBPASS_EXTERNAL;
    dependencies[1].srcStageMask = attachment_stages;
    dependencies[1].dstStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT;
    dependencies[1].srcAccessMask = attachment_writes;
    dependencies[1].dstAccessMask = VK_ACCESS_TRANSFER_READ_BIT;

    VkRenderPassCreateInfo info{};
    info.sType = VK_STRUCTURE_TYPE_RENDER_PASS_CREATE_INFO;
    info.attachmentCount = face_normals ? 3u : 2u;
    info.pAttachments = attachments.data();
    info.subpassCount = 1;
    info.pSubpasses = &subpass;
    info.dependencyCount = static_cast<std::uint32_t>(dependencies.size());
    info.pDependencies = dependencies.data();
    VkRenderPass render_pass = VK_NULL_HANDLE;
    VKS_VK_TRY(context.fn.vkCreateRenderPass(context.device, &info, context.allocator, &render_pass));
    return OwnedRenderPass(context, render_pass);
}

Result<OwnedPipeline> create_depth_pipeline(const VulkanContext& context, VkRenderPass render_pass,
                                            VkPipelineLayout layout, VkShaderModule vertex, VkShaderModule fragment,
                                            std::uint32_t colour_attachments) {
    std::array<VkPipelineShaderStageCreateInfo, 2> stages{};
    stages[0].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    stages[0].stage = VK_SHADER_STAGE_VERTEX_BIT;
    stages[0].module = vertex;
    stages[0].pName = "main";
    stages[1].sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    stages[1].stage = VK_SHADER_STAGE_FRAGMENT_BIT;
    stages[1].module = fragment;
    stages[1].pName = "main";

    VkVertexInputBindingDescription binding{0, 3 * sizeof(float), VK_VERTEX_INPUT_RATE_VERTEX};
    VkVertexInputAttributeDescription attribute{0, 0, VK_FORMAT_R32G32B32_SFLOAT, 0};
    VkPipelineVertexInputStateCreateInfo vertex_input{};
    vertex_input.sType = VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO;
    vertex_input.vertexBindingDescriptionCount = 1;
    vertex_input.pVertexBindingDescriptions = &binding;
    vertex_input.vertexAttributeDescriptionCount = 1;
    vertex_input.pVertexAttributeDescriptions = &attribute;

    VkPipelineInputAssemblyStateCreateInfo input_assembly{};
    input_assembly.sType = VK_STRUCTURE_TYPE_PIPELINE_INPUT_ASSEMBLY_STATE_CREATE_INFO;
    input_assembly.topology = VK_PRIMITIVE_TOPOLOGY_TRIANGLE_LIST;

    VkPipelineViewportStateCreateInfo viewport{};
    viewport.sType = VK_STRUCTURE_TYPE_PIPELINE_VIEWPORT_STATE_CREATE_INFO;
    viewport.viewportCount = 1;
    viewport.scissorCount = 1;

    VkPipelineRasterizationStateCreateInfo raster{};
    raster.sType = VK_STRUCTURE_TYPE_PIPELINE_RASTERIZATION_STATE_CREATE_INFO;
    raster.depthClampEnable = VK_FALSE; // clip 0 <= z <= w, as the CPU rasterizer does
    raster.polygonMode = VK_POLYGON_MODE_FILL;
    raster.cullMode = VK_CULL_MODE_NONE; // the sonar sees both sides of a surface
    raster.frontFace = VK_FRONT_FACE_COUNTER_CLOCKWISE;
    raster.lineWidth = 1.0f;

    VkPipelineMultisampleStateCreateInfo multisample{};
    multisample.sType = VK_STRUCTURE_TYPE_PIPELINE_MULTISAMPLE_STATE_CREATE_INFO;
    multisample.rasterizationSamples = VK_SAMPLE_COUNT_1_BIT;

    VkPipelineDepthStencilStateCreateInfo depth{};
    depth.sType = VK_STRUCTURE_TYPE_PIPELINE_DEPTH_STENCIL_STATE_CREATE_INFO;
    depth.depthTestEnable = VK_TRUE;
    depth.depthWriteEnable = VK_TRUE;
    depth.depthCompareOp = VK_COMPARE_OP_GREATER; // reversed-Z, strict
    depth.minDepthBounds = 0.0f;
    depth.maxDepthBounds = 1.0f;

    // No blending (integer and float targets). Without the independentBlend feature all attachments
    // need identical states: with the face normals both write RGBA (R32_UINT ignores G, B, A).
    std::array<VkPipelineColorBlendAttachmentState, 2> blend_attachments{};
    for (auto& state : blend_attachments) {
        state.colorWriteMask = colour_attachments > 1 ? VK_COLOR_COMPONENT_R_BIT | VK_COLOR_COMPONENT_G_BIT |
                                                            VK_COLOR_COMPONENT_B_BIT | VK_COLOR_COMPONENT_A_BIT
                                                      : VK_COLOR_COMPONENT_R_BIT;
    }
    VkPipelineColorBlendStateCreateInfo blend{};
    blend.sType = VK_STRUCTURE_TYPE_PIPELINE_COLOR_BLEND_STATE_CREATE_INFO;
    blend.attachmentCount = colour_attachments;
    blend.pAttachments = blend_attachments.data();

    std::array<VkDynamicState, 2> dynamic_states{VK_DYNAMIC_STATE_VIEWPORT, VK_DYNAMIC_STATE_SCISSOR};
    VkPipelineDynamicStateCreateInfo dynamic{};
    dynamic.sType = VK_STRUCTURE_TYPE_PIPELINE_DYNAMIC_STATE_CREATE_INFO;
    dynamic.dynamicStateCount = static_cast<std::uint32_t>(dynamic_states.size());
    dynamic.pDynamicStates = dynamic_states.data();

    VkGraphicsPipelineCreateInfo info{};
    info.sType = VK_STRUCTURE_TYPE_GRAPHICS_PIPELINE_CREATE_INFO;
    info.stageCount = static_cast<std::uint32_t>(stages.size());
    info.pStages = stages.data();
    info.pVertexInputState = &vertex_input;
    info.pInputAssemblyState = &input_assembly;
    info.pViewportState = &viewport;
    info.pRasterizationState = &raster;
    info.pMultisampleState = &multisample;
    info.pDepthStencilState = &depth;
    info.pColorBlendState = &blend;
    info.pDynamicState = &dynamic;
    info.layout = layout;
    info.renderPass = render_pass;
    info.subpass = 0;
    VkPipeline pipeline = VK_NULL_HANDLE;
    VKS_VK_TRY(
        context.fn.vkCreateGraphicsPipelines(context.device, VK_NULL_HANDLE, 1, &info, context.allocator, &pipeline));
    return OwnedPipeline(context, pipeline);
}

} // namespace vksonar::vk
