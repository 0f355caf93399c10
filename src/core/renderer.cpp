// Renderer: plan + one StageBackend (CPU or Vulkan) + the shared host stages.
#include "vksonar/renderer.h"

#include "vksonar/host_depth.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <new>
#include <string>
#include <system_error>

#include "core/host_plan.h"
#include "core/plan.h"
#include "core/renderer_access.h"
#include "core/renderer_workers.h"
#include "host/host_stages.h"
#include "host/workers.h"
#include "scene/scene_data.h"
#include "stages/cpu_stages.h"
#include "stages/labels.h"
#include "vk/host_depth.h"
#include "vk/vulkan_backend.h"
#include "vk/vulkan_context.h"

namespace vksonar {

class RendererImpl {
public:
    Plan plan;
    RendererOptions options;
    std::unique_ptr<StageBackend> backend;
    std::unique_ptr<host::Workers> workers;   // host-stage threads, made once here
    vk::HostDepthPass* host_depth = nullptr;  // HostDepthRenderer: `backend`, typed
    std::unique_ptr<cpu::LabelsStage> labels; // only with SaveFlags::labels
    std::size_t visibility_capacity = 0;      // Frame::visibility's reserve (labels)
    // The noise stage's random draws, made on the host threads while the GPU renders
    // (host::noise_draws_ahead, StageBackend::set_gpu_overlap): 2 floats a cell, made once here.
    std::vector<float> speckle_draws, noise_draws;
    std::uint64_t overlap_frame_index = 0;
    // The (seed, frame index) the draws were made for; draws_made false: none yet.
    bool draws_made = false;
    std::uint64_t draws_seed = 0, draws_frame_index = 0;
    // Render-ahead (render with a NextFrame): the pose whose device work the backend started.
    bool started = false;
    Pose started_pose;

    void make_draws(std::uint64_t frame_index) {
        host::noise_draws(plan, options.seed, frame_index, {speckle_draws.data(), noise_draws.data()}, workers.get());
        draws_made = true;
        draws_seed = options.seed;
        draws_frame_index = frame_index;
    }
    bool draws_for(std::uint64_t frame_index) const {
        return draws_made && draws_seed == options.seed && draws_frame_index == frame_index;
    }
    // Makes the frame's draws unless this renderer makes none ahead or has them already.
    void ensure_draws(std::uint64_t frame_index) {
        if (!speckle_draws.empty() && !draws_for(frame_index)) make_draws(frame_index);
    }
};

namespace {

// Runs `body` (a create or label_flow) so that no exception crosses the public API: running out of
// memory (a plan, tables or buffers too big for the machine) and std::system_error (a host thread that
// could not start, host::Workers) come back as an Error naming `where`.
template <class T, class Body> Result<T> without_exceptions(const char* where, Body&& body) {
    try {
        return body();
    } catch (const std::bad_alloc&) {
        return make_error(ErrorCode::unsupported,
                          std::string(where) + ": out of memory: this config's buffers do not fit (fewer bins, beams "
                                               "or accuracy.rows_per_vfov / pixels_per_beam need less)");
    } catch (const std::system_error& e) {
        return make_error(ErrorCode::unsupported,
                          std::string(where) + ": " + e.what() +
                              " (e.g. a host thread could not start: fewer RendererOptions::host_threads)");
    }
}

Frame make_frame_for(const RendererImpl& impl);
Result<void> run_frame(RendererImpl& impl, const Pose& pose, std::uint64_t frame_index, Frame& frame,
                       const NextFrame* next);

// What the backend must fill: what was asked for, and with labels the material image and the echo
// they are computed from.
SaveFlags backend_save_mask(const RendererOptions& options) {
    return any(options.save_mask & SaveFlags::labels) ? options.save_mask | SaveFlags::depth | SaveFlags::echo
                                                      : options.save_mask;
}

// Labels: the plan's flag, and the stage with each instance's class. Instance ids ride in 16 bits of
// the depth pass's id image. The stage spreads pixels as the backend's profile does: in float (the GPU's
// profile pass, the CPU backend in float), else in double (the CPU backend with cpu.precision = double).
Result<void> set_up_labels(RendererImpl& impl, const SceneData* scene) {
    if (!any(impl.options.save_mask & SaveFlags::labels)) return {};
    impl.plan.labels = true;
    std::vector<std::uint16_t> class_of_instance(1, 0);
    if (scene != nullptr) {
        for (const SceneInstance& instance : scene->instances) {
            if (instance.id > 0xffffu || instance.class_id > 0xffffu)
                return make_error(ErrorCode::invalid_argument,
                                  "labels: node " + std::to_string(instance.id - 1) +
                                      (instance.node.empty() ? std::string(" (unnamed)") : " '" + instance.node + "'") +
                                      " has instance id " + std::to_string(instance.id) +
                                      "; labels hold ids up to 65535");
            if (class_of_instance.size() <= instance.id) class_of_instance.resize(instance.id + 1, 0);
            class_of_instance[instance.id] = static_cast<std::uint16_t>(instance.class_id);
        }
        for (std::size_t i = 0; i < scene->draws.size(); ++i) // an engine's own ids (Scene::add_draw)
            if (scene->draws[i].instance > 0xffffu)
                return make_error(ErrorCode::invalid_argument,
                                  "labels: draw " + std::to_string(i) + " has instance id " +
                                      std::to_string(scene->draws[i].instance) + "; labels hold ids up to 65535");
    }
    // Frame::visibility holds at most one entry per distinct instance id of the draws.
    impl.visibility_capacity = 1;
    if (scene != nullptr) impl.visibility_capacity += scene->draws.size();
    const bool float_spreads =
        impl.options.backend == Backend::vulkan || impl.plan.config.cpu_precision != Precision::f64;
    impl.labels = std::make_unique<cpu::LabelsStage>(impl.plan, std::move(class_of_instance), impl.workers.get(), scene,
                                                     float_spreads);
    impl.labels->set_part_timing(impl.options.stage_timing == StageTiming::passes);
    return {};
}

// RendererOptions as set in C++: an enum cast from a number no value has would run some other path in
// silence (a Backend of 7 ran the CPU backend), and save_mask bits past labels mean nothing.
Result<void> check_options(const RendererOptions& o) {
    const auto out_of = [](const char* field, unsigned value, const char* expected) {
        return make_error(ErrorCode::invalid_argument, std::string("RendererOptions: ") + field + " = " +
                                                           std::to_string(value) + " (expected " + expected + ")");
    };
    if (o.backend != Backend::vulkan && o.backend != Backend::cpu)
        return out_of("backend", static_cast<unsigned>(o.backend), "vulkan or cpu");
    if (o.tables != TableAccess::automatic && o.tables != TableAccess::storage)
        return out_of("tables", static_cast<unsigned>(o.tables), "automatic or storage");
    if (o.resample != ResampleMethod::automatic && o.resample != ResampleMethod::gather)
        return out_of("resample", static_cast<unsigned>(o.resample), "automatic or gather");
    if (o.layout != WorkLayout::automatic && o.layout != WorkLayout::cpu_device && o.layout != WorkLayout::gpu)
        return out_of("layout", static_cast<unsigned>(o.layout), "automatic, cpu_device or gpu");
    if (o.stage_timing != StageTiming::automatic && o.stage_timing != StageTiming::host &&
        o.stage_timing != StageTiming::timestamps && o.stage_timing != StageTiming::passes)
        return out_of("stage_timing", static_cast<unsigned>(o.stage_timing), "automatic, host, timestamps or passes");
    if (o.profile_rows != ProfileRows::automatic && o.profile_rows != ProfileRows::whole)
        return out_of("profile_rows", static_cast<unsigned>(o.profile_rows), "automatic or whole");
    const auto known =
        SaveFlags::depth | SaveFlags::normals | SaveFlags::echo | SaveFlags::profiles | SaveFlags::labels;
    const auto mask = static_cast<std::uint32_t>(o.save_mask);
    if ((mask & ~static_cast<std::uint32_t>(known)) != 0)
        return out_of("save_mask", mask, "SaveFlags: depth, normals, echo, profiles, labels");
    return {};
}

} // namespace

const RendererImpl& detail::Access::renderer(const Renderer& renderer) {
    return *renderer.impl_;
}

const RendererImpl& detail::Access::renderer(const HostDepthRenderer& renderer) {
    return *renderer.impl_;
}

Renderer::Renderer() = default;
Renderer::~Renderer() = default;
Renderer::Renderer(Renderer&&) noexcept = default;
Renderer& Renderer::operator=(Renderer&&) noexcept = default;

Result<Renderer> Renderer::create(Context& context, const SonarConfig& config, const Scene& scene,
                                  const RendererOptions& options) {
    return without_exceptions<Renderer>("Renderer::create", [&]() -> Result<Renderer> {
        if (auto checked = check_options(options); !checked) return checked.error();
        auto plan = make_plan(config, scene_data(scene));
        if (!plan) return plan.error();
        auto impl = std::make_unique<RendererImpl>();
        impl->plan = std::move(plan.value());
        impl->options = options;
        impl->workers = std::make_unique<host::Workers>(options.host_threads);
        if (auto labels = set_up_labels(*impl, &scene_data(scene)); !labels) return labels.error();
        if (options.backend == Backend::vulkan) {
            if (!context.has_vulkan()) {
                return make_error(ErrorCode::no_device, "no Vulkan device in this context; use --backend cpu");
            }
            if (!context_vulkan(context)->graphics) {
                return make_error(ErrorCode::unsupported,
                                  "Renderer::create: the adopted queue family has no graphics for the depth pass; "
                                  "use HostDepthRenderer with the host's depth image, or adopt a graphics queue");
            }
            auto backend = vk::make_backend(*context_vulkan(context), impl->plan, scene_data(scene), options);
            if (!backend) return backend.error();
            impl->backend = std::move(backend.value());
            impl->backend->defer_clean(true); // the noise stage copies the scan out on its threads
            if (host::noise_draws_ahead(impl->plan)) {
                const std::size_t cells = std::size_t(impl->plan.bins) * impl->plan.beams;
                impl->speckle_draws.assign(cells, 0.0f);
                impl->noise_draws.assign(cells, 0.0f);
                impl->backend->set_gpu_overlap(
                    [](void* renderer) {
                        auto& i = *static_cast<RendererImpl*>(renderer);
                        i.ensure_draws(i.overlap_frame_index);
                    },
                    impl.get());
            }
        } else {
            impl->backend = cpu::make_backend(impl->plan, scene_data(scene), impl->workers.get(),
                                              options.stage_timing == StageTiming::passes);
        }
        Renderer r;
        r.impl_ = std::move(impl);
        return r;
    });
}

namespace {
// An empty renderer (default-constructed or moved from) has no plan: its calls say so, or answer as
// for nothing (seed 0, the default config, no validity entries, an empty frame).
constexpr const char* kEmptyRenderer =
    "an empty renderer (default-constructed or moved from; make one with Renderer::create)";
constexpr const char* kEmptyHostDepthRenderer =
    "an empty renderer (default-constructed or moved from; make one with HostDepthRenderer::create)";
const SonarConfig& default_config() {
    static const SonarConfig defaults; // a constant, never written
    return defaults;
}
const std::vector<ModelValidity>& no_validity() {
    static const std::vector<ModelValidity> none;
    return none;
}
} // namespace

void Renderer::set_seed(std::uint64_t seed) {
    if (impl_) impl_->options.seed = seed;
}

std::uint64_t Renderer::seed() const {
    return impl_ ? impl_->options.seed : 0;
}

Frame Renderer::make_frame() const {
    return impl_ ? make_frame_for(*impl_) : Frame{};
}

Result<void> Renderer::render(const Pose& pose, std::uint64_t frame_index, Frame& frame) {
    if (!impl_) return make_error(ErrorCode::invalid_argument, std::string("Renderer::render: ") + kEmptyRenderer);
    return run_frame(*impl_, pose, frame_index, frame, nullptr);
}

Result<void> Renderer::render(const Pose& pose, std::uint64_t frame_index, Frame& frame, const NextFrame& next) {
    if (!impl_) return make_error(ErrorCode::invalid_argument, std::string("Renderer::render: ") + kEmptyRenderer);
    return run_frame(*impl_, pose, frame_index, frame, &next);
}

namespace {

Frame make_frame_for(const RendererImpl& impl) {
    const Plan& p = impl.plan;
    const SaveFlags mask = backend_save_mask(impl.options);
    const std::size_t cells = static_cast<std::size_t>(p.bins) * p.beams;
    const std::size_t pixels = static_cast<std::size_t>(p.rows) * p.columns;
    Frame f;
    f.beams = p.beams;
    f.bins = p.bins;
    f.columns = p.columns;
    f.profile_columns = p.profile_columns;
    f.rows = p.rows;
    f.seed = impl.options.seed;
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
        f.profiles.assign(static_cast<std::size_t>(p.bins) * p.profile_columns, 0.0f);
        f.beam_profiles.assign(cells, 0.0f);
    }
    if (any(mask & SaveFlags::labels)) {
        f.instance.assign(cells, 0);
        f.instance_fraction.assign(cells, 0.0f);
        f.object_class.assign(cells, 0);
        f.elevation.assign(cells, 0.0f);
        f.elevation_spread.assign(cells, 0.0f);
        f.point.assign(cells * 3, 0.0f);
        f.visibility.reserve(impl.visibility_capacity);
    }
    f.times.reserve(24); // the stages, and with StageTiming::passes the passes, host steps and labels parts
    f.stages_run.reserve(8);
    f.effects = p.effects.states;
    return f;
}

// The array of `frame` that make_frame_for sizes and this renderer's save mask fills but `frame` holds
// at another size (name null: none). The stages write those arrays by index (the labels stage into
// instance ... point), so a frame from another renderer with the same bins x beams but other saved
// arrays must be refused, not written past its end.
struct Misfit {
    const char* name = nullptr;
    std::size_t size = 0, expected = 0;
    bool count = false; // a count (Frame::bins, beams), not an array's size
};

Misfit misfit_array(const RendererImpl& impl, const Frame& frame) {
    const Plan& p = impl.plan;
    const SaveFlags mask = backend_save_mask(impl.options);
    const std::size_t cells = static_cast<std::size_t>(p.bins) * p.beams;
    const std::size_t pixels = static_cast<std::size_t>(p.rows) * p.columns;
    Misfit misfit;
    auto check = [&](const char* name, std::size_t size, std::size_t expected) {
        if (misfit.name == nullptr && size != expected) misfit = Misfit{name, size, expected};
    };
    // The shape, not only the cell count: a 32 x 16 frame must not pass for a 16 x 32 one.
    if (frame.bins != p.bins) misfit = Misfit{"bins", frame.bins, p.bins, true};
    if (misfit.name == nullptr && frame.beams != p.beams) misfit = Misfit{"beams", frame.beams, p.beams, true};
    check("beam_angles_rad", frame.beam_angles_rad.size(), p.beams);
    check("bin_ranges_m", frame.bin_ranges_m.size(), p.bins);
    check("clean", frame.clean.size(), cells);
    if (any(mask & SaveFlags::depth)) {
        check("depth", frame.depth.size(), pixels);
        check("material", frame.material.size(), pixels);
    }
    if (any(mask & SaveFlags::normals)) check("normals", frame.normals.size(), pixels * 4);
    if (any(mask & SaveFlags::echo)) check("echo", frame.echo.size(), pixels * 2);
    if (any(mask & SaveFlags::profiles)) {
        check("profiles", frame.profiles.size(), static_cast<std::size_t>(p.bins) * p.profile_columns);
        check("beam_profiles", frame.beam_profiles.size(), cells);
    }
    if (any(mask & SaveFlags::labels)) {
        check("instance", frame.instance.size(), cells);
        check("instance_fraction", frame.instance_fraction.size(), cells);
        check("object_class", frame.object_class.size(), cells);
        check("elevation", frame.elevation.size(), cells);
        check("elevation_spread", frame.elevation_spread.size(), cells);
        check("point", frame.point.size(), cells * 3);
    }
    return misfit;
}

// Finite, also as the float the view transforms hold (a pose of 1e39 m was taken and became inf there).
bool finite_pose(const Pose& pose) {
    for (double v : {pose.x_m, pose.y_m, pose.z_m, pose.roll_deg, pose.pitch_deg, pose.yaw_deg})
        if (!std::isfinite(v) || !std::isfinite(static_cast<float>(v))) return false;
    return true;
}

// Bit for bit (-0 is not 0: the started frame is the one this pose would give, to the last bit).
bool same_pose(const Pose& a, const Pose& b) {
    static_assert(sizeof(Pose) == 6 * sizeof(double), "Pose: six doubles, no padding");
    return std::memcmp(&a, &b, sizeof(Pose)) == 0;
}

// The backend's stages for `pose` into `frame`. With `next` (render-ahead on a backend that has a
// device), the next frame is started before this one is waited for, so the device always has the next
// frame queued: this one is picked up where the last call started it, else started here first.
Result<void> backend_frame(RendererImpl& impl, const Pose& pose, std::uint64_t frame_index, Frame& frame,
                           const NextFrame* next) {
    StageBackend& backend = *impl.backend;
    const SaveFlags mask = backend_save_mask(impl.options);
    const bool was_started = impl.started;
    impl.started = false; // taken up, dropped or (below) replaced by the next frame
    const bool picked_up = was_started && same_pose(impl.started_pose, pose);
    if (was_started && !picked_up) { // another pose than announced: wait for that work, drop it
        // (a frame the device cut short is refused with ErrorCode::unsupported: dropped anyway, it does
        // not fail this one, which says for itself)
        if (auto dropped = backend.finish(frame); !dropped && dropped.error().code != ErrorCode::unsupported)
            return dropped;
    }
    if (next == nullptr && !picked_up) return backend.render(pose, mask, frame); // draws made while it works
    if (next != nullptr) {
        if (!picked_up) {
            if (auto r = backend.start(pose, mask, false, false); !r) return r;
        }
        // the next frame, queued behind this one; its draws are made after this frame's noise stage
        if (auto r = backend.start(next->pose, mask, true, false); !r) {
            (void)backend.finish(frame); // nothing left on the device
            return r;
        }
        impl.started = true;
        impl.started_pose = next->pose;
    }
    // this frame's draws, while the device works: made by the last call unless it announced another
    // frame index (or the seed changed since)
    impl.ensure_draws(frame_index);
    return backend.finish(frame);
}

Result<void> run_frame(RendererImpl& impl, const Pose& pose, std::uint64_t frame_index, Frame& frame,
                       const NextFrame* next) {
    if (!finite_pose(pose)) return make_error(ErrorCode::invalid_argument, "pose: a value not finite (in float)");
    if (next != nullptr && !finite_pose(next->pose))
        return make_error(ErrorCode::invalid_argument, "next pose: a value not finite (in float)");
    const Plan& p = impl.plan;
    if (const Misfit misfit = misfit_array(impl, frame); misfit.name != nullptr) {
        return make_error(ErrorCode::invalid_argument,
                          std::string("render: frame was not made by this renderer's make_frame() (Frame::") +
                              misfit.name + (misfit.count ? " is " : " has ") + std::to_string(misfit.size) +
                              (misfit.count ? "" : " elements") + ", this renderer's " +
                              std::to_string(misfit.expected) + ")");
    }
    // Each render reports its own stages: the frame is reused, so the lists start empty (clear keeps
    // the capacity reserved by make_frame; no allocation).
    frame.times.clear();
    frame.stages_run.clear();
    impl.overlap_frame_index = frame_index;
    const bool ahead = next != nullptr && impl.backend->renders_ahead();
    if (auto r = backend_frame(impl, pose, frame_index, frame, ahead ? next : nullptr); !r) return r;
    if (impl.labels) { // the backend's sub-pixel returns are this frame's (one per frame slot)
        const auto start = std::chrono::steady_clock::now();
        impl.labels->run(frame, pose, impl.backend->subpixel_returns());
        frame.times.push_back(
            {"labels", std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count()});
        frame.stages_run.push_back("labels");
    }
    const auto t0 = std::chrono::steady_clock::now();
    frame.frame_index = frame_index;
    frame.seed = impl.options.seed;
    // The axes are this renderer's, also in a frame another renderer of the same shape made (misfit_array
    // checked their sizes: copying into them allocates nothing).
    std::copy_n(p.beam_angle_rad.begin(), p.beams, frame.beam_angles_rad.begin());
    std::copy_n(p.bin_range_m.begin(), p.bins, frame.bin_ranges_m.begin());
    const host::NoiseDraws draws{impl.speckle_draws.data(), impl.noise_draws.data()};
    host::noise_and_gain(p, impl.options.seed, frame_index, frame, impl.workers.get(), impl.backend->pending_clean(),
                         impl.draws_for(frame_index) ? &draws : nullptr);
    const auto t1 = std::chrono::steady_clock::now();
    frame.times.push_back({"noise", std::chrono::duration<double, std::milli>(t1 - t0).count()});
    frame.stages_run.push_back("noise");
    if (ahead) impl.ensure_draws(next->frame_index); // while the device works
    return {};
}

} // namespace

// Embedding (docs/embedding.md). The host-depth pass is the renderer's StageBackend: process() and
// read_back() arm it and go through run_frame, which checks the frame and runs the host stages.
HostDepthRenderer::HostDepthRenderer() = default;
HostDepthRenderer::~HostDepthRenderer() = default;
HostDepthRenderer::HostDepthRenderer(HostDepthRenderer&&) noexcept = default;
HostDepthRenderer& HostDepthRenderer::operator=(HostDepthRenderer&&) noexcept = default;

Result<HostDepthRenderer> HostDepthRenderer::create(Context& context, const SonarConfig& config,
                                                    const HostDepthDesc& desc, const RendererOptions& options) {
    return without_exceptions<HostDepthRenderer>("HostDepthRenderer::create", [&]() -> Result<HostDepthRenderer> {
        if (auto checked = check_options(options); !checked) return checked.error();
        if (options.backend != Backend::vulkan || !context.has_vulkan()) {
            return make_error(ErrorCode::invalid_argument,
                              "HostDepthRenderer::create: a host depth image needs the Vulkan backend and a Vulkan "
                              "context");
        }
        auto plan = make_host_depth_plan(config, desc);
        if (!plan) return plan.error();
        HostDepthRenderer r;
        r.impl_ = std::make_unique<RendererImpl>();
        r.impl_->plan = std::move(plan.value());
        r.impl_->options = options;
        r.impl_->workers = std::make_unique<host::Workers>(options.host_threads);
        if (auto labels = set_up_labels(*r.impl_, nullptr); !labels) return labels.error();
        auto pass = vk::HostDepthPass::create(*context_vulkan(context), r.impl_->plan, desc, options);
        if (!pass) return pass.error();
        r.impl_->host_depth = pass.value().get();
        r.impl_->backend = std::move(pass.value());
        return r;
    });
}

Frame HostDepthRenderer::make_frame() const {
    return impl_ ? make_frame_for(*impl_) : Frame{};
}

void HostDepthRenderer::set_seed(std::uint64_t seed) {
    if (impl_) impl_->options.seed = seed;
}

std::uint64_t HostDepthRenderer::seed() const {
    return impl_ ? impl_->options.seed : 0;
}

Result<void> HostDepthRenderer::process(const HostDepthImage& depth, std::uint64_t frame_index, Frame& frame) {
    if (!impl_)
        return make_error(ErrorCode::invalid_argument,
                          std::string("HostDepthRenderer::process: ") + kEmptyHostDepthRenderer);
    impl_->host_depth->arm_process(depth);
    return run_frame(*impl_, Pose{}, frame_index, frame, nullptr);
}

Result<void> HostDepthRenderer::record(VkCommandBuffer commands, const HostDepthImage& depth) {
    if (!impl_)
        return make_error(ErrorCode::invalid_argument,
                          std::string("HostDepthRenderer::record: ") + kEmptyHostDepthRenderer);
    return impl_->host_depth->record(commands, depth, backend_save_mask(impl_->options));
}

void HostDepthRenderer::discard_recorded() {
    if (impl_) impl_->host_depth->discard_recorded();
}

Result<void> HostDepthRenderer::read_back(std::uint64_t frame_index, Frame& frame) {
    if (!impl_)
        return make_error(ErrorCode::invalid_argument,
                          std::string("HostDepthRenderer::read_back: ") + kEmptyHostDepthRenderer);
    impl_->host_depth->arm_read_back();
    return run_frame(*impl_, Pose{}, frame_index, frame, nullptr);
}

GpuBufferView HostDepthRenderer::polar_buffer() const {
    return impl_ ? impl_->host_depth->polar_buffer() : GpuBufferView{};
}

const SonarConfig& HostDepthRenderer::config() const {
    return impl_ ? impl_->plan.config : default_config();
}

const std::vector<ModelValidity>& HostDepthRenderer::validity() const {
    return impl_ ? impl_->plan.validity : no_validity();
}

Result<void> Renderer::label_flow(const Frame& from, const Pose& from_pose, const Frame& to, const Pose& to_pose,
                                  std::vector<float>& flow) const {
    if (!impl_ || !impl_->labels)
        return make_error(ErrorCode::invalid_argument,
                          "label_flow: this renderer was made without SaveFlags::labels (RendererOptions::save_mask)");
    if (!finite_pose(from_pose) || !finite_pose(to_pose))
        return make_error(ErrorCode::invalid_argument, "label_flow: a pose value not finite (in float)");
    const Plan& p = impl_->plan;
    const std::size_t cells = static_cast<std::size_t>(p.bins) * p.beams;
    const std::size_t pixels = static_cast<std::size_t>(p.rows) * p.columns;
    if (from.instance.size() != cells || from.point.size() != 3 * cells || to.depth.size() != pixels)
        return make_error(ErrorCode::invalid_argument, "label_flow: the frames were not made by this renderer");
    return without_exceptions<void>("label_flow", [&]() -> Result<void> {
        if (flow.size() != 2 * cells) flow.resize(2 * cells);
        impl_->labels->flow(from, from_pose, to, to_pose, flow.data());
        return {};
    });
}

const SonarConfig& Renderer::config() const {
    return impl_ ? impl_->plan.config : default_config();
}

const std::vector<ModelValidity>& Renderer::validity() const {
    return impl_ ? impl_->plan.validity : no_validity();
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
    if (is("VKSONAR_LAYOUT", "cpu_device")) base.layout = WorkLayout::cpu_device;
    if (is("VKSONAR_LAYOUT", "gpu")) base.layout = WorkLayout::gpu;
    if (is("VKSONAR_PROFILE_ROWS", "whole")) base.profile_rows = ProfileRows::whole;
    if (is("VKSONAR_STAGE_TIMING", "host")) base.stage_timing = StageTiming::host;
    if (is("VKSONAR_STAGE_TIMING", "timestamps")) base.stage_timing = StageTiming::timestamps;
    if (is("VKSONAR_STAGE_TIMING", "passes")) base.stage_timing = StageTiming::passes;
    return base;
}

const Plan& renderer_plan(const Renderer& renderer) {
    return detail::Access::renderer(renderer).plan;
}

const Plan& renderer_plan(const HostDepthRenderer& renderer) {
    return detail::Access::renderer(renderer).plan;
}

host::Workers* renderer_workers(const Renderer& renderer) {
    return detail::Access::renderer(renderer).workers.get();
}

} // namespace vksonar
