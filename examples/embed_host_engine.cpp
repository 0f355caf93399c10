// The example host engine (see embed_host_engine.h). Everything here is what an engine already has;
// nothing in this file knows about sonar.
#include "embed_host_engine.h"

#include <cmath>
#include <cstdio>
#include <cstring>

#include "host_depth.vert.spv.h"

namespace host {
namespace {

#define HOST_TRY(call)                                                                                                 \
    do {                                                                                                               \
        VkResult host_result_ = (call);                                                                                \
        if (host_result_ != VK_SUCCESS) return std::string(#call) + " failed: " + std::to_string(host_result_);        \
    } while (0)

VKAPI_ATTR VkBool32 VKAPI_CALL count_message(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                             VkDebugUtilsMessageTypeFlagsEXT,
                                             const VkDebugUtilsMessengerCallbackDataEXT* data, void* user) {
    if (severity & (VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT)) {
        static_cast<std::atomic<std::uint32_t>*>(user)->fetch_add(1);
        std::fprintf(stderr, "host engine: validation: %s\n", data && data->pMessage ? data->pMessage : "");
    }
    return VK_FALSE;
}

bool has_layer(const char* name) {
    std::uint32_t count = 0;
    vkEnumerateInstanceLayerProperties(&count, nullptr);
    std::vector<VkLayerProperties> layers(count);
    vkEnumerateInstanceLayerProperties(&count, layers.data());
    for (const auto& layer : layers) {
        if (std::strcmp(layer.layerName, name) == 0) return true;
    }
    return false;
}

using Mat4 = std::array<double, 16>; // column-major

Mat4 multiply(const Mat4& a, const Mat4& b) {
    Mat4 r{};
    for (int c = 0; c < 4; ++c)
        for (int row = 0; row < 4; ++row)
            for (int k = 0; k < 4; ++k)
                r[c * 4 + row] += a[k * 4 + row] * b[c * 4 + k];
    return r;
}

// camera_from_world for a camera with x right, y down, z forward (Vulkan's clip convention) mounted
// on a body whose pose is x forward, y left, z up.
Mat4 camera_from_world(const CameraPose& pose) {
    const double d = 3.14159265358979323846 / 180.0;
    const double cr = std::cos(pose.roll_deg * d), sr = std::sin(pose.roll_deg * d);
    const double cp = std::cos(pose.pitch_deg * d), sp = std::sin(pose.pitch_deg * d);
    const double cy = std::cos(pose.yaw_deg * d), sy = std::sin(pose.yaw_deg * d);
    // world_from_body rotation R = Rz Ry Rx (rows).
    const double R[3][3] = {{cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr},
                            {sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr},
                            {-sp, cp * sr, cp * cr}};
    const double t[3] = {pose.x_m, pose.y_m, pose.z_m};
    // body_from_world = R^T (p - t); camera = (-body_y, -body_z, body_x).
    double body[3][4];
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j)
            body[i][j] = R[j][i];
        body[i][3] = -(R[0][i] * t[0] + R[1][i] * t[1] + R[2][i] * t[2]);
    }
    const double sign[3] = {-1, -1, 1};
    const int from[3] = {1, 2, 0};
    Mat4 m{};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 4; ++j)
            m[j * 4 + i] = sign[i] * body[from[i]][j];
    m[15] = 1;
    return m;
}

Mat4 projection(const EngineOptions& o) {
    Mat4 p{};
    p[0] = 1.0 / o.tan_half_h;
    p[5] = 1.0 / o.tan_half_v;
    const double n = o.near_m, f = o.far_m;
    if (o.reversed_z) { // d = n (f - z) / (z (f - n))
        p[10] = -n / (f - n);
        p[14] = n * f / (f - n);
    } else { // d = f (z - n) / (z (f - n))
        p[10] = f / (f - n);
        p[14] = -n * f / (f - n);
    }
    p[11] = 1.0; // w = z
    return p;
}

std::uint32_t memory_type(VkPhysicalDevice device, std::uint32_t bits, VkMemoryPropertyFlags flags) {
    VkPhysicalDeviceMemoryProperties properties;
    vkGetPhysicalDeviceMemoryProperties(device, &properties);
    for (std::uint32_t i = 0; i < properties.memoryTypeCount; ++i) {
        if ((bits & (1u << i)) && (properties.memoryTypes[i].propertyFlags & flags) == flags) return i;
    }
    return UINT32_MAX;
}

} // namespace

Engine::~Engine() {
    if (device_ != VK_NULL_HANDLE) {
        vkDeviceWaitIdle(device_);
        vkDestroyFence(device_, fence_, nullptr);
        vkDestroyCommandPool(device_, command_pool_, nullptr);
        vkDestroyBuffer(device_, index_buffer_, nullptr);
        vkFreeMemory(device_, index_memory_, nullptr);
        vkDestroyBuffer(device_, vertex_buffer_, nullptr);
        vkFreeMemory(device_, vertex_memory_, nullptr);
        vkDestroyPipeline(device_, pipeline_, nullptr);
        vkDestroyPipelineLayout(device_, pipeline_layout_, nullptr);
        vkDestroyFramebuffer(device_, framebuffer_, nullptr);
        vkDestroyRenderPass(device_, render_pass_, nullptr);
        vkDestroyImageView(device_, depth_view_, nullptr);
        vkDestroyImage(device_, depth_image_, nullptr);
        vkFreeMemory(device_, depth_memory_, nullptr);
        vkDestroyDevice(device_, nullptr);
    }
    if (messenger_ != VK_NULL_HANDLE) {
        auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
            vkGetInstanceProcAddr(instance_, "vkDestroyDebugUtilsMessengerEXT"));
        if (destroy) destroy(instance_, messenger_, nullptr);
    }
    if (instance_ != VK_NULL_HANDLE) vkDestroyInstance(instance_, nullptr);
}

std::string Engine::create(const EngineOptions& options) {
    options_ = options;
    const bool validation = options.validation && has_layer("VK_LAYER_KHRONOS_validation");
    const char* layer = "VK_LAYER_KHRONOS_validation";
    VkApplicationInfo app{};
    app.sType = VK_STRUCTURE_TYPE_APPLICATION_INFO;
    app.pApplicationName = "vksonar embed_host";
    app.apiVersion = options.api_version;
    VkDebugUtilsMessengerCreateInfoEXT messenger_info{};
    messenger_info.sType = VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT;
    messenger_info.messageSeverity =
        VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
    messenger_info.messageType =
        VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT;
    messenger_info.pfnUserCallback = count_message;
    messenger_info.pUserData = options.message_counter ? options.message_counter : &validation_messages_;
    VkInstanceCreateInfo instance_info{};
    instance_info.sType = VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO;
    instance_info.pApplicationInfo = &app;
    instance_info.enabledLayerCount = validation ? 1 : 0;
    instance_info.ppEnabledLayerNames = &layer;
    // Validate every shader afresh: the layer's on-disk cache (~/.cache) would otherwise hide an error
    // that an earlier process on this machine happened to validate under other settings.
    const VkValidationFeatureDisableEXT no_shader_cache = VK_VALIDATION_FEATURE_DISABLE_SHADER_VALIDATION_CACHE_EXT;
    VkValidationFeaturesEXT features{};
    features.sType = VK_STRUCTURE_TYPE_VALIDATION_FEATURES_EXT;
    features.pNext = &messenger_info;
    features.disabledValidationFeatureCount = 1;
    features.pDisabledValidationFeatures = &no_shader_cache;
    const char* extensions[] = {VK_EXT_DEBUG_UTILS_EXTENSION_NAME, VK_EXT_VALIDATION_FEATURES_EXTENSION_NAME};
    instance_info.enabledExtensionCount = validation ? 2 : 0;
    instance_info.ppEnabledExtensionNames = extensions;
    instance_info.pNext = validation ? &features : nullptr;
    HOST_TRY(vkCreateInstance(&instance_info, nullptr, &instance_));
    if (validation) {
        auto create_messenger = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
            vkGetInstanceProcAddr(instance_, "vkCreateDebugUtilsMessengerEXT"));
        if (create_messenger) HOST_TRY(create_messenger(instance_, &messenger_info, nullptr, &messenger_));
    }

    std::uint32_t count = 0;
    HOST_TRY(vkEnumeratePhysicalDevices(instance_, &count, nullptr));
    std::vector<VkPhysicalDevice> devices(count);
    HOST_TRY(vkEnumeratePhysicalDevices(instance_, &count, devices.data()));
    for (VkPhysicalDevice device : devices) {
        std::uint32_t family_count = 0;
        vkGetPhysicalDeviceQueueFamilyProperties(device, &family_count, nullptr);
        std::vector<VkQueueFamilyProperties> families(family_count);
        vkGetPhysicalDeviceQueueFamilyProperties(device, &family_count, families.data());
        for (std::uint32_t i = 0; i < family_count && physical_device_ == VK_NULL_HANDLE; ++i) {
            if ((families[i].queueFlags & (VK_QUEUE_GRAPHICS_BIT | VK_QUEUE_COMPUTE_BIT)) ==
                (VK_QUEUE_GRAPHICS_BIT | VK_QUEUE_COMPUTE_BIT)) {
                physical_device_ = device;
                queue_family_ = i;
            }
        }
    }
    if (physical_device_ == VK_NULL_HANDLE) return "no device with a graphics + compute queue";
    const float priority = 1.0f;
    VkDeviceQueueCreateInfo queue_info{};
    queue_info.sType = VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO;
    queue_info.queueFamilyIndex = queue_family_;
    queue_info.queueCount = 1;
    queue_info.pQueuePriorities = &priority;
    VkDeviceCreateInfo device_info{};
    device_info.sType = VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO;
    device_info.queueCreateInfoCount = 1;
    device_info.pQueueCreateInfos = &queue_info;
    HOST_TRY(vkCreateDevice(physical_device_, &device_info, nullptr, &device_));
    vkGetDeviceQueue(device_, queue_family_, 0, &queue_);

    // Depth target: attachment for the engine's pass, sampled by whoever reads depth next (vksonar),
    // transfer source for copies.
    VkImageCreateInfo image_info{};
    image_info.sType = VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO;
    image_info.imageType = VK_IMAGE_TYPE_2D;
    image_info.format = options.depth_format;
    image_info.extent = {options.width, options.height, 1};
    image_info.mipLevels = 1;
    image_info.arrayLayers = 1;
    image_info.samples = VK_SAMPLE_COUNT_1_BIT;
    image_info.tiling = VK_IMAGE_TILING_OPTIMAL;
    image_info.usage =
        VK_IMAGE_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT | VK_IMAGE_USAGE_SAMPLED_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT;
    HOST_TRY(vkCreateImage(device_, &image_info, nullptr, &depth_image_));
    VkMemoryRequirements requirements;
    vkGetImageMemoryRequirements(device_, depth_image_, &requirements);
    VkMemoryAllocateInfo allocate{};
    allocate.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO;
    allocate.allocationSize = requirements.size;
    allocate.memoryTypeIndex = memory_type(physical_device_, requirements.memoryTypeBits, 0);
    HOST_TRY(vkAllocateMemory(device_, &allocate, nullptr, &depth_memory_));
    HOST_TRY(vkBindImageMemory(device_, depth_image_, depth_memory_, 0));
    VkImageViewCreateInfo view_info{};
    view_info.sType = VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO;
    view_info.image = depth_image_;
    view_info.viewType = VK_IMAGE_VIEW_TYPE_2D;
    view_info.format = options.depth_format;
    view_info.subresourceRange = {VK_IMAGE_ASPECT_DEPTH_BIT, 0, 1, 0, 1};
    HOST_TRY(vkCreateImageView(device_, &view_info, nullptr, &depth_view_));

    // Depth-only render pass; the image ends read-only so compute (vksonar) can sample it.
    VkAttachmentDescription attachment{};
    attachment.format = options.depth_format;
    attachment.samples = VK_SAMPLE_COUNT_1_BIT;
    attachment.loadOp = VK_ATTACHMENT_LOAD_OP_CLEAR;
    attachment.storeOp = VK_ATTACHMENT_STORE_OP_STORE;
    attachment.stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
    attachment.stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
    attachment.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
    attachment.finalLayout = VK_IMAGE_LAYOUT_DEPTH_STENCIL_READ_ONLY_OPTIMAL;
    VkAttachmentReference depth_ref{0, VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL};
    VkSubpassDescription subpass{};
    subpass.pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
    subpass.pDepthStencilAttachment = &depth_ref;
    std::array<VkSubpassDependency, 2> dependencies{};
    // Earlier readers (last frame's compute or copy) before this frame's clear and writes.
    dependencies[0] = {VK_SUBPASS_EXTERNAL,
                       0,
                       VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                       VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT | VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT,
                       0,
                       VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_READ_BIT | VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT,
                       0};
    // Depth writes before compute/copy reads after the pass.
    dependencies[1] = {0,
                       VK_SUBPASS_EXTERNAL,
                       VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT | VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT,
                       VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                       VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT,
                       VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_TRANSFER_READ_BIT,
                       0};
    VkRenderPassCreateInfo pass_info{};
    pass_info.sType = VK_STRUCTURE_TYPE_RENDER_PASS_CREATE_INFO;
    pass_info.attachmentCount = 1;
    pass_info.pAttachments = &attachment;
    pass_info.subpassCount = 1;
    pass_info.pSubpasses = &subpass;
    pass_info.dependencyCount = static_cast<std::uint32_t>(dependencies.size());
    pass_info.pDependencies = dependencies.data();
    HOST_TRY(vkCreateRenderPass(device_, &pass_info, nullptr, &render_pass_));
    VkFramebufferCreateInfo framebuffer_info{};
    framebuffer_info.sType = VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO;
    framebuffer_info.renderPass = render_pass_;
    framebuffer_info.attachmentCount = 1;
    framebuffer_info.pAttachments = &depth_view_;
    framebuffer_info.width = options.width;
    framebuffer_info.height = options.height;
    framebuffer_info.layers = 1;
    HOST_TRY(vkCreateFramebuffer(device_, &framebuffer_info, nullptr, &framebuffer_));

    VkPushConstantRange push{VK_SHADER_STAGE_VERTEX_BIT, 0, 64};
    VkPipelineLayoutCreateInfo layout_info{};
    layout_info.sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO;
    layout_info.pushConstantRangeCount = 1;
    layout_info.pPushConstantRanges = &push;
    HOST_TRY(vkCreatePipelineLayout(device_, &layout_info, nullptr, &pipeline_layout_));
    VkShaderModuleCreateInfo module_info{};
    module_info.sType = VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO;
    module_info.codeSize = sizeof(host_depth_vert_spv);
    module_info.pCode = host_depth_vert_spv;
    VkShaderModule module = VK_NULL_HANDLE;
    HOST_TRY(vkCreateShaderModule(device_, &module_info, nullptr, &module));
    VkPipelineShaderStageCreateInfo stage{};
    stage.sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO;
    stage.stage = VK_SHADER_STAGE_VERTEX_BIT;
    stage.module = module;
    stage.pName = "main";
    VkVertexInputBindingDescription binding{0, 3 * sizeof(float), VK_VERTEX_INPUT_RATE_VERTEX};
    VkVertexInputAttributeDescription attribute{0, 0, VK_FORMAT_R32G32B32_SFLOAT, 0};
    VkPipelineVertexInputStateCreateInfo vertex_input{};
    vertex_input.sType = VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO;
    vertex_input.vertexBindingDescriptionCount = 1;
    vertex_input.pVertexBindingDescriptions = &binding;
    vertex_input.vertexAttributeDescriptionCount = 1;
    vertex_input.pVertexAttributeDescriptions = &attribute;
    VkPipelineInputAssemblyStateCreateInfo assembly{};
    assembly.sType = VK_STRUCTURE_TYPE_PIPELINE_INPUT_ASSEMBLY_STATE_CREATE_INFO;
    assembly.topology = VK_PRIMITIVE_TOPOLOGY_TRIANGLE_LIST;
    VkViewport viewport{0, 0, float(options.width), float(options.height), 0, 1};
    VkRect2D scissor{{0, 0}, {options.width, options.height}};
    VkPipelineViewportStateCreateInfo viewport_state{};
    viewport_state.sType = VK_STRUCTURE_TYPE_PIPELINE_VIEWPORT_STATE_CREATE_INFO;
    viewport_state.viewportCount = 1;
    viewport_state.pViewports = &viewport;
    viewport_state.scissorCount = 1;
    viewport_state.pScissors = &scissor;
    VkPipelineRasterizationStateCreateInfo raster{};
    raster.sType = VK_STRUCTURE_TYPE_PIPELINE_RASTERIZATION_STATE_CREATE_INFO;
    raster.polygonMode = VK_POLYGON_MODE_FILL;
    raster.cullMode = VK_CULL_MODE_NONE;
    raster.lineWidth = 1.0f;
    VkPipelineMultisampleStateCreateInfo multisample{};
    multisample.sType = VK_STRUCTURE_TYPE_PIPELINE_MULTISAMPLE_STATE_CREATE_INFO;
    multisample.rasterizationSamples = VK_SAMPLE_COUNT_1_BIT;
    VkPipelineDepthStencilStateCreateInfo depth_state{};
    depth_state.sType = VK_STRUCTURE_TYPE_PIPELINE_DEPTH_STENCIL_STATE_CREATE_INFO;
    depth_state.depthTestEnable = VK_TRUE;
    depth_state.depthWriteEnable = VK_TRUE;
    depth_state.depthCompareOp = options.reversed_z ? VK_COMPARE_OP_GREATER : VK_COMPARE_OP_LESS;
    VkGraphicsPipelineCreateInfo pipeline_info{};
    pipeline_info.sType = VK_STRUCTURE_TYPE_GRAPHICS_PIPELINE_CREATE_INFO;
    pipeline_info.stageCount = 1; // depth only: no fragment shader
    pipeline_info.pStages = &stage;
    pipeline_info.pVertexInputState = &vertex_input;
    pipeline_info.pInputAssemblyState = &assembly;
    pipeline_info.pViewportState = &viewport_state;
    pipeline_info.pRasterizationState = &raster;
    pipeline_info.pMultisampleState = &multisample;
    pipeline_info.pDepthStencilState = &depth_state;
    pipeline_info.layout = pipeline_layout_;
    pipeline_info.renderPass = render_pass_;
    VkResult made = vkCreateGraphicsPipelines(device_, VK_NULL_HANDLE, 1, &pipeline_info, nullptr, &pipeline_);
    vkDestroyShaderModule(device_, module, nullptr);
    HOST_TRY(made);

    VkCommandPoolCreateInfo pool_info{};
    pool_info.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
    pool_info.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
    pool_info.queueFamilyIndex = queue_family_;
    HOST_TRY(vkCreateCommandPool(device_, &pool_info, nullptr, &command_pool_));
    VkCommandBufferAllocateInfo buffer_info{};
    buffer_info.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO;
    buffer_info.commandPool = command_pool_;
    buffer_info.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    buffer_info.commandBufferCount = 1;
    HOST_TRY(vkAllocateCommandBuffers(device_, &buffer_info, &command_buffer_));
    VkFenceCreateInfo fence_info{};
    fence_info.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO;
    HOST_TRY(vkCreateFence(device_, &fence_info, nullptr, &fence_));
    return {};
}

std::string Engine::create_buffer(VkDeviceSize size, VkBufferUsageFlags usage, VkBuffer& buffer,
                                  VkDeviceMemory& memory) {
    VkBufferCreateInfo info{};
    info.sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO;
    info.size = size;
    info.usage = usage;
    HOST_TRY(vkCreateBuffer(device_, &info, nullptr, &buffer));
    VkMemoryRequirements requirements;
    vkGetBufferMemoryRequirements(device_, buffer, &requirements);
    VkMemoryAllocateInfo allocate{};
    allocate.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO;
    allocate.allocationSize = requirements.size;
    allocate.memoryTypeIndex = memory_type(physical_device_, requirements.memoryTypeBits,
                                           VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT);
    if (allocate.memoryTypeIndex == UINT32_MAX) return "no host-visible memory";
    HOST_TRY(vkAllocateMemory(device_, &allocate, nullptr, &memory));
    HOST_TRY(vkBindBufferMemory(device_, buffer, memory, 0));
    return {};
}

std::string Engine::upload(const std::vector<Mesh>& meshes) {
    std::vector<float> positions;
    std::vector<std::uint32_t> indices;
    for (const Mesh& mesh : meshes) {
        draws_.push_back({static_cast<std::uint32_t>(indices.size()), static_cast<std::uint32_t>(mesh.indices.size()),
                          static_cast<std::uint32_t>(positions.size() / 3)});
        positions.insert(positions.end(), mesh.positions.begin(), mesh.positions.end());
        indices.insert(indices.end(), mesh.indices.begin(), mesh.indices.end());
    }
    // Host-visible buffers read directly by the vertex stage: fine for an example.
    std::string error = create_buffer(positions.size() * sizeof(float), VK_BUFFER_USAGE_VERTEX_BUFFER_BIT,
                                      vertex_buffer_, vertex_memory_);
    if (!error.empty()) return error;
    error = create_buffer(indices.size() * sizeof(std::uint32_t), VK_BUFFER_USAGE_INDEX_BUFFER_BIT, index_buffer_,
                          index_memory_);
    if (!error.empty()) return error;
    void* mapped = nullptr;
    HOST_TRY(vkMapMemory(device_, vertex_memory_, 0, VK_WHOLE_SIZE, 0, &mapped));
    std::memcpy(mapped, positions.data(), positions.size() * sizeof(float));
    vkUnmapMemory(device_, vertex_memory_);
    HOST_TRY(vkMapMemory(device_, index_memory_, 0, VK_WHOLE_SIZE, 0, &mapped));
    std::memcpy(mapped, indices.data(), indices.size() * sizeof(std::uint32_t));
    vkUnmapMemory(device_, index_memory_);
    return {};
}

std::string Engine::begin_frame(const CameraPose& camera) {
    if (in_flight_) { // the previous frame's command buffer may still be executing
        HOST_TRY(vkWaitForFences(device_, 1, &fence_, VK_TRUE, UINT64_MAX));
        in_flight_ = false;
    }
    HOST_TRY(vkResetCommandBuffer(command_buffer_, 0));
    VkCommandBufferBeginInfo begin{};
    begin.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    HOST_TRY(vkBeginCommandBuffer(command_buffer_, &begin));
    VkClearValue clear{};
    clear.depthStencil = {options_.reversed_z ? 0.0f : 1.0f, 0};
    VkRenderPassBeginInfo pass{};
    pass.sType = VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO;
    pass.renderPass = render_pass_;
    pass.framebuffer = framebuffer_;
    pass.renderArea = {{0, 0}, {options_.width, options_.height}};
    pass.clearValueCount = 1;
    pass.pClearValues = &clear;
    vkCmdBeginRenderPass(command_buffer_, &pass, VK_SUBPASS_CONTENTS_INLINE);
    vkCmdBindPipeline(command_buffer_, VK_PIPELINE_BIND_POINT_GRAPHICS, pipeline_);
    const VkDeviceSize zero = 0;
    vkCmdBindVertexBuffers(command_buffer_, 0, 1, &vertex_buffer_, &zero);
    vkCmdBindIndexBuffer(command_buffer_, index_buffer_, 0, VK_INDEX_TYPE_UINT32);
    // Meshes are in world coordinates: clip_from_world composed in double, rounded to float once.
    const Mat4 clip = multiply(projection(options_), camera_from_world(camera));
    std::array<float, 16> clip_f{};
    for (int i = 0; i < 16; ++i)
        clip_f[i] = static_cast<float>(clip[i]);
    vkCmdPushConstants(command_buffer_, pipeline_layout_, VK_SHADER_STAGE_VERTEX_BIT, 0, 64, clip_f.data());
    for (const auto& draw : draws_) {
        vkCmdDrawIndexed(command_buffer_, draw[1], 1, draw[0], static_cast<std::int32_t>(draw[2]), 0);
    }
    vkCmdEndRenderPass(command_buffer_);
    return {};
}

std::string Engine::end_frame(VkSemaphore signal, bool wait) {
    HOST_TRY(vkEndCommandBuffer(command_buffer_));
    VkSubmitInfo submit{};
    submit.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    submit.commandBufferCount = 1;
    submit.pCommandBuffers = &command_buffer_;
    if (signal != VK_NULL_HANDLE) {
        submit.signalSemaphoreCount = 1;
        submit.pSignalSemaphores = &signal;
    }
    HOST_TRY(vkResetFences(device_, 1, &fence_));
    HOST_TRY(vkQueueSubmit(queue_, 1, &submit, fence_));
    in_flight_ = true;
    if (wait) {
        HOST_TRY(vkWaitForFences(device_, 1, &fence_, VK_TRUE, UINT64_MAX));
        in_flight_ = false;
    }
    return {};
}

std::vector<Mesh> demo_scene() {
    std::vector<Mesh> scene;
    // Seabed: 60 x 40 m at z = -3 (the camera is 3 m above it), split into a grid so the seabed is
    // not one huge triangle pair.
    Mesh seabed;
    const int nx = 12, ny = 8;
    for (int j = 0; j <= ny; ++j) {
        for (int i = 0; i <= nx; ++i) {
            seabed.positions.insert(seabed.positions.end(),
                                    {float(-5.0 + 60.0 * i / nx), float(-20.0 + 40.0 * j / ny), -3.0f});
        }
    }
    for (int j = 0; j < ny; ++j) {
        for (int i = 0; i < nx; ++i) {
            const std::uint32_t a = j * (nx + 1) + i, b = a + 1, c = a + nx + 1, d = c + 1;
            seabed.indices.insert(seabed.indices.end(), {a, b, d, a, d, c});
        }
    }
    scene.push_back(seabed);
    // A 2 m box standing on the seabed 12 m ahead, turned 30 degrees.
    Mesh box;
    const double pi = 3.14159265358979323846;
    for (int k = 0; k < 8; ++k) {
        const double lx = (k & 1) ? 1.0 : -1.0, ly = (k & 2) ? 1.0 : -1.0, lz = (k & 4) ? -1.0 : -3.0;
        const double a = 30.0 * pi / 180.0;
        box.positions.insert(box.positions.end(), {float(12.0 + lx * std::cos(a) - ly * std::sin(a)),
                                                   float(2.0 + lx * std::sin(a) + ly * std::cos(a)), float(lz)});
    }
    box.indices = {0, 1, 3, 0, 3, 2, 4, 6, 7, 4, 7, 5, 0, 4, 5, 0, 5, 1,
                   2, 3, 7, 2, 7, 6, 0, 2, 6, 0, 6, 4, 1, 5, 7, 1, 7, 3};
    scene.push_back(box);
    // A pillar (16-sided cylinder, radius 0.6 m) 20 m ahead, 5 m to starboard.
    Mesh pillar;
    const int sides = 16;
    for (int s = 0; s < sides; ++s) {
        const double a = 2.0 * pi * s / sides;
        for (double z : {-3.0, 1.0}) {
            pillar.positions.insert(pillar.positions.end(),
                                    {float(20.0 + 0.6 * std::cos(a)), float(-5.0 + 0.6 * std::sin(a)), float(z)});
        }
    }
    for (int s = 0; s < sides; ++s) {
        const std::uint32_t a = 2 * s, b = 2 * ((s + 1) % sides);
        pillar.indices.insert(pillar.indices.end(), {a, b, b + 1, a, b + 1, a + 1});
    }
    scene.push_back(pillar);
    return scene;
}

} // namespace host
