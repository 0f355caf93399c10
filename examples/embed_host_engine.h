// A tiny "host engine" for examples/embed_host.cpp and tests/embed_test.cpp: it owns its Vulkan
// instance, device and queue, uploads triangle meshes and renders a depth image with its own
// depth-only pipeline, the way a game engine's depth prepass would. Plain Vulkan, no vksonar types
// except in the glue functions at the end, which show what an engine hands to vksonar.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include <vulkan/vulkan_core.h>

namespace host {

struct Mesh {
    std::vector<float> positions; // xyz, world frame (x forward, y left, z up), metres
    std::vector<std::uint32_t> indices;
};

// A camera pose in the engine's world frame: position, then roll/pitch/yaw in degrees with
// R = Rz(yaw) Ry(pitch) Rx(roll); the camera looks along its +x with +z up (the sonar's frame).
struct CameraPose {
    double x_m = 0, y_m = 0, z_m = 0;
    double roll_deg = 0, pitch_deg = 0, yaw_deg = 0;
};

struct EngineOptions {
    std::uint32_t width = 256, height = 64;
    double tan_half_h = 1.0, tan_half_v = 0.25; // pinhole: fx = width / (2 tan_half_h)
    double near_m = 0.05, far_m = 200.0;
    bool reversed_z = true;
    VkFormat depth_format = VK_FORMAT_D32_SFLOAT;
    bool validation = false;                        // VK_LAYER_KHRONOS_validation + a counting messenger
    std::uint32_t api_version = VK_API_VERSION_1_1; // VkApplicationInfo.apiVersion
    // Where validation messages are counted (null: inside the engine). An outside counter also sees the
    // messages of vkDestroyDevice, e.g. objects someone forgot to destroy.
    std::atomic<std::uint32_t>* message_counter = nullptr;
};

class Engine {
public:
    Engine() = default;
    ~Engine(); // destroys everything it created, in reverse order
    Engine(const Engine&) = delete;
    Engine& operator=(const Engine&) = delete;

    // Returns an empty string on success, else what failed.
    std::string create(const EngineOptions& options);
    std::string upload(const std::vector<Mesh>& meshes);
    // Renders the meshes' depth from `camera` into the depth image, leaving it in
    // DEPTH_STENCIL_READ_ONLY_OPTIMAL. `after_depth` (optional) records more work into the same
    // command buffer after the render pass (e.g. vksonar's HostDepthRenderer::record). Submits and waits.
    template <class AfterDepth> std::string render_depth(const CameraPose& camera, AfterDepth&& after_depth) {
        std::string error = begin_frame(camera);
        if (!error.empty()) return error;
        std::string after = after_depth(command_buffer_);
        if (!after.empty()) return after;
        return end_frame();
    }
    std::string render_depth(const CameraPose& camera) {
        return render_depth(camera, [](VkCommandBuffer) { return std::string(); });
    }
    // The depth pass of a frame whose later passes are separate submissions: renders the depth image
    // as render_depth does, submits it signalling `signal` (a binary semaphore, which later work on the
    // GPU waits for) and returns without waiting. The engine waits for it before its next frame.
    std::string submit_depth(const CameraPose& camera, VkSemaphore signal) {
        std::string error = begin_frame(camera);
        return error.empty() ? end_frame(signal, false) : error;
    }

    // A host-visible, coherent buffer with its own memory; the caller destroys both (before the engine).
    std::string create_buffer(VkDeviceSize size, VkBufferUsageFlags usage, VkBuffer& buffer, VkDeviceMemory& memory);

    VkInstance instance() const { return instance_; }
    VkPhysicalDevice physical_device() const { return physical_device_; }
    VkDevice device() const { return device_; }
    std::uint32_t queue_family() const { return queue_family_; }
    VkQueue queue() const { return queue_; }
    VkImage depth_image() const { return depth_image_; }
    VkImageView depth_view() const { return depth_view_; }
    const EngineOptions& options() const { return options_; }
    std::uint32_t validation_messages() const {
        return options_.message_counter ? options_.message_counter->load() : validation_messages_.load();
    }
    bool validation_enabled() const { return messenger_ != VK_NULL_HANDLE; }

private:
    std::string begin_frame(const CameraPose& camera);
    std::string end_frame(VkSemaphore signal = VK_NULL_HANDLE, bool wait = true);

    EngineOptions options_;
    VkInstance instance_ = VK_NULL_HANDLE;
    VkDebugUtilsMessengerEXT messenger_ = VK_NULL_HANDLE;
    VkPhysicalDevice physical_device_ = VK_NULL_HANDLE;
    VkDevice device_ = VK_NULL_HANDLE;
    std::uint32_t queue_family_ = 0;
    VkQueue queue_ = VK_NULL_HANDLE;
    VkImage depth_image_ = VK_NULL_HANDLE;
    VkDeviceMemory depth_memory_ = VK_NULL_HANDLE;
    VkImageView depth_view_ = VK_NULL_HANDLE;
    VkRenderPass render_pass_ = VK_NULL_HANDLE;
    VkFramebuffer framebuffer_ = VK_NULL_HANDLE;
    VkPipelineLayout pipeline_layout_ = VK_NULL_HANDLE;
    VkPipeline pipeline_ = VK_NULL_HANDLE;
    VkBuffer vertex_buffer_ = VK_NULL_HANDLE, index_buffer_ = VK_NULL_HANDLE;
    VkDeviceMemory vertex_memory_ = VK_NULL_HANDLE, index_memory_ = VK_NULL_HANDLE;
    std::vector<std::array<std::uint32_t, 3>> draws_; // first_index, index_count, vertex_offset
    VkCommandPool command_pool_ = VK_NULL_HANDLE;
    VkCommandBuffer command_buffer_ = VK_NULL_HANDLE;
    VkFence fence_ = VK_NULL_HANDLE;
    bool in_flight_ = false; // fence_ is pending: submit_depth did not wait for it
    std::atomic<std::uint32_t> validation_messages_{0};
};

// The scene both the engine and vksonar's standalone renderer draw: a seabed, a box and a pillar
// in front of a camera at the origin, looking along +x.
std::vector<Mesh> demo_scene();

} // namespace host
