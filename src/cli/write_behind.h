// WriteBehind: the render loop renders on the calling thread while one background thread writes the
// frames before it, so a trajectory runs at render speed instead of render + write speed.
//
// A fixed ring of frame slots, each a Frame made once by Renderer::make_frame (nothing is allocated
// per frame for the frame data): the caller acquires the next slot (blocking while every slot still
// waits to be written: back-pressure), renders into it and submits it; the writer takes the slots in
// submission order, so no frame is lost or reordered. The first exception the write function throws
// stops the writer (no later frame is written, so what is on disk is a prefix of the trajectory) and
// is rethrown to the caller by the next acquire() or finish(), keeping its type (bad input or failure).
#pragma once

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include "vksonar/frame.h"
#include "vksonar/scene.h"

namespace vksonar::cli {

class WriteBehind {
public:
    struct Slot {
        Frame frame;
        Pose pose;
        std::uint64_t line = 0;    // the trajectory line (the frame index)
        double time_s = 0.0;       // the trajectory's time column, if any
        std::uint64_t time_ns = 0; // ... in nanoseconds as written (TrajectoryPose::time_ns)
        std::vector<float> flow;   // --save flow: label_flow to the next frame (sized on first use)
    };
    using WriteFn = std::function<void(const Slot&)>;

    // `frames` are the slots (at least one), moved in; `write` runs on the background thread only.
    WriteBehind(std::vector<Frame> frames, WriteFn write);
    // Writes what was submitted and not yet written (unless the writer failed), then joins the thread.
    ~WriteBehind();
    WriteBehind(const WriteBehind&) = delete;
    WriteBehind& operator=(const WriteBehind&) = delete;

    // The next slot to render into; waits while all slots are pending. Rethrows the writer's error.
    // ahead = 1: the slot after the next, while the next is held back unsubmitted (--save flow renders
    // frame t + 1 before frame t is submitted); the ring needs two slots for it.
    Slot& acquire(std::size_t ahead = 0);
    // Hands the slot from acquire() to the writer.
    void submit();
    // Waits until every submitted slot is written. Rethrows the writer's error.
    void finish();
    // Frames written so far (for progress and for keeping the output directory).
    std::uint64_t written() const;

private:
    void run();
    void rethrow_locked(); // with mutex_ held

    std::vector<Slot> slots_;
    WriteFn write_;
    mutable std::mutex mutex_;
    std::condition_variable slot_free_;  // the writer finished a slot (or failed)
    std::condition_variable slot_ready_; // a slot was submitted (or stopping)
    std::uint64_t submitted_ = 0, written_ = 0;
    bool stopping_ = false;
    std::exception_ptr error_;
    std::thread thread_; // last: started once everything above exists
};

} // namespace vksonar::cli
