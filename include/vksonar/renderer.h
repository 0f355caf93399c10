// Renderer: one simulated sonar. Create once per (config, scene); render() many poses. (Embedded in an
// engine, on the engine's own depth images: HostDepthRenderer, vksonar/host_depth.h.)
// Thread-safety: a Renderer is not thread-safe (one thread at a time uses it: one Renderer per thread);
// several Renderers, on as many threads, may share one Context. Frame, Scene and SonarConfig are plain
// values: safe to read from many threads, to write from one. A Scene must not change while a Renderer
// made from it exists.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "vksonar/config.h"
#include "vksonar/context.h"
#include "vksonar/frame.h"
#include "vksonar/result.h"
#include "vksonar/scene.h"
#include "vksonar/validity.h"

namespace vksonar {

// Where a Renderer runs its stages: the Vulkan device of its Context, or the CPU reference (same math;
// needs no Vulkan). Host stages (noise, gain, labels) run on the CPU either way.
enum class Backend : std::uint8_t { vulkan, cpu };

// How the Vulkan backend reads its small tables (materials, column and beam tables, side-lobe
// weights). automatic: through uniform blocks where they fit maxUniformBufferRange, else through
// their storage bindings; storage: always through storage bindings. Frames are bit-identical either
// way (tests compare the two); automatic is the fast path.
enum class TableAccess : std::uint8_t { automatic, storage };
// How resample.comp sums each beam's columns. automatic: walk each run of columns once where that
// adds the same terms in the same order as the gather, else gather; gather: always gather. Frames
// are bit-identical either way; automatic is the fast path.
enum class ResampleMethod : std::uint8_t { automatic, gather };
// How the Vulkan backend shares out the beamform passes. automatic: by the device's type; cpu_device:
// few invocations that each do much (lavapipe runs a workgroup's lanes as loops): one per pixel column
// (line array: per four cone columns) for the range profiles, 16 beams each for resample and side
// lobes; gpu: 32 invocations per column (line array: per cone column), each adding to every 32nd bin,
// and 4 beams each, which a GPU needs to be busy. Frames are bit-identical either way.
enum class WorkLayout : std::uint8_t { automatic, cpu_device, gpu };
// How profile.comp walks the rows of its columns. automatic: in bands of rows, one dispatch each, sized
// so that no invocation loops more often than lavapipe allows (it ends an invocation's loops after 65535
// iterations in all); whole: one dispatch over every row (as before the bands: where the device ends its
// loops early, render() then fails with ErrorCode::unsupported instead of returning a frame with rows
// missing). Frames are bit-identical either way wherever the loops run to the end.
enum class ProfileRows : std::uint8_t { automatic, whole };
// How the Vulkan backend measures Frame::times. automatic: timestamp queries where the queue has
// them, except on CPU devices (lavapipe), else host clocks around one submission per stage; host:
// always host clocks; timestamps: timestamp queries where the queue has them, else host clocks;
// passes: as timestamps, and where there are timestamps Frame::times also lists the beamform stage's
// passes ("bf:profile", "bf:resample", "bf:far_deposit", "bf:far_convolve", "bf:sidelobe": GPU time from
// the pass before to this one's end) and the host's own steps around the GPU work ("host:prepare":
// draw matrices, culling, sub-pixel returns; "host:record"; "host:gpu_wait": submit to fence; "host:copy":
// the readback out; not on a HostDepthRenderer, which lists the passes only), and with labels the
// labels stage's parts ("labels:pixels", "labels:beams", "labels:visible", host clocks; on either
// backend). The CPU backend lists its beamform passes on host clocks ("bf:profile"; "bf:beams": the
// resample and the side lobes, fused). Those entries (names with a ':') lie inside or beside the
// stages and are not stages:
// a sum over Frame::times skips them. A timestamp between passes can cost a little GPU time: for finding
// where a frame goes, not for the frame rate.
enum class StageTiming : std::uint8_t { automatic, host, timestamps, passes };

// How a renderer runs, fixed at create (copied there).
// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct RendererOptions {
    Backend backend = Backend::vulkan;
    std::uint64_t seed = 1;
    SaveFlags save_mask = SaveFlags::none; // the intermediates make_frame sizes and render fills
    // Threads for the host stages (noise, gain): 0 = one per hardware thread (at most 16), 1 = the
    // calling thread only. Created once with the Renderer. Output does not depend on it.
    std::uint32_t host_threads = 0;
    // Vulkan backend paths (ignored by the CPU backend); the defaults are the fast paths.
    TableAccess tables = TableAccess::automatic;
    ResampleMethod resample = ResampleMethod::automatic;
    WorkLayout layout = WorkLayout::automatic;
    StageTiming stage_timing = StageTiming::automatic;
    ProfileRows profile_rows = ProfileRows::automatic;
};

// The options `base` with what the environment asks for, for tools and tests; vksonar itself never
// reads the environment. VKSONAR_HOST_THREADS=N sets host_threads (when base.host_threads is 0),
// VKSONAR_TABLES=storage, VKSONAR_RESAMPLE=gather, VKSONAR_LAYOUT=cpu_device|gpu,
// VKSONAR_STAGE_TIMING=host|timestamps|passes and VKSONAR_PROFILE_ROWS=whole set the paths above; other values are
// ignored. Thread-safety: reads the environment (std::getenv).
[[nodiscard]] RendererOptions renderer_options_from_env(RendererOptions base = {});

// The frame a caller will render next, for Renderer::render's look-ahead.
struct NextFrame {
    Pose pose;
    std::uint64_t frame_index = 0;
};

class RendererImpl; // internal
namespace detail {
struct Access; // internal: src/core/access.h
}

// Thread-safety: not thread-safe: one thread at a time; Renderers sharing a Context are independent.
class Renderer {
public:
    // An empty renderer, to move one from create() into: render() on it fails with
    // ErrorCode::invalid_argument and make_frame() gives an empty Frame; set_seed(), seed(), config(),
    // validity() and label_flow's frames need a renderer from create(). Move-only; destroying it frees
    // every buffer and Vulkan object it made (after its submissions finished), none of the Context's
    // or Scene's.
    Renderer();
    ~Renderer();
    Renderer(Renderer&&) noexcept;
    Renderer& operator=(Renderer&&) noexcept;

    // Validates the config, resolves effects against the scene, builds the plan, creates every buffer,
    // pipeline and command buffer it will use and uploads the scene (submitting on the context's queue
    // and waiting). Fails with ErrorCode::invalid_argument for a config or material that does not
    // validate (naming the key) or an option no value has (naming the field), ErrorCode::no_device for Backend::vulkan
    // on a CPU-only context, ErrorCode::unsupported for a grid past the device's limits, an adopted queue without
    // graphics, host memory that runs out or a host thread that cannot start (RendererOptions::host_threads),
    // ErrorCode::vulkan if a Vulkan call fails. The context and scene must outlive the renderer;
    // config and options are copied. Thread-safety: may be called from any thread, also while other
    // renderers on the same context create or render.
    [[nodiscard]] static Result<Renderer> create(Context& context, const SonarConfig& config, const Scene& scene,
                                                 const RendererOptions& options = {});

    // A new frame sized for this renderer and its save_mask (the only allocation; reuse it for every
    // render). Owned by the caller.
    Frame make_frame() const;

    // The noise seed (RendererOptions::seed): (seed, frame_index) key the noise of every frame, so a
    // frame is reproducible from the two alone. Changing it costs nothing.
    void set_seed(std::uint64_t seed);
    std::uint64_t seed() const;

    // Renders the scene from `pose` into `frame` (from make_frame) and waits for it. frame_index keys the
    // noise RNG with the seed. Allocates nothing. Fails with ErrorCode::invalid_argument for an empty
    // renderer, a non-finite pose or a frame of another size, ErrorCode::vulkan if a Vulkan call fails
    // (the frame's contents are then unspecified).
    [[nodiscard]] Result<void> render(const Pose& pose, std::uint64_t frame_index, Frame& frame);
    // As render(pose, frame_index, frame), and once this frame's device work is done, starts the next
    // frame's (`next`) before this frame's host stages (noise, gain) run, so that the device renders the
    // next frame while the host finishes this one; the noise draws of `next` are made then too. For a
    // sequence of poses known one ahead (a trajectory, a dataset): on a GPU, frames/s then follows the
    // GPU's time per frame instead of the GPU's plus the host's (docs/benchmarks.md). The next render()
    // picks the started frame up when its pose is next.pose (its frame_index may differ: the noise is
    // then drawn anew); for any other pose it waits for the started work, drops it and renders its own.
    // Frames are bit-identical to render()'s. The CPU backend has no device to overlap: there this is
    // render(pose, frame_index, frame). Fails as render() does, also for a non-finite next.pose.
    [[nodiscard]] Result<void> render(const Pose& pose, std::uint64_t frame_index, Frame& frame, const NextFrame& next);

    // Flow between two frames this renderer made with SaveFlags::labels, in a static scene
    // (docs/labels.md): for each cell of `from` with a label, where its point lands in the polar grid
    // seen from to_pose, as flow[2 i] = d_bin, flow[2 i + 1] = d_beam (bins * beams * 2, float; resized
    // only if its size differs); NaN where the cell has no label, the point leaves the window or
    // something in `to` hides it. Fails with invalid_argument without labels or on frames not its own,
    // unsupported if host memory for `flow` runs out.
    [[nodiscard]] Result<void> label_flow(const Frame& from, const Pose& from_pose, const Frame& to,
                                          const Pose& to_pose, std::vector<float>& flow) const;

    // The validated config this renderer was made with (valid as long as the renderer).
    const SonarConfig& config() const;
    // Each model this renderer's frames use, checked against its validity domain (validity.h): the
    // entries with ok == false are what the CLI prints as warnings and meta.json lists under "validity".
    const std::vector<ModelValidity>& validity() const;

private:
    friend struct detail::Access; // src/core/access.h
    std::unique_ptr<RendererImpl> impl_;
};

} // namespace vksonar
