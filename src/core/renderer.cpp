// Renderer: plan + one StageBackend (CPU or Vulkan) + the shared host stages.
#include "vksonar/renderer.h"

#include <chrono>
#include <cmath>

#include "core/plan.h"
#include "core/renderer_access.h"
#include "host/host_stages.h"
#include "host/workers.h"
#include "scene/scene_data.h"
#include "stages/cpu_stages.h"
#include "vk/vulkan_backend.h"

namespace vksonar {

class RendererImpl {
public:
    Plan plan;
    RendererOptions options;
    std::unique_ptr<StageBackend> backend;
    std::unique_ptr<host::Workers> workers; // host-stage threads, made once here
};

Renderer::Renderer() = default;
Renderer::~Renderer() = default;
Renderer::Renderer(Renderer&&) noexcept = default;
Renderer& Renderer::operator=(Renderer&&) noexcept = default;

Result<Renderer> Renderer::create(Context& context, const SonarConfig& config, const Scene& scene,
                                  const RendererOptions& options) {
    auto plan = make_plan(config, scene.data());
    if (!plan) return plan.error();
    auto impl = std::make_unique<RendererImpl>();
    impl->plan = std::move(plan.value());
    impl->options = options;
    impl->workers = std::make_unique<host::Workers>(options.host_threads);
    if (options.backend == Backend::vulkan) {
        if (!context.has_vulkan()) {
            return make_error(ErrorCode::no_device, "no Vulkan device in this context; use --backend cpu");
        }
        auto backend = vk::make_backend(*context.vulkan(), impl->plan, scene.data());
        if (!backend) return backend.error();
        impl->backend = std::move(backend.value());
    } else {
        impl->backend = cpu::make_backend(impl->plan, scene.data());
    }
    Renderer r;
    r.impl_ = std::move(impl);
    return r;
}

Frame Renderer::make_frame() const {
    const Plan& p = impl_->plan;
    const std::uint32_t mask = impl_->options.save_mask;
    const std::size_t cells = static_cast<std::size_t>(p.bins) * p.beams;
    const std::size_t pixels = static_cast<std::size_t>(p.rows) * p.columns;
    Frame f;
    f.beams = p.beams;
    f.bins = p.bins;
    f.columns = p.columns;
    f.rows = p.rows;
    f.seed = impl_->options.seed;
    f.beam_angles_rad = p.beam_angle_rad;
    f.bin_ranges_m = p.bin_range_m;
    f.clean.assign(cells, 0.0f);
    f.intensity.assign(cells, 0.0f);
    f.display.assign(cells, 0.0f);
    if (mask & save_depth) {
        f.depth.assign(pixels, 0.0f);
        f.material.assign(pixels, shared::kNoMaterial);
    }
    if (mask & save_normals) f.normals.assign(pixels * 4, 0.0f);
    if (mask & save_echo) f.echo.assign(pixels * 2, 0.0f);
    if (mask & save_profiles) {
        f.profiles.assign(static_cast<std::size_t>(p.bins) * p.columns, 0.0f);
        f.beam_profiles.assign(cells, 0.0f);
    }
    f.times.reserve(8);
    f.stages_run.reserve(8);
    f.effects = p.effects.states;
    return f;
}

Result<void> Renderer::render(const Pose& pose, std::uint64_t frame_index, Frame& frame) {
    for (double v : {pose.x_m, pose.y_m, pose.z_m, pose.roll_deg, pose.pitch_deg, pose.yaw_deg}) {
        if (!std::isfinite(v)) return make_error(ErrorCode::invalid_argument, "pose: non-finite value");
    }
    const Plan& p = impl_->plan;
    if (frame.clean.size() != static_cast<std::size_t>(p.bins) * p.beams) {
        return make_error(ErrorCode::invalid_argument, "render: frame was not made by this renderer's make_frame()");
    }
    auto r = impl_->backend->render(pose, impl_->options.save_mask, frame);
    if (!r) return r;
    const auto t0 = std::chrono::steady_clock::now();
    frame.frame_index = frame_index;
    frame.seed = impl_->options.seed;
    host::noise_and_gain(p, impl_->options.seed, frame_index, frame, impl_->workers.get());
    const auto t1 = std::chrono::steady_clock::now();
    frame.times.push_back({"noise", std::chrono::duration<double, std::milli>(t1 - t0).count()});
    frame.stages_run.push_back("noise");
    return {};
}

const SonarConfig& Renderer::config() const { return impl_->plan.config; }

const Plan& renderer_plan(const Renderer& renderer) { return renderer.impl_->plan; }

} // namespace vksonar
