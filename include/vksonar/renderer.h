// Renderer: one simulated sonar. Create once per (config, scene); render() many poses.
// Thread-safety: one Renderer per thread; several Renderers may share a Context.
#pragma once

#include <cstdint>
#include <memory>

#include "vksonar/config.h"
#include "vksonar/context.h"
#include "vksonar/frame.h"
#include "vksonar/result.h"
#include "vksonar/scene.h"

namespace vksonar {

enum class Backend : std::uint8_t { vulkan, cpu };

struct RendererOptions {
    Backend backend = Backend::vulkan;
    std::uint64_t seed = 1;
    std::uint32_t save_mask = 0; // SaveFlags
    // Threads for the host stages (noise, gain): 0 = one per hardware thread (at most 8), 1 = the
    // calling thread only. Created once with the Renderer. Output does not depend on it.
    std::uint32_t host_threads = 0;
};

class RendererImpl; // internal
struct Plan;        // internal

class Renderer {
public:
    Renderer();
    ~Renderer();
    Renderer(Renderer&&) noexcept;
    Renderer& operator=(Renderer&&) noexcept;

    // Validates the config, resolves effects against the scene, builds the plan, uploads the scene.
    // The context and scene must outlive the renderer.
    [[nodiscard]] static Result<Renderer> create(Context& context, const SonarConfig& config, const Scene& scene,
                                                 const RendererOptions& options = {});

    // A frame sized for this renderer (the only allocation; reuse it for every render).
    Frame make_frame() const;

    // Renders the scene from `pose` into `frame`. frame_index keys the noise RNG with the seed.
    [[nodiscard]] Result<void> render(const Pose& pose, std::uint64_t frame_index, Frame& frame);

    const SonarConfig& config() const;

private:
    friend const Plan& renderer_plan(const Renderer&);
    std::unique_ptr<RendererImpl> impl_;
};

} // namespace vksonar
