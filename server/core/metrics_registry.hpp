// metrics_registry.hpp — the one list of every named metric mocapd publishes: counters,
// gauges and stage latency histograms. Components register their metrics once, at set-up;
// the Stats reply (serve/stats_reply.hpp), GET /metrics (serve/prometheus_text.hpp) and the
// periodic log line (core/metrics_log.hpp) are renderers of one snapshot() of it, so a metric
// added here appears in all three with no name typed twice (docs/performance.md, "Metrics
// registry").
//
// Contract
// - Set-up: add()/add_gauge()/add_latency() from one thread, before any reader runs.
//   Afterwards the registry is read-only and snapshot() may be called from any thread,
//   concurrently. Registration holds pointers to the components' counters and histograms
//   and their gauge readers, so the registry must not outlive them.
// - Recording costs nothing new: components keep incrementing their own counters
//   (core/counters.hpp: Counter, SingleWriterCounter, with their threading rules) and
//   histograms; the registry only reads them (relaxed loads), on the stats path.
// - Names: a counter is "component.name" (CounterGroup's component and entry name); a gauge
//   is one token ("pose_clients"); a latency is a stage label ("ingest"). Renderers derive
//   their own spelling from these (e.g. Prometheus `mocapd_component_name_total`).
// - snapshot() allocates and calls the gauge and latency readers: stats path only.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "core/counters.hpp"
#include "core/latency_histogram.hpp"

namespace mocap {

struct GaugeValue {
    std::string name;  ///< one token, e.g. "pose_clients"
    std::string help;  ///< one line for humans (Prometheus # HELP)
    double value = 0;
    std::string log_key = {};  ///< key in the periodic log line; empty = not logged
};

struct LatencyValue {
    std::string stage;  ///< e.g. "ingest", "filter", "assembly"
    LatencySnapshot snapshot;
};

/// Every metric's value at one moment (each read relaxed: not atomic across metrics).
struct MetricsSnapshot {
    std::vector<CounterValue> counters;  ///< "component.name", in registration order; only go up
    std::vector<GaugeValue> gauges;
    std::vector<LatencyValue> latencies;
};

class MetricsRegistry {
public:
    MetricsRegistry() = default;
    MetricsRegistry(const MetricsRegistry&) = delete;
    MetricsRegistry& operator=(const MetricsRegistry&) = delete;

    /// Set-up only. Every entry of `group` as counter "component.name".
    void add(const CounterGroup& group);

    /// Set-up only. A value that goes up and down, read on every snapshot (any thread, must
    /// be cheap and safe to call concurrently). `log_key` non-empty puts it in the log line.
    void add_gauge(std::string name, std::string help, std::function<double()> read, std::string log_key = {});

    struct LatencyOptions {
        /// Also publish the values below zero as counter "latency.<stage>_negative": for a
        /// stage timed across two clocks (a sender's and the host's), where a clock ahead of
        /// the host's gives negative latencies that the histogram does not bucket.
        bool negative_counter = false;
    };
    /// Set-up only. A stage latency read by `read` (any thread; e.g. merged per-worker
    /// histograms).
    void add_latency(std::string stage, std::function<LatencySnapshot()> read, LatencyOptions options);
    void add_latency(std::string stage, std::function<LatencySnapshot()> read) {
        add_latency(std::move(stage), std::move(read), LatencyOptions{});
    }

    /// Any thread (after set-up). Counters in registration order, then the negative-latency
    /// counters; gauges and latencies in registration order.
    [[nodiscard]] MetricsSnapshot snapshot() const;

private:
    struct Gauge {
        std::string name, help, log_key;
        std::function<double()> read;
    };
    struct Latency {
        std::string stage;
        std::function<LatencySnapshot()> read;
        LatencyOptions options;
    };
    std::vector<const CounterGroup*> groups_;
    std::vector<Gauge> gauges_;
    std::vector<Latency> latencies_;
};

}  // namespace mocap
