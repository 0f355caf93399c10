// Renderer: plan + one StageBackend (CPU or Vulkan) + the shared host stages.
#include "vksonar/renderer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>

#include "core/host_plan.h"
#include "core/plan.h"
#include "core/renderer_access.h"
#include "host/host_stages.h"
#include "host/workers.h"
#include "scene/scene_data.h"
#include "stages/cpu_stages.h"
#include "vk/host_depth.h"
#include "vk/vulkan_backend.h"
#include "vk/vulkan_context.h"

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
        if (!context.vulkan()->graphics) {
            return make_error(ErrorCode::unsupported,
                              "Renderer::create: the adopted queue family has no graphics for the depth pass; "
                              "use create_for_depth with the host's depth image, or adopt a graphics queue");
        }
        auto backend = vk::make_backend(*context.vulkan(), impl->plan, scene.data(), options);
        if (!backend) return backend.error();
        impl->backend = std::move(backend.value());
    } else {
        impl->backend = cpu::make_backend(impl->plan, scene.data(), impl->workers.get());
    }
    Renderer r;
    r.impl_ = std::move(impl);
    return r;
}

void Renderer::set_seed(std::uint64_t seed) {
    impl_->options.seed = seed;
}

std::uint64_t Renderer::seed() const {
    return impl_->options.seed;
}

Frame Renderer::make_frame() const {
    const Plan& p = impl_->plan;
    const SaveFlags mask = impl_->options.save_mask;
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
    if (any(mask & SaveFlags::depth)) {
        f.depth.assign(pixels, 0.0f);
        f.material.assign(pixels, shared::kNoMaterial);
    }
    if (any(mask & SaveFlags::normals)) f.normals.assign(pixels * 4, 0.0f);
    if (any(mask & SaveFlags::echo)) f.echo.assign(pixels * 2, 0.0f);
    if (any(mask & SaveFlags::profiles)) {
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
    // Each render reports its own stages: the frame is reused, so the lists start empty (clear keeps
    // the capacity reserved by make_frame; no allocation).
    frame.times.clear();
    frame.stages_run.clear();
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

// Embedding (docs/embedding.md). The host-depth pass is the renderer's StageBackend: process() and
// read_back() arm it and go through render(), which checks the frame and runs the host stages.
Result<Renderer> Renderer::create_for_depth(Context& context, const SonarConfig& config, const HostDepthDesc& desc,
                                            const RendererOptions& options) {
    if (options.backend != Backend::vulkan || !context.has_vulkan()) {
        return make_error(ErrorCode::invalid_argument,
                          "create_for_depth: a host depth image needs the Vulkan backend and a Vulkan context");
    }
    auto plan = make_host_depth_plan(config, desc);
    if (!plan) return plan.error();
    Renderer r;
    r.impl_ = std::make_unique<RendererImpl>();
    r.impl_->plan = std::move(plan.value());
    r.impl_->options = options;
    r.impl_->workers = std::make_unique<host::Workers>(options.host_threads);
    auto pass = vk::HostDepthPass::create(*context.vulkan(), r.impl_->plan, desc, options);
    if (!pass) return pass.error();
    r.impl_->backend = std::move(pass.value());
    return r;
}

namespace {
vk::HostDepthPass* host_depth_pass(const std::unique_ptr<RendererImpl>& impl) {
    return impl ? dynamic_cast<vk::HostDepthPass*>(impl->backend.get()) : nullptr;
}
Error not_for_depth(const char* call) {
    return make_error(ErrorCode::invalid_argument,
                      std::string(call) + ": this renderer was made by create(); use create_for_depth");
}
} // namespace

Result<void> Renderer::process(const HostDepthImage& depth, std::uint64_t frame_index, Frame& frame) {
    vk::HostDepthPass* pass = host_depth_pass(impl_);
    if (!pass) return not_for_depth("process");
    pass->arm_process(depth);
    return render(Pose{}, frame_index, frame);
}

Result<void> Renderer::record(VkCommandBuffer commands, const HostDepthImage& depth) {
    vk::HostDepthPass* pass = host_depth_pass(impl_);
    if (!pass) return not_for_depth("record");
    return pass->record(commands, depth, impl_->options.save_mask);
}

Result<void> Renderer::read_back(std::uint64_t frame_index, Frame& frame) {
    vk::HostDepthPass* pass = host_depth_pass(impl_);
    if (!pass) return not_for_depth("read_back");
    pass->arm_read_back();
    return render(Pose{}, frame_index, frame);
}

Result<GpuBufferView> Renderer::polar_buffer() const {
    vk::HostDepthPass* pass = host_depth_pass(impl_);
    if (!pass) return not_for_depth("polar_buffer");
    return pass->polar_buffer();
}

const SonarConfig& Renderer::config() const {
    return impl_->plan.config;
}

const std::vector<ModelValidity>& Renderer::validity() const {
    return impl_->plan.validity;
}

RendererOptions renderer_options_from_env(RendererOptions base) {
    auto is = [](const char* name, const char* value) {
        const char* set = std::getenv(name);
        return set && std::strcmp(set, value) == 0;
    };
    if (base.host_threads == 0) {
        const char* threads = std::getenv("VKSONAR_HOST_THREADS");
        const long requested = threads ? std::strtol(threads, nullptr, 10) : 0;
        if (requested > 0) base.host_threads = static_cast<std::uint32_t>(std::min<long>(requested, 1 << 16));
    }
    if (is("VKSONAR_TABLES", "storage")) base.tables = TableAccess::storage;
    if (is("VKSONAR_RESAMPLE", "gather")) base.resample = ResampleMethod::gather;
    if (is("VKSONAR_STAGE_TIMING", "host")) base.stage_timing = StageTiming::host;
    if (is("VKSONAR_STAGE_TIMING", "timestamps")) base.stage_timing = StageTiming::timestamps;
    return base;
}

const Plan& renderer_plan(const Renderer& renderer) {
    return renderer.impl_->plan;
}

} // namespace vksonar
