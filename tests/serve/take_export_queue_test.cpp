// The queue that runs take exports off the serve threads (serve/take_export_queue.hpp):
// one at a time, bounded, cancelled by stop().
#include "serve/take_export_queue.hpp"

#include <gtest/gtest.h>

#include <condition_variable>
#include <future>
#include <mutex>
#include <vector>

namespace mocap::serve {
namespace {

using namespace std::chrono_literals;

/// A job that holds the worker until released, so the test controls what waits.
struct Gate {
    std::mutex mutex;
    std::condition_variable cv;
    bool open = false;
    bool entered = false;
    void wait_entered() {
        std::unique_lock lock(mutex);
        ASSERT_TRUE(cv.wait_for(lock, 30s, [this] { return entered; }));
    }
    void release() {
        std::lock_guard lock(mutex);
        open = true;
        cv.notify_all();
    }
    void hold(const std::atomic<bool>& cancel) {
        std::unique_lock lock(mutex);
        entered = true;
        cv.notify_all();
        // stop() sets the flag without knowing this condition variable: look at it often.
        while (!open && !cancel.load())
            cv.wait_for(lock, 5ms);
    }
};

TEST(TakeExportQueue, RunsInOrderOneAtATimeAndRefusesBeyondItsBound) {
    TakeExportQueue queue(2);
    Gate gate;
    std::mutex mutex;
    std::vector<int> order;
    std::promise<void> done;
    ASSERT_TRUE(queue.submit([&](const std::atomic<bool>& cancel) { gate.hold(cancel); }));
    gate.wait_entered();
    // The running job does not count: two more may wait, the third is refused at once.
    ASSERT_TRUE(queue.submit([&](const std::atomic<bool>&) {
        std::lock_guard lock(mutex);
        order.push_back(1);
    }));
    ASSERT_TRUE(queue.submit([&](const std::atomic<bool>&) {
        {
            std::lock_guard lock(mutex);
            order.push_back(2);
        }
        done.set_value();
    }));
    EXPECT_FALSE(queue.submit([](const std::atomic<bool>&) {}));
    gate.release();
    ASSERT_EQ(done.get_future().wait_for(30s), std::future_status::ready);
    std::lock_guard lock(mutex);
    EXPECT_EQ(order, (std::vector<int>{1, 2}));
}

TEST(TakeExportQueue, StopCancelsTheRunningJobAndRunsWaitingOnesCancelled) {
    TakeExportQueue queue(4);
    Gate gate;
    std::atomic<int> cancelled{0};
    ASSERT_TRUE(queue.submit([&](const std::atomic<bool>& cancel) {
        gate.hold(cancel);  // never released: only the cancel flag ends it
        if (cancel.load()) cancelled.fetch_add(1);
    }));
    gate.wait_entered();
    ASSERT_TRUE(queue.submit([&](const std::atomic<bool>& cancel) {
        if (cancel.load()) cancelled.fetch_add(1);
    }));
    queue.stop();
    EXPECT_EQ(cancelled.load(), 2) << "every job learns it is cancelled";
    EXPECT_FALSE(queue.submit([](const std::atomic<bool>&) {}));
}

}  // namespace
}  // namespace mocap::serve
