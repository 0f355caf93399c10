// The interface both backends implement: depth pass, normals, echo and beamform for one pose.
// Host stages (noise, gain, images) run after it and are shared.
#pragma once

#include <cstdint>
#include <string>

#include "vksonar/frame.h"
#include "vksonar/result.h"
#include "vksonar/scene.h"

namespace vksonar {

struct Plan;
struct SceneData;
class SubpixelReturns;

class StageBackend {
public:
    virtual ~StageBackend() = default;
    // Fills frame.clean (bins * beams, linear, relative to SL), the intermediates selected by
    // save_mask, frame.times (one entry per GPU/CPU stage run) and frame.stages_run.
    // Must not allocate once the frame is sized (Renderer::make_frame).
    [[nodiscard]] virtual Result<void> render(const Pose& pose, SaveFlags save_mask, Frame& frame) = 0;
    // render() in two halves, for a caller that knows its next pose (Renderer::render with a NextFrame):
    // start() does the work up to the device's submission and returns while the device renders; finish()
    // waits for it and fills `frame` as render() would. keep_last: what the frame finished last left
    // readable (pending_clean()) stays so while this one renders. overlap: run the set_gpu_overlap work
    // once the device has the frame. A backend without a device (renders_ahead() false) has neither.
    virtual bool renders_ahead() const { return false; }
    [[nodiscard]] virtual Result<void> start(const Pose&, SaveFlags, bool /*keep_last*/, bool /*overlap*/) {
        return make_error(ErrorCode::unsupported, std::string(name()) + " backend: no start()");
    }
    [[nodiscard]] virtual Result<void> finish(Frame&) {
        return make_error(ErrorCode::unsupported, std::string(name()) + " backend: no finish()");
    }
    virtual const char* name() const = 0;
    // The last render's sub-pixel returns (core/subpixel.h), for the labels stage; null: none listed.
    virtual const SubpixelReturns* subpixel_returns() const = 0;
    // After defer_clean(true), render() may leave the clean scan where pending_clean() points (bins *
    // beams floats, valid until the next render) instead of copying it into frame.clean: the noise stage
    // copies it there on its threads as it reads it (a single-threaded 1 MiB copy out of the Vulkan
    // backend's readback took 0.10 ms of an H100 frame). null: render() filled frame.clean.
    virtual void defer_clean(bool) {}
    virtual const float* pending_clean() const { return nullptr; }
    // Host work that needs nothing of the frame's results (the noise stage's draws): a backend that waits
    // for a device calls work(context) once per render() while the device runs; the Vulkan backend does,
    // after its submission. Others never call it, and the caller then does that work itself.
    virtual void set_gpu_overlap(void (*)(void*), void*) {}
};

} // namespace vksonar
