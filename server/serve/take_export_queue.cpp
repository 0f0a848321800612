// take_export_queue.cpp — one worker thread at nice 19, a bounded queue, a cancel flag per job.
#include "serve/take_export_queue.hpp"

#include <pthread.h>
#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>

#include "core/errno_text.hpp"

namespace mocap::serve {

bool TakeExportQueue::submit(Job job, std::shared_ptr<std::atomic<bool>> cancel) {
    std::deque<Waiting> abandoned;  // destroyed after the unlock: a job holds its session
    std::lock_guard lock(mutex_);
    if (stopping_) return false;
    // A connection that closed while its export waited set its flag: nobody reads the result.
    for (auto it = waiting_.begin(); it != waiting_.end();) {
        if (it->cancel->load()) {
            abandoned.push_back(std::move(*it));
            it = waiting_.erase(it);
        } else {
            ++it;
        }
    }
    dropped_.fetch_add(abandoned.size(), std::memory_order_relaxed);
    if (waiting_.size() >= max_waiting_) return false;
    waiting_.push_back({std::move(job), std::move(cancel)});
    if (!thread_.joinable()) {
        thread_ = std::thread([this] {
            pthread_setname_np(pthread_self(), "mocap-export");
            // Linux nice values are per thread: this one alone yields to the live path. Only
            // raising the value, which needs no privilege (the unit allows setpriority).
            const auto tid = static_cast<id_t>(::syscall(SYS_gettid));
            if (::setpriority(PRIO_PROCESS, tid, 19) != 0) {
                spdlog::warn("take exports: cannot lower the export thread's priority: {}", errno_text(errno));
            }
            run();
        });
    }
    wake_.notify_one();
    return true;
}

void TakeExportQueue::stop() {
    {
        std::lock_guard lock(mutex_);
        if (stopping_) return;
        stopping_ = true;
        if (running_) running_->store(true);
        for (Waiting& w : waiting_)
            w.cancel->store(true);
    }
    wake_.notify_one();
    if (thread_.joinable()) thread_.join();
}

void TakeExportQueue::run() {
    for (;;) {
        Waiting next;
        bool abandoned = false;
        {
            std::unique_lock lock(mutex_);
            if (running_) running_.reset();
            wake_.wait(lock, [this] { return stopping_ || !waiting_.empty(); });
            if (waiting_.empty()) return;  // stopping, nothing left
            next = std::move(waiting_.front());
            waiting_.pop_front();
            // Abandoned while it waited (not by stop(), whose jobs run to answer their sessions).
            abandoned = next.cancel->load() && !stopping_;
            if (!abandoned) running_ = next.cancel;
        }
        if (abandoned) {
            dropped_.fetch_add(1, std::memory_order_relaxed);
            continue;
        }
        next.job(*next.cancel);
    }
}

}  // namespace mocap::serve
