// take_export_queue.cpp — one worker thread, a bounded queue, a cancel flag.
#include "serve/take_export_queue.hpp"

#include <pthread.h>

namespace mocap::serve {

bool TakeExportQueue::submit(Job job) {
    std::lock_guard lock(mutex_);
    if (stopping_ || waiting_.size() >= max_waiting_) return false;
    waiting_.push_back(std::move(job));
    if (!thread_.joinable()) {
        thread_ = std::thread([this] {
            pthread_setname_np(pthread_self(), "mocap-export");
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
        cancel_.store(true);
    }
    wake_.notify_one();
    if (thread_.joinable()) thread_.join();
}

void TakeExportQueue::run() {
    for (;;) {
        Job job;
        {
            std::unique_lock lock(mutex_);
            wake_.wait(lock, [this] { return stopping_ || !waiting_.empty(); });
            if (waiting_.empty()) return;  // stopping, nothing left
            job = std::move(waiting_.front());
            waiting_.pop_front();
        }
        job(cancel_);
    }
}

}  // namespace mocap::serve
