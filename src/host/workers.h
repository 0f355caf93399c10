// A fixed set of helper threads for the host stages, created once with the Renderer (never per
// frame). run() splits one stage into `count()` parts, runs part 0 on the caller and the others on the
// helpers, and returns when all are done. The parts are pure functions of their index, so the
// result never depends on the thread count or the scheduling.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>
#include <vector>

namespace vksonar::host {

// The CPUs this process may run on: its affinity mask where the system has one (a Slurm task, `taskset`,
// a container's cpuset), which std::thread::hardware_concurrency ignores, else the hardware threads;
// at least 1.
std::uint32_t usable_cpus();

class Workers {
public:
    using Task = void (*)(void* context, std::uint32_t part, std::uint32_t parts);

    // threads = 0: one per usable CPU (usable_cpus); at most kMaxThreads.
    // 1: everything on the caller. If a thread cannot start, the ones started are stopped and joined
    // and the std::system_error (or std::bad_alloc) is rethrown: Renderer::create turns it into an Error.
    explicit Workers(std::uint32_t threads = 0);
    ~Workers();
    Workers(const Workers&) = delete;
    Workers& operator=(const Workers&) = delete;

    void run(Task task, void* context);
    std::uint32_t count() const { return static_cast<std::uint32_t>(helpers_.size()) + 1; }

    // Runs task(context, block, thread) once for every block in [0, blocks), on whichever thread comes
    // first: the caller and the helpers take blocks in turn from a shared counter, so a helper that the
    // system runs late (another process on its core) leaves its blocks to the others instead of holding
    // up the stage. thread: the index of the thread running the block (0 = the caller, < count()), for
    // per-thread scratch. Returns when every block is done. Which thread runs a block must not change
    // its result: each block a pure function of its index.
    using BlockTask = void (*)(void* context, std::uint32_t block, std::uint32_t thread);
    void run_blocks(BlockTask task, void* context, std::uint32_t blocks);

    static constexpr std::uint32_t kMaxThreads = 16;

private:
    void helper_loop(std::uint32_t part);
    void stop_helpers(); // tells every helper to return and joins it

    std::vector<std::thread> helpers_;
    std::mutex mutex_;
    std::condition_variable start_, done_;
    Task task_ = nullptr;
    void* context_ = nullptr;
    // Written under mutex_; atomic so that a thread may spin on them briefly before it sleeps
    // (spin_until): the next job of a frame, or the last helper's end, comes within microseconds.
    std::atomic<std::uint64_t> generation_{0}; // bumped by run(): helpers wait for a new one
    std::atomic<std::uint32_t> pending_{0};    // helpers still working on the current generation
    bool stop_ = false;
    // run_blocks: helpers join the generation only while it is open, and the caller waits for the
    // ones that joined (active_) after closing it.
    bool blocks_ = false, open_ = false;
    std::atomic<std::uint32_t> active_{0};
};

// task(context, part, parts) for every part of `workers` (Workers::run), or as the one part on the
// caller where there is no pool.
inline void run_parts(Workers* workers, Workers::Task task, void* context) {
    if (workers != nullptr)
        workers->run(task, context);
    else
        task(context, 0, 1);
}

} // namespace vksonar::host
