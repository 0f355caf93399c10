#include "host/workers.h"

#include <algorithm>
#include <cstdlib>
#if defined(__linux__)
#include <sched.h>
#endif

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif
#include <chrono>

namespace vksonar::host {

namespace {

// Spins until done() or about kSpinMicroseconds have passed (the caller then checks again under its lock,
// and sleeps if need be). A futex wake-up costs tens of
// microseconds on a VM, against stages of a few hundred: a thread that is about to sleep between two jobs
// of a frame (or while the last helper finishes) waits this long awake first.
constexpr int kSpinMicroseconds = 50;
template <class Done> void spin_until(const Done& done) {
    const auto start = std::chrono::steady_clock::now();
    for (;;) {
        for (int i = 0; i < 64; ++i) {
            if (done()) return;
#if defined(__x86_64__) || defined(__i386__)
            _mm_pause();
#endif
        }
        if (std::chrono::steady_clock::now() - start > std::chrono::microseconds(kSpinMicroseconds)) return;
    }
}

} // namespace

std::uint32_t usable_cpus() {
#if defined(__linux__)
    cpu_set_t set;
    CPU_ZERO(&set);
    if (sched_getaffinity(0, sizeof set, &set) == 0 && CPU_COUNT(&set) > 0)
        return static_cast<std::uint32_t>(CPU_COUNT(&set));
#endif
    return std::max(1u, std::thread::hardware_concurrency());
}

Workers::Workers(std::uint32_t threads) {
    if (threads == 0) threads = usable_cpus();
    threads = std::min(threads, kMaxThreads);
    helpers_.reserve(threads - 1);
    try {
        for (std::uint32_t part = 1; part < threads; ++part)
            helpers_.emplace_back([this, part] { helper_loop(part); });
    } catch (...) {
        // A thread that could not start (std::system_error): the destructor will not run, and a
        // joinable std::thread destroyed with helpers_ would call std::terminate. Stop and join the
        // ones that started, then let the caller see the failure.
        stop_helpers();
        throw;
    }
}

Workers::~Workers() {
    stop_helpers();
}

void Workers::stop_helpers() {
    {
        std::lock_guard<std::mutex> lock(mutex_);
        stop_ = true;
    }
    start_.notify_all();
    for (auto& helper : helpers_)
        helper.join();
}

void Workers::run(Task task, void* context) {
    const std::uint32_t parts = count();
    if (parts > 1) {
        std::lock_guard<std::mutex> lock(mutex_);
        task_ = task;
        context_ = context;
        pending_ = parts - 1;
        blocks_ = false;
        ++generation_;
    }
    start_.notify_all();
    task(context, 0, parts);
    if (parts > 1) {
        spin_until([this] { return pending_.load(std::memory_order_acquire) == 0; });
        std::unique_lock<std::mutex> lock(mutex_);
        done_.wait(lock, [this] { return pending_ == 0; });
    }
}

namespace {

struct BlockJob {
    Workers::BlockTask task;
    void* context;
    std::uint32_t blocks;
    std::atomic<std::uint32_t> next{0};
};

// Takes blocks until none is left.
void take_blocks(void* job_pointer, std::uint32_t thread, std::uint32_t) {
    auto& job = *static_cast<BlockJob*>(job_pointer);
    for (std::uint32_t block = job.next.fetch_add(1, std::memory_order_relaxed); block < job.blocks;
         block = job.next.fetch_add(1, std::memory_order_relaxed))
        job.task(job.context, block, thread);
}

} // namespace

void Workers::run_blocks(BlockTask task, void* context, std::uint32_t blocks) {
    if (count() == 1 || blocks < 2) {
        for (std::uint32_t block = 0; block < blocks; ++block)
            task(context, block, 0);
        return;
    }
    BlockJob job{task, context, blocks};
    {
        std::lock_guard<std::mutex> lock(mutex_);
        task_ = take_blocks;
        context_ = &job;
        blocks_ = true;
        open_ = true;
        active_ = 0;
        ++generation_;
    }
    start_.notify_all();
    take_blocks(&job, 0, count());
    // Every block is taken: close the job (a helper that wakes now leaves it alone) and wait for the
    // helpers still running the blocks they took.
    std::unique_lock<std::mutex> lock(mutex_);
    open_ = false;
    if (active_ != 0) {
        lock.unlock();
        spin_until([this] { return active_.load(std::memory_order_acquire) == 0; });
        lock.lock();
    }
    done_.wait(lock, [this] { return active_ == 0; });
}

void Workers::helper_loop(std::uint32_t part) {
    std::uint64_t seen = 0;
    for (;;) {
        Task task;
        void* context;
        bool blocks;
        {
            spin_until([&] { return generation_.load(std::memory_order_acquire) != seen; });
            std::unique_lock<std::mutex> lock(mutex_);
            start_.wait(lock, [&] { return stop_ || generation_ != seen; });
            if (stop_) return;
            seen = generation_;
            blocks = blocks_;
            if (blocks && !open_) continue; // a run_blocks job already done without this helper
            if (blocks) ++active_;
            task = task_;
            context = context_;
        }
        task(context, part, count());
        {
            std::lock_guard<std::mutex> lock(mutex_);
            if (blocks) {
                if (--active_ == 0) done_.notify_one();
            } else if (--pending_ == 0) {
                done_.notify_one();
            }
        }
    }
}

} // namespace vksonar::host
