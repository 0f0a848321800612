// pipeline.hpp — the processing chain of mocapd, live and replayed:
//     route (node -> segment) -> filter per (subject, segment) -> assembly per SYNC instant
//     -> skeleton solve (PoseSolver) -> outputs (pipeline/output.hpp)
// The daemon (server/daemon) owns threads, sockets, signals and systemd; replay owns the
// file reading. Both drive this one class, so routing and filter construction exist once.
//
// Two ways to drive it:
//   live         start_workers(); the ingest thread calls route() for every sample (and
//                wake_workers() once per batch); a thread the daemon starts runs
//                run_assembler() until request_assembler_stop(). Filters run on the worker
//                pool (core/worker_pool.hpp), one worker per segment.
//   synchronous  process() for every sample in order, with the caller's clock (replay: the
//                recorded received_us), then flush(). Filters run inline on the caller's
//                thread; a segment's samples are filtered in the same order as live.
// Subjects: the configured ids; every subject has the same body model. Every filter is
// created at construction, so nothing is allocated when a sink appears.
//
// Counters (component "route", written by the routing thread only): samples_routed,
// samples_unknown_node, samples_rejected; one ingest latency histogram (sink_send_us ->
// received_us) per subject, so one sink's clock never moves another subject's figure.
// Only samples that reach a segment of a configured subject count as arriving (latency,
// first/last sample time): samples for nodes outside the body model are counted and passed
// to the sample outputs (the raw recorder), nothing else.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/clock.hpp"
#include "core/counters.hpp"
#include "core/latency_histogram.hpp"
#include "core/metrics_registry.hpp"
#include "core/subject_assembler.hpp"
#include "core/subject_ids.hpp"
#include "core/worker_pool.hpp"
#include "filter/filter_factory.hpp"
#include "pipeline/filter_processor.hpp"
#include "pipeline/output.hpp"
#include "skeleton/body_model.hpp"
#include "skeleton/calibration_store.hpp"
#include "skeleton/pose_solver.hpp"

namespace mocap::pipeline {

struct PipelineConfig {
    skeleton::BodyModel model;              ///< validated (skeleton::validate)
    std::vector<std::uint32_t> subjects;    ///< subject ids, each once (sorted by the pipeline)
    filter::FilterParamList filter_params;  ///< applied to every segment's filter
    std::uint32_t workers = 0;              ///< worker threads (live), 0 = hardware cores
    std::uint32_t ring_capacity = 4096;     ///< worker pool rings (live)
    AssemblerConfig assembler;
    skeleton::PoseSolverOptions solver;  ///< subject_ids is set from `subjects`
    /// Where calibrations are loaded from and saved to (nullptr = nowhere), and where the
    /// solver's log lines go (nullptr = nowhere): injected, the pipeline does no file I/O.
    std::unique_ptr<skeleton::CalibrationStore> calibration_store;
    skeleton::LogFn solver_log;
};

/// What happened to one sample in the synchronous mode.
enum class RouteResult : std::uint8_t {
    kProcessed,    ///< filtered and handed to the assembler
    kUnknownNode,  ///< node not in the model, or subject not configured
    kRejected,     ///< the filter refused it (non-finite input)
};

class Pipeline final {
public:
    /// Builds filters, solver and assemblers. nullptr + *error for a filter that cannot be
    /// made (unknown name or parameter); the message names the segment.
    static std::unique_ptr<Pipeline> create(PipelineConfig config, const Clock& clock, std::string* error);
    ~Pipeline();

    Pipeline(const Pipeline&) = delete;
    Pipeline& operator=(const Pipeline&) = delete;

    /// Set-up: outputs receive frames in the order they were added.
    void add_output(std::unique_ptr<Output> output);
    /// Set-up: starts every output in order; false + *error on the first failure.
    bool start_outputs(std::string* error);
    /// After the assembler stopped: stops every output; false + *error of the first failure
    /// (every output is stopped regardless).
    bool stop_outputs(std::string* error);

    // --- live ---
    /// Starts the worker threads (after every output started).
    void start_workers();
    /// Ingest thread only. Feeds the sample-outputs, then routes it to its segment's worker
    /// without waking it. True when the sample was queued: the caller calls wake_workers()
    /// once after the batch (one wake-up per worker, not one per sample).
    bool route(const SegmentSample& in);
    /// Ingest thread only.
    void wake_workers() { pool_->wake_workers(); }
    /// The assembler thread: drains the workers, assembles, solves and publishes until
    /// request_assembler_stop(); then emits what the workers still had and every open
    /// instant. on_pass runs after every turn of the loop (at least every 50 ms): the
    /// daemon's watchdog ping.
    void run_assembler(const std::function<void()>& on_pass);
    /// Any thread. Call after stop_workers() so the final drain sees every pose.
    void request_assembler_stop() { assembler_stop_.store(true, std::memory_order_release); }
    /// After ingest stopped: the workers finish what is queued and exit.
    void stop_workers() { pool_->stop(); }

    // --- synchronous ---
    /// Routes, filters and assembles one sample at now_us (the caller's clock, never
    /// decreasing). Outputs receive frames from inside this call.
    RouteResult process(const SegmentSample& in, std::int64_t now_us);
    /// Emits every open instant.
    void flush(std::int64_t now_us) { assemblers_->flush(now_us); }

    // --- set-up results and stats (any thread) ---
    [[nodiscard]] const skeleton::BodyModel& model() const { return config_.model; }
    [[nodiscard]] const std::vector<std::uint32_t>& subjects() const { return config_.subjects; }
    /// -1 = the node is not in the model. The one node -> segment table of live and replay.
    [[nodiscard]] int segment_of(std::uint32_t node_id) const {
        return node_id < node_to_segment_.size() ? node_to_segment_[node_id] : -1;
    }
    [[nodiscard]] skeleton::PoseSolver& solver() { return *solver_; }
    [[nodiscard]] const skeleton::PoseSolver& solver() const { return *solver_; }
    [[nodiscard]] const WorkerPool& pool() const { return *pool_; }
    [[nodiscard]] const AssemblerSet& assemblers() const { return *assemblers_; }
    [[nodiscard]] const CounterGroup& route_counters() const { return route_counters_; }
    /// Ingest latency of every subject, merged.
    [[nodiscard]] LatencySnapshot ingest_latency() const;
    /// Ingest latency of one subject's samples only (empty for an id not configured).
    [[nodiscard]] LatencySnapshot ingest_latency(std::uint32_t subject_id) const;
    [[nodiscard]] const std::vector<std::unique_ptr<Output>>& outputs() const { return outputs_; }
    /// Set-up, after the outputs were added: the route counters and the ingest latency (with
    /// counter latency.ingest_negative), the worker pool's, the assemblers', the solver's and its store's
    /// metrics, and every output's.
    void register_metrics(MetricsRegistry& registry) const;
    /// Wall clock µs of the first and the latest sample routed to a segment of a configured
    /// subject (0 = none yet). /healthz reads them as "samples arrive": samples for nodes the
    /// body model does not have must not count, or they made a daemon without frames unhealthy.
    [[nodiscard]] std::int64_t first_sample_us() const { return first_sample_us_.load(std::memory_order_relaxed); }
    [[nodiscard]] std::int64_t last_sample_us() const { return last_sample_us_.load(std::memory_order_relaxed); }
    /// Clock µs of the assembler loop's last turn (start time before it runs).
    [[nodiscard]] std::int64_t assembler_alive_us() const {
        return assembler_alive_us_.load(std::memory_order_relaxed);
    }

private:
    Pipeline(PipelineConfig config, const Clock& clock);
    bool build(std::string* error);
    void note_sample(const SegmentSample& in);
    void note_routed(const SegmentSample& in, std::size_t subject_index);
    /// Index into config_.subjects, -1 = not configured.
    [[nodiscard]] int subject_index_of(std::uint32_t subject_id) const {
        return subject_position(config_.subjects, subject_id);
    }
    void publish(const SubjectFrame& frame, const skeleton::SkeletonPose& pose);

    PipelineConfig config_;
    const Clock& clock_;
    // Node ids are one byte on the wire: 256 entries cover every node.
    std::array<std::int16_t, 256> node_to_segment_{};

    std::vector<std::unique_ptr<FilterProcessor>> processors_;  // subject-major, segment-minor
    std::unique_ptr<WorkerPool> pool_;
    std::unique_ptr<skeleton::PoseSolver> solver_;
    std::unique_ptr<AssemblerSet> assemblers_;
    std::vector<std::unique_ptr<Output>> outputs_;
    std::vector<Output*> sample_outputs_;  // wants_samples(), fixed before samples flow

    std::atomic<bool> assembler_stop_{false};
    std::atomic<std::int64_t> assembler_alive_us_{0};
    std::atomic<std::int64_t> first_sample_us_{0};  // routing thread
    std::atomic<std::int64_t> last_sample_us_{0};   // routing thread

    // Written by the routing thread only.
    // sink_send_us -> received_us, one per subject (index as config_.subjects), made at build.
    std::vector<std::unique_ptr<SingleWriterLatencyHistogram>> ingest_latency_;
    SingleWriterCounter unknown_nodes_, samples_routed_, samples_rejected_;
    CounterGroup route_counters_{"route"};
};

}  // namespace mocap::pipeline
