// worker_pool.hpp — N filter worker threads; every segment is pinned to one worker so its
// samples are processed in order without locks.
//
// Data path (all rings are SpscRing, fixed capacity, allocated in start()):
//     ingest thread --submit()--> input ring of the segment's worker --> worker thread:
//     SegmentProcessor::process() --> that worker's output ring --drain()--> assembler thread
//
// Threads and who calls what
// - Set-up thread (before start()): constructor, add_segment(), start().
// - Ingest thread: submit(). ONE producer thread only (each input ring is single-producer);
//   a daemon with several ingest sources funnels them through one ingest thread (or runs one
//   WorkerPool per ingest thread).
// - Assembler thread: drain(), wait_for_output(). ONE consumer thread only.
// - Worker threads (owned by the pool): call SegmentProcessor::process() and, when a clock is
//   given, Clock::now_us().
// - Any thread: counters(), queue_wait_snapshot(), filter_snapshot(), worker_of(),
//   worker_count(), input_depth().
// - stop(): from the set-up/control thread once the ingest thread no longer calls submit().
//   It lets every worker finish what is queued, then joins them. Outputs stay drainable.
//   The destructor calls stop().
//
// Assignment: add_segment() places a segment on the worker with the least total cost weight
// so far (ties: lowest index), i.e. round-robin when all weights are equal. Fixed for the
// pool's lifetime.
//
// Back-pressure (explicit, counted, never blocks the ingest thread):
// - input ring full: submit() drops the NEW sample (drop-newest) and counts
//   samples_dropped_full. Drop-oldest would need the producer to pop from a ring it does not
//   consume. A full ring means the worker is already capacity samples behind, so the segment
//   has lost real time either way; the filter sees a gap, exactly as with a lost CAN frame.
// - output ring full (assembler behind): the worker drops that pose and counts
//   poses_dropped_full; the assembler then flags the segment stale for that instant.
//
// Idle workers spin `spin_iterations` polls (with a CPU pause) and then sleep on a futex
// (EventCount) for at most idle_beat_us; submit() wakes a sleeping worker. Every turn of a
// worker's loop, busy or idle, adds one to its heartbeat (worker_beats(i)): a count that
// stops moving means a worker stuck or frozen (the daemon's /healthz and watchdog). Wake-up costs the scheduler's
// latency (measured in docs/performance.md); spinning longer trades CPU for lower p99.
//
// Cost per sample: submit ~ ring copy (~200 B) + one uncontended atomic RMW; the worker adds two
// Clock::now_us() calls and two histogram records when a clock is given. Nothing on the
// sample path allocates or locks.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <thread>
#include <vector>

#include "core/clock.hpp"
#include "core/counters.hpp"
#include "core/event_count.hpp"
#include "core/frame.hpp"
#include "core/latency_histogram.hpp"
#include "core/metrics_registry.hpp"
#include "core/segment_processor.hpp"
#include "core/spsc_ring.hpp"

namespace mocap {

struct WorkerPoolConfig {
    std::size_t workers = 0;              ///< worker threads; 0 = hardware cores (at least 1)
    std::size_t input_capacity = 1024;    ///< samples per worker input ring (power of two)
    std::size_t output_capacity = 1024;   ///< poses per worker output ring (power of two)
    std::size_t batch = 64;               ///< samples a worker processes before waking the assembler
    std::uint32_t spin_iterations = 200;  ///< idle polls (each with a CPU pause) before sleeping
    bool pin_cpus = false;                ///< pin worker i to CPU i mod cores (failures counted)
    /// An idle worker wakes at least this often to beat its heartbeat (worker_beats()), so
    /// a worker that sleeps is told from one that is stuck.
    std::int64_t idle_beat_us = 100'000;
};

namespace detail {
/// A sample on a worker's input ring (outside WorkerPool: a nested type with member
/// initialisers is not default-constructible until the enclosing class is complete).
struct WorkItem {
    SegmentSample sample{};
    std::uint32_t slot = 0;  ///< index into the worker's processors
};
}  // namespace detail

enum class SubmitResult : std::uint8_t {
    kQueued,          ///< on its worker's input ring
    kDroppedFull,     ///< input ring full: sample dropped (drop-newest), counted
    kUnknownSegment,  ///< (subject, segment) was never added: counted
    kStopped,         ///< pool not running: counted
};

class WorkerPool {
public:
    static constexpr std::size_t kNoWorker = static_cast<std::size_t>(-1);

    /// @param clock optional (may be null, then no dequeued/filtered stamps and no histograms);
    ///        not owned, must outlive the pool.
    /// @throws std::invalid_argument for a ring capacity that is not a power of two >= 2 or a
    ///         zero batch.
    explicit WorkerPool(const WorkerPoolConfig& config, const Clock* clock = nullptr);
    ~WorkerPool();

    WorkerPool(const WorkerPool&) = delete;
    WorkerPool& operator=(const WorkerPool&) = delete;

    /// Set-up only. Registers a segment and its processor (not owned; must outlive the pool's
    /// stop()). cost_weight balances mixed filters (e.g. a particle filter weighs more).
    /// Returns the worker index. @throws std::logic_error after start() or for a duplicate.
    std::size_t add_segment(std::uint32_t subject_id, std::uint16_t segment_index, SegmentProcessor& processor,
                            std::uint32_t cost_weight = 1);

    /// Set-up only: starts the worker threads. @throws std::logic_error if called twice.
    void start();

    /// Ingest thread only. Never blocks or allocates; O(log segments) route lookup.
    /// wake = true wakes the segment's worker if it sleeps. A caller that submits a batch
    /// (all samples of one TCP packet) may pass wake = false and call wake_workers() once
    /// after the batch: one wake-up per worker instead of one per sample.
    SubmitResult submit(const SegmentSample& sample, bool wake = true) noexcept;

    /// Ingest thread only. Wakes every sleeping worker (cheap for awake ones).
    void wake_workers() noexcept;

    /// Any thread: worker `i`'s heartbeat, one per turn of its loop (at least one per
    /// idle_beat_us while it runs); i < worker_count().
    [[nodiscard]] const std::atomic<std::uint64_t>& worker_beats(std::size_t i) const { return workers_.at(i)->beats; }

    /// Assembler thread only. Pops every ready pose (at most max_per_worker per worker) and
    /// calls on_pose(const PoseUpdate&) for each; returns how many. Per segment, poses come
    /// in submission order; across segments there is no order.
    /// Taking a bounded chunk per worker in turn keeps workers' poses interleaved, so the
    /// assembler sees instants complete in step rather than one worker's backlog first.
    template <typename OnPose>
    std::size_t drain(OnPose&& on_pose, std::size_t max_per_worker = 64) {
        std::size_t n = 0;
        for (auto& w : workers_) {
            for (std::size_t i = 0; i < max_per_worker; ++i) {
                const PoseUpdate* u = w->output.front();
                if (u == nullptr) break;
                on_pose(*u);
                w->output.pop();
                ++n;
            }
        }
        return n;
    }

    /// Assembler thread only. Returns at once if a pose is ready or stop() has finished;
    /// otherwise spins briefly, then sleeps until a worker publishes a pose or timeout_us
    /// passes (may return early). Returns true if a pose may be ready (or the pool stopped).
    bool wait_for_output(std::int64_t timeout_us) noexcept;

    /// Control thread, after the ingest thread stopped submitting: drains inputs, joins the
    /// workers. Idempotent.
    void stop();

    [[nodiscard]] std::size_t worker_count() const noexcept { return workers_.size(); }
    /// Worker of a registered segment, or kNoWorker.
    [[nodiscard]] std::size_t worker_of(std::uint32_t subject_id, std::uint16_t segment_index) const noexcept;
    /// Samples waiting on a worker's input ring (approximate while running).
    [[nodiscard]] std::size_t input_depth(std::size_t worker) const noexcept;

    /// Counters (component "worker_pool"): samples_submitted, samples_dropped_full,
    /// samples_unknown_segment, samples_after_stop, samples_processed, samples_rejected,
    /// poses_dropped_full, worker_sleeps, pin_failures.
    [[nodiscard]] const CounterGroup& counters() const noexcept { return counters_; }
    /// Queue wait: received_us -> dequeued_us (samples with received_us != 0), all workers.
    [[nodiscard]] LatencySnapshot queue_wait_snapshot() const noexcept;
    /// Filter: dequeued_us -> filtered_us, all workers.
    [[nodiscard]] LatencySnapshot filter_snapshot() const noexcept;
    /// Set-up: the counters above and stage latencies "queue_wait" and "filter".
    void register_metrics(MetricsRegistry& registry) const;

private:
    using WorkItem = detail::WorkItem;

    struct Route {
        std::uint64_t key = 0;  // subject << 16 | segment
        std::uint32_t worker = 0;
        std::uint32_t slot = 0;
    };

    struct Worker {
        Worker(std::size_t input_capacity, std::size_t output_capacity)
            : input(input_capacity), output(output_capacity) {}
        SpscRing<WorkItem> input;
        SpscRing<PoseUpdate> output;
        EventCount wake;
        std::vector<SegmentProcessor*> processors;  // read-only once started
        std::uint64_t weight = 0;                   // set-up only
        std::thread thread;
        // Written by the worker thread only (single-writer: no locked add per sample).
        alignas(kCacheLineBytes) SingleWriterCounter processed;
        SingleWriterCounter rejected;
        SingleWriterCounter output_dropped;
        SingleWriterCounter sleeps;
        std::atomic<std::uint64_t> beats{0};  ///< one per loop turn (heartbeat), any thread reads
        SingleWriterLatencyHistogram queue_wait;
        SingleWriterLatencyHistogram filter;
        // Written by the ingest thread only (own cache line).
        alignas(kCacheLineBytes) SingleWriterCounter submitted;
        SingleWriterCounter dropped_full;
    };

    static std::uint64_t route_key(std::uint32_t subject_id, std::uint16_t segment) noexcept {
        return (static_cast<std::uint64_t>(subject_id) << 16) | segment;
    }
    [[nodiscard]] const Route* find_route(std::uint64_t key) const noexcept;
    void run_worker(Worker& w);
    void process_one(Worker& w, const WorkItem& item);
    bool spin_until_input(const Worker& w) const noexcept;

    WorkerPoolConfig config_;
    const Clock* clock_;
    std::vector<std::unique_ptr<Worker>> workers_;
    std::vector<Route> routes_;  // sorted by key; read-only once started
    EventCount output_event_;    // workers -> assembler thread
    std::atomic<bool> running_{false};
    std::atomic<bool> stopping_{false};
    std::atomic<bool> joined_flag_{false};  // every worker has exited (end of stop())
    bool started_ = false;                  // set-up/control thread only
    bool joined_ = false;                   // set-up/control thread only

    SingleWriterCounter unknown_segment_;  // ingest thread
    SingleWriterCounter after_stop_;       // ingest thread
    SingleWriterCounter pin_failures_;     // set-up thread
    CounterGroup counters_{"worker_pool"};
};

}  // namespace mocap
