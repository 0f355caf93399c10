// WriteBehind (write_behind.h): a ring of frame slots between the render loop and one writer thread.
#include "cli/write_behind.h"

#include <utility>

namespace vksonar::cli {

WriteBehind::WriteBehind(std::vector<Frame> frames, WriteFn write) : write_(std::move(write)) {
    slots_.resize(frames.size());
    for (std::size_t i = 0; i < frames.size(); ++i)
        slots_[i].frame = std::move(frames[i]);
    thread_ = std::thread([this] { run(); });
}

WriteBehind::~WriteBehind() {
    {
        std::lock_guard<std::mutex> lock(mutex_);
        stopping_ = true;
    }
    slot_ready_.notify_all();
    thread_.join();
}

void WriteBehind::rethrow_locked() {
    if (error_) std::rethrow_exception(error_);
}

WriteBehind::Slot& WriteBehind::acquire(std::size_t ahead) {
    std::unique_lock<std::mutex> lock(mutex_);
    slot_free_.wait(lock, [&] { return error_ || submitted_ + ahead - written_ < slots_.size(); });
    rethrow_locked();
    return slots_[(submitted_ + ahead) % slots_.size()];
}

void WriteBehind::submit() {
    {
        std::lock_guard<std::mutex> lock(mutex_);
        ++submitted_;
    }
    slot_ready_.notify_one();
}

void WriteBehind::finish() {
    std::unique_lock<std::mutex> lock(mutex_);
    slot_free_.wait(lock, [&] { return error_ || written_ == submitted_; });
    rethrow_locked();
}

std::uint64_t WriteBehind::written() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return written_;
}

void WriteBehind::run() {
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
        // Stopping still drains what was submitted: a frame that rendered is written.
        slot_ready_.wait(lock, [&] { return stopping_ || written_ < submitted_; });
        if (written_ == submitted_ || error_) return;
        const Slot& slot = slots_[written_ % slots_.size()];
        lock.unlock();
        std::exception_ptr failed;
        try {
            write_(slot);
        } catch (...) {
            failed = std::current_exception();
        }
        lock.lock();
        if (failed) {
            error_ = failed;
        } else {
            ++written_;
        }
        slot_free_.notify_all();
        if (error_) return;
    }
}

} // namespace vksonar::cli
