// Pipeline micro-benchmarks: ring throughput, worker-pool sample->pose latency (hot and
// after sleeping, i.e. including the futex wake-up), counter add and histogram record (any-
// thread vs single-writer forms) and frame assembly.
// Run: build/tests/bench/core_bench --benchmark_min_time=0.2
#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <thread>
#include <vector>

#include "core/counters.hpp"
#include "core/latency_histogram.hpp"
#include "core/spsc_ring.hpp"
#include "core/subject_assembler.hpp"
#include "core/worker_pool.hpp"

namespace mocap {
namespace {

std::int64_t steady_ns() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

void BM_SpscRingPushPop(benchmark::State& state) {
    SpscRing<SegmentSample> ring(1024);
    SegmentSample in, out;
    for (auto _ : state) {
        benchmark::DoNotOptimize(ring.try_push(in));
        benchmark::DoNotOptimize(ring.try_pop(out));
    }
    state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_SpscRingPushPop);

// Producer on another thread, consumer here: items per second across two cores.
void BM_SpscRingTwoThreads(benchmark::State& state) {
    SpscRing<SegmentSample> ring(1024);
    std::atomic<bool> stop{false};
    std::thread producer([&] {
        SegmentSample s;
        while (!stop.load(std::memory_order_relaxed)) {
            for (int i = 0; i < 64; ++i) {
                ++s.sync;
                if (!ring.try_push(s)) break;
            }
        }
    });
    SegmentSample out;
    std::int64_t popped = 0;
    for (auto _ : state) {
        while (!ring.try_pop(out)) {
        }
        ++popped;
    }
    stop.store(true);
    producer.join();
    state.SetItemsProcessed(popped);
}
BENCHMARK(BM_SpscRingTwoThreads)->UseRealTime();

class TrivialProcessor : public SegmentProcessor {
public:
    bool process(const SegmentSample& in, SegmentPose& out) override {
        out.q_earth_sensor_wxyz = {1.0, 0.0, 0.0, static_cast<double>(in.sync)};
        return true;
    }
};

// One sample submitted, the pose drained on this thread; reports percentiles of the round
// trip. Arg 0: worker spins, consumer spins (hot path, no sleep).
// Arg 1: worker asleep at submit (futex wake), consumer spins.
// Arg 2: both asleep (worker wake + assembler-thread wake through wait_for_output), the
//        daemon's configuration when the load is light.
void BM_WorkerPoolSampleToPose(benchmark::State& state) {
    const auto mode = state.range(0);
    WorkerPoolConfig cfg;
    cfg.workers = 1;
    cfg.spin_iterations = mode == 0 ? 1'000'000'000u : 0u;
    WorkerPool pool(cfg);
    TrivialProcessor proc;
    pool.add_segment(0, 0, proc);
    pool.start();
    std::vector<std::int64_t> rtt_ns;
    rtt_ns.reserve(1 << 16);
    SegmentSample s;
    for (auto _ : state) {
        if (mode != 0) {
            state.PauseTiming();
            std::this_thread::sleep_for(std::chrono::microseconds(200));  // let it sleep
            state.ResumeTiming();
        }
        ++s.sync;
        const std::int64_t t0 = steady_ns();
        pool.submit(s);
        std::size_t got = 0;
        while (got == 0) {
            if (mode == 2) pool.wait_for_output(100'000);
            got = pool.drain([](const PoseUpdate& u) { benchmark::DoNotOptimize(u.sync); });
        }
        if (rtt_ns.size() < rtt_ns.capacity()) rtt_ns.push_back(steady_ns() - t0);
    }
    pool.stop();
    std::sort(rtt_ns.begin(), rtt_ns.end());
    if (!rtt_ns.empty()) {
        auto at = [&](double p) {
            return static_cast<double>(rtt_ns[static_cast<std::size_t>(p * (rtt_ns.size() - 1))]);
        };
        state.counters["p50_ns"] = at(0.50);
        state.counters["p90_ns"] = at(0.90);
        state.counters["p99_ns"] = at(0.99);
        state.counters["max_ns"] = static_cast<double>(rtt_ns.back());
    }
}
BENCHMARK(BM_WorkerPoolSampleToPose)->Arg(0)->Arg(1)->Arg(2)->UseRealTime();

// Any-thread (locked RMW) against single-writer (load + store) forms, same work.
template <class Histogram>
void latency_histogram_record(benchmark::State& state) {
    Histogram h;
    std::int64_t v = 1;
    for (auto _ : state) {
        h.record(v);
        v = (v * 1103515245 + 12345) & 0xFFFF;  // spread over buckets
    }
    benchmark::DoNotOptimize(h.snapshot().count);
    state.SetItemsProcessed(state.iterations());
}
void BM_LatencyHistogramRecord(benchmark::State& state) {
    latency_histogram_record<LatencyHistogram>(state);
}
BENCHMARK(BM_LatencyHistogramRecord);
void BM_SingleWriterLatencyHistogramRecord(benchmark::State& state) {
    latency_histogram_record<SingleWriterLatencyHistogram>(state);
}
BENCHMARK(BM_SingleWriterLatencyHistogramRecord);

// Four counters bumped per iteration, as the reassembler does per raw sample (3 frames + 1
// sample); the counters are read once at the end so the adds cannot be dropped.
template <class C>
void counter_add4(benchmark::State& state) {
    C frames, samples;
    for (auto _ : state) {
        frames.add();
        frames.add();
        frames.add();
        samples.add();
    }
    benchmark::DoNotOptimize(frames.value() + samples.value());
    state.SetItemsProcessed(state.iterations() * 4);
}
void BM_CounterAdd(benchmark::State& state) {
    counter_add4<Counter>(state);
}
BENCHMARK(BM_CounterAdd);
void BM_SingleWriterCounterAdd(benchmark::State& state) {
    counter_add4<SingleWriterCounter>(state);
}
BENCHMARK(BM_SingleWriterCounterAdd);

void BM_LatencySnapshotP99(benchmark::State& state) {
    LatencyHistogram h;
    for (int i = 0; i < 100'000; ++i)
        h.record(i % 5000);
    for (auto _ : state) {
        const LatencySnapshot s = h.snapshot();
        benchmark::DoNotOptimize(s.percentile_us(99));
    }
}
BENCHMARK(BM_LatencySnapshotP99);

class NullSink : public FrameSink {
public:
    void on_frame(const SubjectFrame& f) override { benchmark::DoNotOptimize(f.sync); }
};

// One 15-segment frame assembled and emitted per iteration.
void BM_SubjectAssemblerFrame15(benchmark::State& state) {
    NullSink sink;
    SubjectAssembler a(1, 15, AssemblerConfig{}, sink);
    PoseUpdate u;
    u.subject_id = 1;
    std::uint64_t sync = 0;
    std::int64_t now = 0;
    for (auto _ : state) {
        u.sync = ++sync;
        now += 10'000;
        for (std::uint16_t k = 0; k < 15; ++k) {
            u.segment_index = k;
            a.on_pose(u, now);
        }
    }
    state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_SubjectAssemblerFrame15);

class CountingSink : public FrameSink {
public:
    void on_frame(const SubjectFrame& f) override {
        benchmark::DoNotOptimize(f.sync);
        ++frames;
    }
    std::uint64_t frames = 0;
};

// One SYNC instant of K subjects x 15 segments pushed through the whole core pipeline:
// submit (batched, one wake per worker) -> 2 workers -> drain -> AssemblerSet -> K frames.
// Real time per iteration = latency of a whole instant; at 100 Hz the budget is 10 ms.
void BM_PipelineInstant(benchmark::State& state) {
    const auto subjects = static_cast<std::uint32_t>(state.range(0));
    WorkerPoolConfig cfg;
    cfg.workers = 2;
    cfg.input_capacity = 4096;
    cfg.output_capacity = 4096;
    WorkerPool pool(cfg);
    CountingSink sink;
    AssemblerSet assembler(AssemblerConfig{}, sink);
    std::vector<std::unique_ptr<TrivialProcessor>> procs;
    for (std::uint32_t s = 0; s < subjects; ++s) {
        assembler.add_subject(s, 15);
        for (std::uint16_t k = 0; k < 15; ++k) {
            procs.push_back(std::make_unique<TrivialProcessor>());
            pool.add_segment(s, k, *procs.back());
        }
    }
    pool.start();
    std::uint64_t sync = 0;
    std::int64_t now_us = 0;
    for (auto _ : state) {
        ++sync;
        now_us += 10'000;
        const std::uint64_t target = sink.frames + subjects;
        for (std::uint32_t s = 0; s < subjects; ++s) {
            for (std::uint16_t k = 0; k < 15; ++k) {
                SegmentSample smp;
                smp.subject_id = s;
                smp.segment_index = k;
                smp.sync = sync;
                pool.submit(smp, /*wake=*/false);
            }
        }
        pool.wake_workers();
        while (sink.frames < target) {
            pool.wait_for_output(100'000);
            pool.drain([&](const PoseUpdate& u) { assembler.on_pose(u, now_us); });
        }
    }
    pool.stop();
    state.SetItemsProcessed(state.iterations() * subjects * 15);  // segment samples
}
BENCHMARK(BM_PipelineInstant)->Arg(1)->Arg(50)->UseRealTime();

}  // namespace
}  // namespace mocap

BENCHMARK_MAIN();
