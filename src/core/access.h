// Internal access to the insides of the public classes (Context, Scene, Renderer, HostDepthRenderer),
// for the library, the CLI and the tests. Not installed: the public headers name only the opaque types.
#pragma once

namespace vksonar {

struct VulkanContext;
struct SceneData;
struct Plan;
class RendererImpl;
class Context;
class Scene;
class Renderer;
class HostDepthRenderer;

namespace detail {
// The one friend of the public classes; each function is defined beside the class it opens.
struct Access {
    static VulkanContext* vulkan(const Context& context); // null for a CPU-only context
    static const SceneData& scene(const Scene& scene);
    static Scene copy(const Scene& scene); // the same arrays (Scene is move-only in the API)
    static const RendererImpl& renderer(const Renderer& renderer);
    static const RendererImpl& renderer(const HostDepthRenderer& renderer);
};
} // namespace detail

// The Vulkan objects behind a context (src/vk/vulkan_context.h), or null for a CPU-only context.
inline VulkanContext* context_vulkan(const Context& context) {
    return detail::Access::vulkan(context);
}
// The arrays behind a scene (src/scene/scene_data.h).
inline const SceneData& scene_data(const Scene& scene) {
    return detail::Access::scene(scene);
}

} // namespace vksonar
