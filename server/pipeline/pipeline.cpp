#include "pipeline/pipeline.hpp"

#include <algorithm>
#include <chrono>

#include "core/saturating.hpp"

namespace mocap::pipeline {

std::unique_ptr<Pipeline> Pipeline::create(PipelineConfig config, const Clock& clock, std::string* error) {
    std::unique_ptr<Pipeline> p(new Pipeline(std::move(config), clock));
    if (!p->build(error)) return nullptr;
    return p;
}

Pipeline::Pipeline(PipelineConfig config, const Clock& clock) : config_(std::move(config)), clock_(clock) {
    route_counters_.add("samples_routed", samples_routed_);
    route_counters_.add("samples_unknown_node", unknown_nodes_);
    route_counters_.add("samples_rejected", samples_rejected_);
}

Pipeline::~Pipeline() {
    if (pool_) pool_->stop();
}

bool Pipeline::build(std::string* error) {
    const auto& model = config_.model;
    node_to_segment_.fill(-1);
    // Ascending, so a subject's index is found by search (core/subject_ids.hpp): ids are
    // sparse 32-bit numbers (subject_id_base + sink id), too wide for a table indexed by id.
    std::sort(config_.subjects.begin(), config_.subjects.end());
    for (std::size_t i = 0; i < config_.subjects.size(); ++i)
        ingest_latency_.push_back(std::make_unique<SingleWriterLatencyHistogram>());
    for (std::size_t i = 0; i < model.size(); ++i) {
        const int node = model.segments[i].node_id;
        if (node >= 0 && node < static_cast<int>(node_to_segment_.size())) {
            node_to_segment_[static_cast<std::size_t>(node)] = static_cast<std::int16_t>(i);
        }
    }

    // Filters: one per segment per subject, built before any thread starts.
    WorkerPoolConfig pc;
    pc.workers = config_.workers;
    pc.input_capacity = config_.ring_capacity;
    pc.output_capacity = config_.ring_capacity;
    pool_ = std::make_unique<WorkerPool>(pc, &clock_);
    for (std::uint32_t id : config_.subjects) {
        for (std::size_t i = 0; i < model.size(); ++i) {
            const auto& seg = model.segments[i];
            auto f = filter::make_filter(seg.filter, config_.filter_params, error);
            if (!f) {
                *error = "filter for segment " + seg.name + ": " + *error;
                return false;
            }
            // Weighed so the pool balances work, not segment counts.
            const std::uint32_t weight = filter::filter_cost_weight(seg.filter);
            processors_.push_back(std::make_unique<FilterProcessor>(std::move(f)));
            pool_->add_segment(id, static_cast<std::uint16_t>(i), *processors_.back(), weight);
        }
    }

    skeleton::PoseSolverOptions so = config_.solver;
    so.subject_ids = config_.subjects;
    so.max_subjects = 0;  // exactly the configured subjects, even none
    solver_ = std::make_unique<skeleton::PoseSolver>(
        model, so, [this](const SubjectFrame& f, const skeleton::SkeletonPose& p) { publish(f, p); },
        std::move(config_.calibration_store), config_.solver_log);
    assemblers_ = std::make_unique<AssemblerSet>(config_.assembler, *solver_);
    for (std::uint32_t id : config_.subjects)
        assemblers_->add_subject(id, static_cast<std::uint16_t>(model.size()));
    assembler_alive_us_ = clock_.now_us();
    return true;
}

void Pipeline::add_output(std::unique_ptr<Output> output) {
    if (output->wants_samples()) sample_outputs_.push_back(output.get());
    outputs_.push_back(std::move(output));
}

void Pipeline::register_metrics(MetricsRegistry& registry) const {
    registry.add(route_counters_);
    // A sink clock ahead of the host gives negative latencies: not in the histogram, counted.
    registry.add_latency("ingest", [this] { return ingest_latency(); }, {.negative_counter = true});
    pool_->register_metrics(registry);
    assemblers_->register_metrics(registry);
    registry.add(solver_->counters());
    if (const auto* store = solver_->store()) store->register_metrics(registry);
    for (const auto& o : outputs_)
        o->register_metrics(registry);
}

bool Pipeline::start_outputs(std::string* error) {
    for (auto& o : outputs_) {
        if (!o->start(error)) return false;
    }
    return true;
}

bool Pipeline::stop_outputs(std::string* error) {
    bool ok = true;
    for (auto& o : outputs_) {
        std::string err;
        if (!o->stop(&err) && ok) {
            ok = false;
            *error = std::move(err);
        }
    }
    return ok;
}

void Pipeline::publish(const SubjectFrame& frame, const skeleton::SkeletonPose& pose) {
    for (auto& o : outputs_)
        o->on_frame(frame, pose);
}

void Pipeline::note_sample(const SegmentSample& in) {
    for (Output* o : sample_outputs_)
        o->on_sample(in);  // every node, before the model filters it
}

void Pipeline::note_routed(const SegmentSample& in, std::size_t subject_index) {
    // Saturated: the stamps are the sink's word (ingest keeps implausible ones out, replay
    // reads them from a file).
    if (in.times.sink_send_us != 0) {
        ingest_latency_[subject_index]->record(saturating_sub(in.times.received_us, in.times.sink_send_us));
    }
    if (first_sample_us_.load(std::memory_order_relaxed) == 0) first_sample_us_.store(in.times.received_us);
    last_sample_us_.store(in.times.received_us, std::memory_order_relaxed);
}

LatencySnapshot Pipeline::ingest_latency() const {
    LatencySnapshot all;
    for (const auto& h : ingest_latency_)
        all.merge(h->snapshot());
    return all;
}

LatencySnapshot Pipeline::ingest_latency(std::uint32_t subject_id) const {
    const int i = subject_index_of(subject_id);
    return i < 0 ? LatencySnapshot{} : ingest_latency_[static_cast<std::size_t>(i)]->snapshot();
}

void Pipeline::start_workers() {
    assembler_alive_us_ = clock_.now_us();
    pool_->start();
}

bool Pipeline::route(const SegmentSample& in) {
    note_sample(in);
    const int seg = segment_of(in.node_id);
    if (seg < 0) {
        unknown_nodes_.add();
        return false;
    }
    // A sample for a configured subject's segment arrives even when its ring is full: the
    // subject is served and owes frames.
    if (const int subject = subject_index_of(in.subject_id); subject >= 0) {
        note_routed(in, static_cast<std::size_t>(subject));
    }
    SegmentSample s = in;
    s.segment_index = static_cast<std::uint16_t>(seg);
    if (pool_->submit(s, /*wake=*/false) == SubmitResult::kQueued) {
        samples_routed_.add();
        return true;
    }
    samples_rejected_.add();
    return false;
}

void Pipeline::run_assembler(const std::function<void()>& on_pass) {
    const auto on_pose = [this](const PoseUpdate& u) { assemblers_->on_pose(u, clock_.now_us()); };
    while (!assembler_stop_.load(std::memory_order_acquire)) {
        const std::int64_t now = clock_.now_us();
        const std::int64_t next = assemblers_->next_deadline_us();
        const std::int64_t wait = next == kNoDeadline ? 50'000 : std::clamp<std::int64_t>(next - now, 0, 50'000);
        pool_->wait_for_output(wait);
        pool_->drain(on_pose);
        assemblers_->advance(clock_.now_us());
        assembler_alive_us_.store(clock_.now_us(), std::memory_order_relaxed);
        if (on_pass) on_pass();
    }
    // Drain what the workers still produce, then emit every open instant.
    pool_->drain(on_pose, SIZE_MAX);
    assemblers_->flush(clock_.now_us());
}

RouteResult Pipeline::process(const SegmentSample& in, std::int64_t now_us) {
    note_sample(in);
    const int seg = segment_of(in.node_id);
    const int subject = subject_index_of(in.subject_id);
    if (seg < 0 || subject < 0) {
        unknown_nodes_.add();
        return RouteResult::kUnknownNode;
    }
    const auto subject_index = static_cast<std::size_t>(subject);
    note_routed(in, subject_index);
    FilterProcessor& filter = *processors_[subject_index * config_.model.size() + static_cast<std::size_t>(seg)];
    PoseUpdate u;
    u.subject_id = in.subject_id;
    u.segment_index = static_cast<std::uint16_t>(seg);
    u.sync = in.sync;
    u.pose.sample_us = in.imu.t_us;
    u.pose.flags = 0;
    u.times = in.times;
    u.times.dequeued_us = now_us;
    u.times.filtered_us = now_us;
    SegmentSample s = in;
    s.segment_index = u.segment_index;
    assemblers_->advance(now_us);
    if (!filter.process(s, u.pose)) {
        samples_rejected_.add();
        return RouteResult::kRejected;
    }
    samples_routed_.add();
    assemblers_->on_pose(u, now_us);
    return RouteResult::kProcessed;
}

}  // namespace mocap::pipeline
