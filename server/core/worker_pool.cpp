// worker_pool.cpp — the worker loop and the routing behind WorkerPool. Why it looks like
// this: see the header (pinned segments, drop-newest, spin-then-futex).
#include "core/worker_pool.hpp"

#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <stdexcept>

namespace mocap {
namespace {

inline void cpu_relax() noexcept {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    asm volatile("yield" ::: "memory");
#endif
}

std::size_t resolve_workers(std::size_t requested) {
    if (requested != 0) return requested;
    const unsigned cores = std::thread::hardware_concurrency();
    return cores == 0 ? 1 : cores;
}

}  // namespace

WorkerPool::WorkerPool(const WorkerPoolConfig& config, const Clock* clock) : config_(config), clock_(clock) {
    if (config_.batch == 0) throw std::invalid_argument("WorkerPool batch must be >= 1");
    const std::size_t n = resolve_workers(config_.workers);
    config_.workers = n;
    workers_.reserve(n);
    for (std::size_t i = 0; i < n; ++i) {
        workers_.push_back(std::make_unique<Worker>(config_.input_capacity, config_.output_capacity));
    }
    for (const auto& w : workers_) {
        counters_.add("samples_submitted", w->submitted);
        counters_.add("samples_dropped_full", w->dropped_full);
    }
    counters_.add("samples_unknown_segment", unknown_segment_);
    counters_.add("samples_after_stop", after_stop_);
    for (const auto& w : workers_) {
        counters_.add("samples_processed", w->processed);
        counters_.add("samples_rejected", w->rejected);
        counters_.add("poses_dropped_full", w->output_dropped);
        counters_.add("worker_sleeps", w->sleeps);
    }
    counters_.add("pin_failures", pin_failures_);
}

WorkerPool::~WorkerPool() {
    stop();
}

std::size_t WorkerPool::add_segment(std::uint32_t subject_id, std::uint16_t segment_index, SegmentProcessor& processor,
                                    std::uint32_t cost_weight) {
    if (started_) throw std::logic_error("WorkerPool::add_segment after start()");
    const std::uint64_t key = route_key(subject_id, segment_index);
    auto pos = std::lower_bound(routes_.begin(), routes_.end(), key,
                                [](const Route& r, std::uint64_t k) { return r.key < k; });
    if (pos != routes_.end() && pos->key == key) {
        throw std::logic_error("WorkerPool::add_segment: segment added twice");
    }
    // Least total weight wins; min_element keeps the lowest index on ties (round-robin).
    auto lightest = std::min_element(workers_.begin(), workers_.end(),
                                     [](const auto& a, const auto& b) { return a->weight < b->weight; });
    Worker& w = **lightest;
    const auto worker_index = static_cast<std::uint32_t>(lightest - workers_.begin());
    w.weight += cost_weight;
    w.processors.push_back(&processor);
    routes_.insert(pos, Route{key, worker_index, static_cast<std::uint32_t>(w.processors.size() - 1)});
    return worker_index;
}

void WorkerPool::start() {
    if (started_) throw std::logic_error("WorkerPool::start called twice");
    started_ = true;
    running_.store(true, std::memory_order_release);
    const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
    for (std::size_t i = 0; i < workers_.size(); ++i) {
        Worker& w = *workers_[i];
        w.thread = std::thread([this, &w, i] {
            const std::string name = "mocap-worker-" + std::to_string(i);
            pthread_setname_np(pthread_self(), name.substr(0, 15).c_str());
            run_worker(w);
        });
        if (config_.pin_cpus) {
            cpu_set_t set;
            CPU_ZERO(&set);
            CPU_SET(static_cast<int>(i % cores), &set);
            if (pthread_setaffinity_np(w.thread.native_handle(), sizeof(set), &set) != 0) {
                pin_failures_.add();
            }
        }
    }
}

const WorkerPool::Route* WorkerPool::find_route(std::uint64_t key) const noexcept {
    auto pos = std::lower_bound(routes_.begin(), routes_.end(), key,
                                [](const Route& r, std::uint64_t k) { return r.key < k; });
    return (pos != routes_.end() && pos->key == key) ? &*pos : nullptr;
}

SubmitResult WorkerPool::submit(const SegmentSample& sample, bool wake) noexcept {
    if (!running_.load(std::memory_order_acquire)) {
        after_stop_.add();
        return SubmitResult::kStopped;
    }
    const Route* route = find_route(route_key(sample.subject_id, sample.segment_index));
    if (route == nullptr) {
        unknown_segment_.add();
        return SubmitResult::kUnknownSegment;
    }
    Worker& w = *workers_[route->worker];
    if (!w.input.try_push(WorkItem{sample, route->slot})) {
        w.dropped_full.add();
        return SubmitResult::kDroppedFull;
    }
    w.submitted.add();
    if (wake) w.wake.notify_all();
    return SubmitResult::kQueued;
}

void WorkerPool::wake_workers() noexcept {
    for (auto& w : workers_)
        w->wake.notify_all();
}

bool WorkerPool::spin_until_input(const Worker& w) const noexcept {
    for (std::uint32_t i = 0; i < config_.spin_iterations; ++i) {
        if (w.input.size_approx() != 0) return true;
        if (stopping_.load(std::memory_order_relaxed)) return false;  // stop() waits on us
        cpu_relax();
    }
    return false;
}

void WorkerPool::process_one(Worker& w, const WorkItem& item) {
    const SegmentSample& s = item.sample;
    PoseUpdate u;
    u.subject_id = s.subject_id;
    u.segment_index = s.segment_index;
    u.sync = s.sync;
    u.times = s.times;
    u.pose.sample_us = s.imu.t_us;
    u.pose.flags = 0;
    if (clock_ != nullptr) u.times.dequeued_us = clock_->now_us();
    const bool ok = w.processors[item.slot]->process(s, u.pose);
    w.processed.add();
    if (!ok) {
        w.rejected.add();
        return;
    }
    if (clock_ != nullptr) {
        u.times.filtered_us = clock_->now_us();
        if (s.times.received_us != 0) w.queue_wait.record(u.times.dequeued_us - s.times.received_us);
        w.filter.record(u.times.filtered_us - u.times.dequeued_us);
    }
    if (!w.output.try_push(u)) w.output_dropped.add();
}

void WorkerPool::run_worker(Worker& w) {
    for (;;) {
        w.beats.fetch_add(1, std::memory_order_relaxed);
        std::size_t done = 0;
        while (done < config_.batch) {
            const WorkItem* item = w.input.front();
            if (item == nullptr) break;
            process_one(w, *item);
            w.input.pop();
            ++done;
        }
        if (done != 0) {
            output_event_.notify_all();
            continue;
        }
        if (spin_until_input(w)) continue;
        // Stop only with an empty input ring: everything submitted before stop() is processed.
        if (stopping_.load(std::memory_order_acquire)) {
            if (w.input.empty()) break;
            continue;
        }
        const EventCount::Key key = w.wake.prepare_wait();
        if (!w.input.empty() || stopping_.load(std::memory_order_acquire)) {
            w.wake.cancel_wait();
            continue;
        }
        w.sleeps.add();
        w.wake.wait_for(key, config_.idle_beat_us);
    }
}

bool WorkerPool::wait_for_output(std::int64_t timeout_us) noexcept {
    auto ready = [this] {
        for (const auto& w : workers_) {
            if (w->output.size_approx() != 0) return true;
        }
        return false;
    };
    // Not `stopping_`: while stop() drains the inputs the workers still produce poses, and
    // the assembler thread should sleep until they do rather than spin.
    if (ready() || joined_flag_.load(std::memory_order_acquire)) return true;
    for (std::uint32_t i = 0; i < config_.spin_iterations; ++i) {
        if (ready()) return true;
        cpu_relax();
    }
    const EventCount::Key key = output_event_.prepare_wait();
    if (ready() || joined_flag_.load(std::memory_order_acquire)) {
        output_event_.cancel_wait();
        return true;
    }
    output_event_.wait_for(key, timeout_us);
    return ready();
}

void WorkerPool::stop() {
    if (!started_ || joined_) return;
    running_.store(false, std::memory_order_release);
    stopping_.store(true, std::memory_order_seq_cst);
    for (auto& w : workers_)
        w->wake.notify_all();
    for (auto& w : workers_) {
        if (w->thread.joinable()) w->thread.join();
    }
    joined_ = true;
    joined_flag_.store(true, std::memory_order_seq_cst);
    output_event_.notify_all();
}

std::size_t WorkerPool::worker_of(std::uint32_t subject_id, std::uint16_t segment_index) const noexcept {
    const Route* route = find_route(route_key(subject_id, segment_index));
    return route == nullptr ? kNoWorker : route->worker;
}

std::size_t WorkerPool::input_depth(std::size_t worker) const noexcept {
    return worker < workers_.size() ? workers_[worker]->input.size_approx() : 0;
}

void WorkerPool::register_metrics(MetricsRegistry& registry) const {
    registry.add(counters_);
    registry.add_latency("queue_wait", [this] { return queue_wait_snapshot(); });
    registry.add_latency("filter", [this] { return filter_snapshot(); });
}

LatencySnapshot WorkerPool::queue_wait_snapshot() const noexcept {
    LatencySnapshot total;
    for (const auto& w : workers_)
        total.merge(w->queue_wait.snapshot());
    return total;
}

LatencySnapshot WorkerPool::filter_snapshot() const noexcept {
    LatencySnapshot total;
    for (const auto& w : workers_)
        total.merge(w->filter.snapshot());
    return total;
}

}  // namespace mocap
