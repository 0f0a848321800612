// daemon_stats.cpp — what the daemon reports beyond the metrics registry (the Stats reply
// and /metrics render metrics() directly): /healthz and the periodic log line.
#include <spdlog/spdlog.h>

#include "core/metrics_log.hpp"
#include "daemon/daemon.hpp"

namespace mocap::daemon {

// Alive: the assembler loop turns (it wakes at least every 50 ms), the ingest thread's
// io_context runs, every thread that must make progress beats (heartbeat_monitor.hpp), and
// samples that arrive turn into frames within 2 s.
serve::HealthStatus Daemon::health() const {
    constexpr std::int64_t kWindowUs = 2'000'000;
    const std::int64_t now = clock_.now_us();
    if (stopping_.load()) return {false, "stopping"};
    if (now - pipeline_->assembler_alive_us() > kWindowUs) return {false, "assembler thread stalled"};
    if (ingest_io_.stopped()) return {false, "ingest thread stopped"};
    if (const std::string stale = heartbeats_.stale(steady_us(), kHeartbeatWindowUs); !stale.empty())
        return {false, stale + " made no progress for 2 s"};
    const std::int64_t last_sample = pipeline_->last_sample_us();
    if (last_sample == 0) return {true, "no sink data yet"};
    std::int64_t last_frame = pipeline_->first_sample_us();
    for (const auto& o : pipeline_->outputs())
        last_frame = std::max(last_frame, o->last_frame_us());
    if (now - last_sample <= kWindowUs && now - last_frame > kWindowUs)
        return {false, "samples arrive but no frame was assembled for 2 s"};
    return {true, "ok"};
}

void Daemon::log_stats() {
    spdlog::info("stats:{}", render_log_line(metrics()));
}

}  // namespace mocap::daemon
