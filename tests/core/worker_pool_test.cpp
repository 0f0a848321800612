#include "core/worker_pool.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <thread>
#include <vector>

namespace mocap {
namespace {

// Writes a pose derived from the sync so the consumer can check the pose belongs to the
// sample; remembers the last sync it saw to check order on the worker thread itself.
class OrderCheckingProcessor : public SegmentProcessor {
public:
    bool process(const SegmentSample& in, SegmentPose& out) override {
        if (seen_ != 0 && in.sync <= last_sync_) ++out_of_order_;
        last_sync_ = in.sync;
        ++seen_;
        out.q_earth_sensor_wxyz = {1.0, static_cast<double>(in.sync), 0.0, 0.0};
        return true;
    }
    std::uint64_t seen_ = 0;  // read by the test only after stop() joined the workers
    std::uint64_t out_of_order_ = 0;

private:
    std::uint64_t last_sync_ = 0;
};

// Blocks inside process() until released, to fill the input ring deterministically.
class GateProcessor : public SegmentProcessor {
public:
    bool process(const SegmentSample&, SegmentPose&) override {
        entered_.store(true, std::memory_order_release);
        for (int i = 0; i < 200'000 && !open_.load(std::memory_order_acquire); ++i) {
            std::this_thread::sleep_for(std::chrono::microseconds(50));
        }
        return true;
    }
    std::atomic<bool> entered_{false};
    std::atomic<bool> open_{false};
};

class RejectOddProcessor : public SegmentProcessor {
public:
    bool process(const SegmentSample& in, SegmentPose&) override { return in.sync % 2 == 0; }
};

class TickClock : public Clock {
public:
    std::int64_t now_us() const noexcept override { return t_.fetch_add(10, std::memory_order_relaxed) + 10; }
    mutable std::atomic<std::int64_t> t_{1000};
};

SegmentSample sample(std::uint32_t subject, std::uint16_t segment, std::uint64_t sync) {
    SegmentSample s;
    s.subject_id = subject;
    s.segment_index = segment;
    s.sync = sync;
    s.imu.t_us = static_cast<std::int64_t>(sync) * 10'000;
    return s;
}

std::uint64_t counter(const WorkerPool& pool, const char* name) {
    const auto v = pool.counters().value(name);
    EXPECT_TRUE(v.has_value()) << name;
    return v.value_or(0);
}

// Bounded wait for a condition the pool threads make true.
template <typename Pred>
bool eventually(Pred pred) {
    for (int i = 0; i < 20'000; ++i) {
        if (pred()) return true;
        std::this_thread::sleep_for(std::chrono::microseconds(100));
    }
    return pred();
}

TEST(WorkerPool, AssignsSegmentsRoundRobinAndByWeight) {
    WorkerPoolConfig cfg;
    cfg.workers = 3;
    WorkerPool pool(cfg);
    OrderCheckingProcessor p[7];
    for (std::uint16_t k = 0; k < 6; ++k)
        EXPECT_EQ(pool.add_segment(1, k, p[k]), k % 3u);
    EXPECT_EQ(pool.worker_of(1, 4), 1u);
    EXPECT_EQ(pool.worker_of(2, 0), WorkerPool::kNoWorker);
    // A heavy segment lands on worker 0 (all tied), then the next ones avoid it.
    EXPECT_EQ(pool.add_segment(2, 0, p[6], 10), 0u);
    OrderCheckingProcessor q[2];
    EXPECT_EQ(pool.add_segment(2, 1, q[0]), 1u);
    EXPECT_EQ(pool.add_segment(2, 2, q[1]), 2u);
    EXPECT_THROW(pool.add_segment(1, 0, q[0]), std::logic_error);
    EXPECT_EQ(pool.worker_count(), 3u);
}

TEST(WorkerPool, DefaultsToHardwareCores) {
    WorkerPool pool(WorkerPoolConfig{});
    EXPECT_EQ(pool.worker_count(), std::max(1u, std::thread::hardware_concurrency()));
}

TEST(WorkerPool, RejectsBadConfigAndLateRegistration) {
    WorkerPoolConfig bad;
    bad.workers = 1;
    bad.input_capacity = 100;
    EXPECT_THROW(WorkerPool{bad}, std::invalid_argument);
    WorkerPoolConfig cfg;
    cfg.workers = 1;
    WorkerPool pool(cfg);
    OrderCheckingProcessor p;
    pool.add_segment(0, 0, p);
    pool.start();
    EXPECT_THROW(pool.add_segment(0, 1, p), std::logic_error);
    EXPECT_THROW(pool.start(), std::logic_error);
}

TEST(WorkerPool, PreservesPerSegmentOrderAcrossWorkersUnderLoad) {
    constexpr std::uint32_t kSubjects = 3;
    constexpr std::uint16_t kSegments = 15;
    constexpr std::uint64_t kSyncs = 300;
    WorkerPoolConfig cfg;
    cfg.workers = 4;
    cfg.input_capacity = 64;  // small: the producer outruns the workers, some samples drop
    cfg.output_capacity = 4096;
    cfg.spin_iterations = 50;
    WorkerPool pool(cfg);
    std::vector<std::unique_ptr<OrderCheckingProcessor>> procs;
    for (std::uint32_t s = 0; s < kSubjects; ++s) {
        for (std::uint16_t k = 0; k < kSegments; ++k) {
            procs.push_back(std::make_unique<OrderCheckingProcessor>());
            pool.add_segment(s, k, *procs.back());
        }
    }
    pool.start();

    std::atomic<bool> producer_done{false};
    std::map<std::uint64_t, std::uint64_t> last_sync;  // consumer thread only
    std::uint64_t received = 0, out_of_order = 0, wrong_pose = 0;
    std::thread consumer([&] {
        auto on_pose = [&](const PoseUpdate& u) {
            const std::uint64_t key = (std::uint64_t{u.subject_id} << 16) | u.segment_index;
            auto it = last_sync.find(key);
            if (it != last_sync.end() && u.sync <= it->second) ++out_of_order;
            last_sync[key] = u.sync;
            if (u.pose.q_earth_sensor_wxyz[1] != static_cast<double>(u.sync)) ++wrong_pose;
            if (u.pose.sample_us != static_cast<std::int64_t>(u.sync) * 10'000) ++wrong_pose;
            ++received;
        };
        for (int i = 0; i < 200'000; ++i) {
            pool.drain(on_pose);
            if (producer_done.load(std::memory_order_acquire)) break;
            pool.wait_for_output(1000);
        }
        while (pool.drain(on_pose) != 0) {
        }
    });

    std::uint64_t queued = 0, dropped = 0;
    for (std::uint64_t sync = 1; sync <= kSyncs; ++sync) {
        for (std::uint32_t s = 0; s < kSubjects; ++s) {
            for (std::uint16_t k = 0; k < kSegments; ++k) {
                const SubmitResult r = pool.submit(sample(s, k, sync));
                if (r == SubmitResult::kQueued) ++queued;
                if (r == SubmitResult::kDroppedFull) ++dropped;
            }
        }
    }
    pool.stop();  // processes everything queued before joining
    producer_done.store(true, std::memory_order_release);
    consumer.join();

    EXPECT_EQ(queued + dropped, kSubjects * kSegments * kSyncs);
    EXPECT_EQ(counter(pool, "samples_submitted"), queued);
    EXPECT_EQ(counter(pool, "samples_dropped_full"), dropped);
    EXPECT_EQ(counter(pool, "samples_processed"), queued);
    EXPECT_EQ(counter(pool, "poses_dropped_full"), 0u);
    EXPECT_EQ(received, queued);
    EXPECT_EQ(out_of_order, 0u);
    EXPECT_EQ(wrong_pose, 0u);
    std::uint64_t seen = 0;
    for (const auto& p : procs) {
        EXPECT_EQ(p->out_of_order_, 0u);
        seen += p->seen_;
    }
    EXPECT_EQ(seen, queued);
}

TEST(WorkerPool, FullInputRingDropsNewestAndCountsIt) {
    WorkerPoolConfig cfg;
    cfg.workers = 1;
    cfg.input_capacity = 4;
    WorkerPool pool(cfg);
    GateProcessor gate;
    pool.add_segment(0, 0, gate);
    pool.start();
    ASSERT_EQ(pool.submit(sample(0, 0, 1)), SubmitResult::kQueued);
    ASSERT_TRUE(eventually([&] { return gate.entered_.load(); }));
    // The sample being processed keeps its slot until process() returns: 3 more fit.
    for (std::uint64_t s = 2; s <= 4; ++s)
        EXPECT_EQ(pool.submit(sample(0, 0, s)), SubmitResult::kQueued);
    EXPECT_EQ(pool.submit(sample(0, 0, 5)), SubmitResult::kDroppedFull);
    EXPECT_EQ(pool.submit(sample(0, 0, 6)), SubmitResult::kDroppedFull);
    EXPECT_EQ(pool.input_depth(0), 4u);
    gate.open_.store(true);
    pool.stop();
    EXPECT_EQ(counter(pool, "samples_dropped_full"), 2u);
    EXPECT_EQ(counter(pool, "samples_processed"), 4u);
    std::vector<std::uint64_t> syncs;
    pool.drain([&](const PoseUpdate& u) { syncs.push_back(u.sync); });
    EXPECT_EQ(syncs, (std::vector<std::uint64_t>{1, 2, 3, 4}));  // the oldest survive
}

TEST(WorkerPool, FullOutputRingDropsPoseAndCountsIt) {
    WorkerPoolConfig cfg;
    cfg.workers = 1;
    cfg.output_capacity = 2;
    WorkerPool pool(cfg);
    OrderCheckingProcessor p;
    pool.add_segment(0, 0, p);
    pool.start();
    for (std::uint64_t s = 1; s <= 5; ++s)
        ASSERT_EQ(pool.submit(sample(0, 0, s)), SubmitResult::kQueued);
    pool.stop();
    EXPECT_EQ(counter(pool, "poses_dropped_full"), 3u);
    EXPECT_EQ(pool.drain([](const PoseUpdate&) {}), 2u);
}

TEST(WorkerPool, CountsUnknownSegmentsRejectedSamplesAndSubmitsAfterStop) {
    WorkerPoolConfig cfg;
    cfg.workers = 2;
    WorkerPool pool(cfg);
    RejectOddProcessor p;
    pool.add_segment(7, 3, p);
    EXPECT_EQ(pool.submit(sample(7, 3, 1)), SubmitResult::kStopped);  // not started yet
    pool.start();
    EXPECT_EQ(pool.submit(sample(7, 4, 1)), SubmitResult::kUnknownSegment);
    EXPECT_EQ(pool.submit(sample(8, 3, 1)), SubmitResult::kUnknownSegment);
    for (std::uint64_t s = 1; s <= 10; ++s)
        ASSERT_EQ(pool.submit(sample(7, 3, s)), SubmitResult::kQueued);
    pool.stop();
    EXPECT_EQ(pool.submit(sample(7, 3, 11)), SubmitResult::kStopped);
    EXPECT_EQ(counter(pool, "samples_unknown_segment"), 2u);
    EXPECT_EQ(counter(pool, "samples_after_stop"), 2u);
    EXPECT_EQ(counter(pool, "samples_rejected"), 5u);
    EXPECT_EQ(pool.drain([](const PoseUpdate& u) { EXPECT_EQ(u.sync % 2, 0u); }), 5u);
}

TEST(WorkerPool, StampsStagesAndRecordsHistogramsWithAClock) {
    WorkerPoolConfig cfg;
    cfg.workers = 1;
    TickClock clock;
    WorkerPool pool(cfg, &clock);
    OrderCheckingProcessor p;
    pool.add_segment(0, 0, p);
    pool.start();
    SegmentSample s = sample(0, 0, 1);
    s.times.sink_send_us = 500;
    s.times.received_us = 900;
    ASSERT_EQ(pool.submit(s), SubmitResult::kQueued);
    pool.stop();
    PoseUpdate got;
    ASSERT_EQ(pool.drain([&](const PoseUpdate& u) { got = u; }), 1u);
    EXPECT_EQ(got.times.sink_send_us, 500);
    EXPECT_EQ(got.times.received_us, 900);
    EXPECT_EQ(got.times.dequeued_us, 1010);
    EXPECT_EQ(got.times.filtered_us, 1020);
    const auto qw = pool.queue_wait_snapshot();
    ASSERT_EQ(qw.count, 1u);
    EXPECT_EQ(qw.max_us, 110u);
    const auto f = pool.filter_snapshot();
    ASSERT_EQ(f.count, 1u);
    EXPECT_EQ(f.max_us, 10u);
}

TEST(WorkerPool, SleepingWorkerWakesOnSubmit) {
    WorkerPoolConfig cfg;
    cfg.workers = 2;
    cfg.spin_iterations = 0;  // sleep as soon as idle
    WorkerPool pool(cfg);
    OrderCheckingProcessor a, b;
    pool.add_segment(0, 0, a);
    pool.add_segment(0, 1, b);
    pool.start();
    ASSERT_TRUE(eventually([&] { return counter(pool, "worker_sleeps") >= 2; }));
    std::uint64_t got = 0;
    for (std::uint64_t round = 1; round <= 20; ++round) {
        const std::uint64_t sleeps = counter(pool, "worker_sleeps");
        ASSERT_EQ(pool.submit(sample(0, round % 2, round)), SubmitResult::kQueued);
        std::uint64_t n = 0;
        for (int i = 0; i < 500 && n == 0; ++i) {
            pool.wait_for_output(10'000);
            n = pool.drain([](const PoseUpdate&) {});
        }
        ASSERT_EQ(n, 1u) << "round " << round;
        got += n;
        // The worker goes back to sleep before the next round.
        ASSERT_TRUE(eventually([&] { return counter(pool, "worker_sleeps") > sleeps; }));
    }
    pool.stop();
    EXPECT_EQ(got, 20u);
}

TEST(WorkerPool, BatchSubmitWakesOncePerWorker) {
    WorkerPoolConfig cfg;
    cfg.workers = 2;
    cfg.spin_iterations = 0;
    WorkerPool pool(cfg);
    OrderCheckingProcessor p[4];
    for (std::uint16_t k = 0; k < 4; ++k)
        pool.add_segment(0, k, p[k]);
    pool.start();
    ASSERT_TRUE(eventually([&] { return counter(pool, "worker_sleeps") >= 2; }));
    for (std::uint16_t k = 0; k < 4; ++k) {
        ASSERT_EQ(pool.submit(sample(0, k, 1), /*wake=*/false), SubmitResult::kQueued);
    }
    pool.wake_workers();
    std::size_t got = 0;
    for (int i = 0; i < 500 && got < 4; ++i) {
        pool.wait_for_output(10'000);
        got += pool.drain([](const PoseUpdate&) {});
    }
    EXPECT_EQ(got, 4u);
    pool.stop();
}

TEST(WorkerPool, StopIsPromptEvenWithALongSpinAndPinnedWorkers) {
    WorkerPoolConfig cfg;
    cfg.workers = 2;
    cfg.spin_iterations = 4'000'000'000u;  // would spin for minutes without the stop check
    cfg.pin_cpus = true;
    WorkerPool pool(cfg);
    OrderCheckingProcessor p;
    pool.add_segment(0, 0, p);
    pool.start();
    ASSERT_EQ(pool.submit(sample(0, 0, 1)), SubmitResult::kQueued);
    const auto t0 = std::chrono::steady_clock::now();
    pool.stop();
    EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(2));
    EXPECT_EQ(counter(pool, "samples_processed"), 1u);
}

TEST(WorkerPool, StopProcessesEverythingQueued) {
    WorkerPoolConfig cfg;
    cfg.workers = 2;
    WorkerPool pool(cfg);
    OrderCheckingProcessor p[4];
    for (std::uint16_t k = 0; k < 4; ++k)
        pool.add_segment(0, k, p[k]);
    pool.start();
    for (std::uint64_t s = 1; s <= 200; ++s)
        ASSERT_EQ(pool.submit(sample(0, s % 4, s)), SubmitResult::kQueued);
    pool.stop();
    pool.stop();  // idempotent
    EXPECT_EQ(counter(pool, "samples_processed"), 200u);
    EXPECT_EQ(pool.drain([](const PoseUpdate&) {}, 1000), 200u);
    EXPECT_TRUE(pool.wait_for_output(1'000'000));  // returns at once once stopped
}

}  // namespace
}  // namespace mocap
