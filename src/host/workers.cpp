#include "host/workers.h"

#include <algorithm>
#include <cstdlib>

namespace vksonar::host {

Workers::Workers(std::uint32_t threads) {
    if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
    threads = std::min(threads, kMaxThreads);
    helpers_.reserve(threads - 1);
    for (std::uint32_t part = 1; part < threads; ++part)
        helpers_.emplace_back([this, part] { helper_loop(part); });
}

Workers::~Workers() {
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
        ++generation_;
    }
    start_.notify_all();
    task(context, 0, parts);
    if (parts > 1) {
        std::unique_lock<std::mutex> lock(mutex_);
        done_.wait(lock, [this] { return pending_ == 0; });
    }
}

void Workers::helper_loop(std::uint32_t part) {
    std::uint64_t seen = 0;
    for (;;) {
        Task task;
        void* context;
        {
            std::unique_lock<std::mutex> lock(mutex_);
            start_.wait(lock, [&] { return stop_ || generation_ != seen; });
            if (stop_) return;
            seen = generation_;
            task = task_;
            context = context_;
        }
        task(context, part, count());
        {
            std::lock_guard<std::mutex> lock(mutex_);
            if (--pending_ == 0) done_.notify_one();
        }
    }
}

} // namespace vksonar::host
