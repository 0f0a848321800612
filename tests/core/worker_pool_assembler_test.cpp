// The wiring the daemon does, end to end on real threads: one ingest thread submits, the
// worker pool filters, one assembler thread drains into an AssemblerSet.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <map>
#include <memory>
#include <thread>
#include <vector>

#include "core/subject_assembler.hpp"
#include "core/worker_pool.hpp"

namespace mocap {
namespace {

class SteadyClock : public Clock {
public:
    std::int64_t now_us() const noexcept override {
        return std::chrono::duration_cast<std::chrono::microseconds>(
                   std::chrono::steady_clock::now().time_since_epoch())
            .count();
    }
};

class SyncProcessor : public SegmentProcessor {
public:
    bool process(const SegmentSample& in, SegmentPose& out) override {
        out.q_earth_sensor_wxyz = {1.0, static_cast<double>(in.sync), 0.0, 0.0};
        return true;
    }
};

class CheckingSink : public FrameSink {
public:
    void on_frame(const SubjectFrame& f) override {
        auto& last = last_sync[f.subject_id];
        if (f.sync <= last) ++out_of_order;
        last = f.sync;
        ++frames[f.subject_id];
        for (std::size_t k = 0; k < f.segment_count; ++k) {
            if (f.segments[k].flags != 0) ++stale;
            if (f.segments[k].q_earth_sensor_wxyz[1] != static_cast<double>(f.sync)) ++wrong;
        }
        if (f.times.assembled_us < f.times.filtered_us || f.times.filtered_us < f.times.dequeued_us ||
            f.times.dequeued_us < f.times.received_us) {
            ++bad_times;
        }
    }
    std::map<std::uint32_t, std::uint64_t> last_sync, frames;
    std::uint64_t out_of_order = 0, stale = 0, wrong = 0, bad_times = 0;
};

TEST(WorkerPoolAssembler, IngestWorkersAssemblerDeliverEveryFrameInOrder) {
    constexpr std::uint32_t kSubjects = 4;
    constexpr std::uint16_t kSegments = 15;
    constexpr std::uint64_t kSyncs = 200;
    SteadyClock clock;
    WorkerPoolConfig pcfg;
    pcfg.workers = 2;
    pcfg.input_capacity = 8192;  // holds the whole run: this test checks completeness
    pcfg.output_capacity = 8192;
    pcfg.spin_iterations = 100;
    WorkerPool pool(pcfg, &clock);
    CheckingSink sink;
    AssemblerConfig acfg;
    acfg.deadline_us = 5'000'000;  // generous: a loaded CI host must not make frames partial
    acfg.window = 256;             // the whole burst may be open at once (not so in real time)
    AssemblerSet assembler(acfg, sink);
    std::vector<std::unique_ptr<SyncProcessor>> procs;
    for (std::uint32_t s = 0; s < kSubjects; ++s) {
        assembler.add_subject(s, kSegments);
        for (std::uint16_t k = 0; k < kSegments; ++k) {
            procs.push_back(std::make_unique<SyncProcessor>());
            pool.add_segment(s, k, *procs.back());
        }
    }
    pool.start();

    std::atomic<bool> ingest_done{false};
    std::thread assembler_thread([&] {
        auto on_pose = [&](const PoseUpdate& u) { assembler.on_pose(u, clock.now_us()); };
        for (int i = 0; i < 1'000'000; ++i) {
            pool.drain(on_pose);
            assembler.advance(clock.now_us());
            if (ingest_done.load(std::memory_order_acquire)) break;
            const std::int64_t deadline = assembler.next_deadline_us();
            const std::int64_t now = clock.now_us();
            pool.wait_for_output(deadline == kNoDeadline ? 10'000 : std::max<std::int64_t>(deadline - now, 0));
        }
        while (pool.drain(on_pose) != 0) {
        }
        assembler.flush(clock.now_us());
    });

    for (std::uint64_t sync = 1; sync <= kSyncs; ++sync) {
        for (std::uint32_t s = 0; s < kSubjects; ++s) {
            for (std::uint16_t k = 0; k < kSegments; ++k) {
                SegmentSample smp;
                smp.subject_id = s;
                smp.segment_index = k;
                smp.sync = sync;
                smp.times.received_us = clock.now_us();
                ASSERT_EQ(pool.submit(smp), SubmitResult::kQueued);
            }
        }
    }
    pool.stop();
    ingest_done.store(true, std::memory_order_release);
    assembler_thread.join();

    for (std::uint32_t s = 0; s < kSubjects; ++s)
        EXPECT_EQ(sink.frames[s], kSyncs) << "subject " << s;
    EXPECT_EQ(sink.out_of_order, 0u);
    EXPECT_EQ(sink.stale, 0u);
    EXPECT_EQ(sink.wrong, 0u);
    EXPECT_EQ(sink.bad_times, 0u);
    EXPECT_EQ(assembler.counters().value("frames_complete"), kSubjects * kSyncs);
    EXPECT_EQ(pool.queue_wait_snapshot().count, kSubjects * kSegments * kSyncs);
    EXPECT_EQ(assembler.assembly_snapshot().count, kSubjects * kSyncs);
}

}  // namespace
}  // namespace mocap
