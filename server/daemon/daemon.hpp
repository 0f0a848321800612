// daemon.hpp — mocapd's process: threads, signals, sd_notify, reload, the stats timer and the
// control handlers. The processing chain is the Pipeline (pipeline/pipeline.hpp); its outputs
// come from the registry in daemon/outputs.hpp.
//
// Threads:
//   main      run(): signals (SIGTERM/SIGINT stop, SIGHUP reload), periodic stats log
//   ingest    one io_context: sink TCP listener + SocketCAN readers (or, with --play, the
//             take player) -> Pipeline::route -> worker pool (the pool's single producer)
//   workers   WorkerPool: one FilterProcessor per (subject, segment), pinned to a worker
//   assembler Pipeline::run_assembler: drains the pool, joins segments per SYNC instant,
//             solves the skeleton and publishes to the outputs; pings the watchdog unless
//             a thread's heartbeat stopped (heartbeat_monitor.hpp)
//   serve     the network outputs' own threads (client sessions)
// Subjects: subject id = ingest.subject_id_base + sink id (1..pipeline.max_subjects) or the id configured for a
// SocketCAN interface. Every subject has the same body model; filters for all subjects are
// created at start so nothing is allocated when a sink appears.
#pragma once

#include <atomic>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "core/asio.hpp"
#include "daemon/config.hpp"
#include "daemon/heartbeat_monitor.hpp"
#include "daemon/outputs.hpp"
#include "daemon/pipeline_config.hpp"
#include "daemon/take_player.hpp"
#include "daemon/wall_clock.hpp"
#include "ingest/sink_listener.hpp"
#include "ingest/socketcan_reader.hpp"
#include "pipeline/pipeline.hpp"
#include "serve/http_server.hpp"

namespace mocap::daemon {

class Daemon {
public:
    /// config_path: where SIGHUP re-reads the config ("" = embedded default, nothing to reload).
    Daemon(DaemonConfig config, std::string config_path);
    ~Daemon();

    /// Before start(): serve a recorded take (take_player.hpp) instead of opening the sink
    /// listener and the SocketCAN readers.
    void play(PlayOptions options) { play_ = std::move(options); }

    /// Creates every component and binds every socket. Returns false with a message on the
    /// first failure (bad filter name, port in use, missing CAN interface...).
    bool start(std::string* error);

    /// Blocks until SIGTERM/SIGINT (or request_stop()), then drains and stops everything.
    void run();

    /// Any thread: makes run() return after draining.
    void request_stop();

    // For tests and the stats reply.
    [[nodiscard]] std::uint16_t sink_port() const { return sink_listener_ ? sink_listener_->port() : 0; }
    [[nodiscard]] std::uint16_t pose_port() const { return output_port("pose"); }
    [[nodiscard]] std::uint16_t bvh_port() const { return output_port("bvh_live"); }
    [[nodiscard]] std::uint16_t http_port() const { return output_port("http"); }
    /// Any thread, after start(): every metric, as the Stats reply, /metrics and the log line
    /// show them.
    [[nodiscard]] MetricsSnapshot metrics() const { return metrics_.snapshot(); }
    /// Any thread: what /healthz shows.
    [[nodiscard]] serve::HealthStatus health() const;

private:
    [[nodiscard]] std::uint16_t output_port(std::string_view name) const;
    [[nodiscard]] serve::ControlHandlers control_handlers();
    void route(const SegmentSample& in);
    void reload();
    void log_stats();
    void arm_stats_timer();
    /// A thread whose heartbeat did not move for this long is stale (/healthz, watchdog):
    /// eight beats of the slowest (250 ms).
    static constexpr std::int64_t kHeartbeatWindowUs = 2'000'000;
    void beat_ingest();
    /// Steady-clock µs: the heartbeats' time base.
    static std::int64_t steady_us();
    void shutdown();

    DaemonConfig config_;
    std::string config_path_;
    WallClock clock_;

    std::unique_ptr<pipeline::Pipeline> pipeline_;
    // Set once in start(): the output the control handlers reach by type.
    BvhRecorderOutput* bvh_recorder_ = nullptr;
    TakeRecorderOutput* take_recorder_ = nullptr;
    // Filled in start() before any reader runs; read-only afterwards (core/metrics_registry.hpp).
    MetricsRegistry metrics_;

    asio::io_context ingest_io_;
    asio::steady_timer ingest_beat_timer_{ingest_io_};  // ingest thread
    std::atomic<std::uint64_t> ingest_beats_{0};        // heartbeat of the ingest thread
    /// Every thread that must make progress (heartbeat_monitor.hpp): filled in start().
    mutable HeartbeatMonitor heartbeats_;
    std::unique_ptr<ingest::SinkListener> sink_listener_;
    std::vector<std::unique_ptr<ingest::SocketCanReader>> can_readers_;
    PlayOptions play_;
    std::unique_ptr<TakePlayer> player_;  // instead of the sink listener and CAN readers
    std::thread ingest_thread_;
    std::thread assembler_thread_;

    asio::io_context main_io_;
    asio::signal_set signals_{main_io_};
    asio::steady_timer stats_timer_{main_io_};

    std::atomic<bool> stopping_{false};
    bool shut_down_ = false;  // main thread: shutdown() ran
    std::uint64_t watchdog_usec_ = 0;

    bool wake_posted_ = false;  // ingest thread: a wake_workers() is posted to ingest_io_ (see route())
};

}  // namespace mocap::daemon
