// daemon.hpp — mocapd's wiring: every component, its threads, signals and systemd.
//
// Threads:
//   main      run(): signals (SIGTERM/SIGINT stop, SIGHUP reload), periodic stats log
//   ingest    one io_context: sink TCP listener + SocketCAN readers -> route -> worker pool
//             (the pool's single producer)
//   workers   WorkerPool: one FilterProcessor per (subject, segment), pinned to a worker
//   assembler drains the pool, joins segments per SYNC instant (SubjectAssembler), solves the
//             skeleton (PoseSolver) and publishes to the pose service; pings the watchdog
//   serve     PoseServer's own threads (client sessions)
// Subjects: subject id = sink id (1..pipeline.max_subjects) or the id configured for a
// SocketCAN interface. Every subject has the same body model; filters for all subjects are
// created at start so nothing is allocated when a sink appears.
#pragma once

#include <atomic>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "core/asio.hpp"
#include "core/latency_histogram.hpp"
#include "core/subject_assembler.hpp"
#include "core/worker_pool.hpp"
#include "daemon/config.hpp"
#include "daemon/filter_processor.hpp"
#include "daemon/pose_solver.hpp"
#include "daemon/wall_clock.hpp"
#include "ingest/sink_listener.hpp"
#include "ingest/socketcan_reader.hpp"
#include "serve/pose_server.hpp"
// Outputs (docs/outputs.md): live BVH, BVH file recorder, raw recorder.
#include "serve/bvh_frame_encoder.hpp"
#include "serve/bvh_recorder.hpp"
#include "serve/bvh_server.hpp"
#include "serve/raw_recorder.hpp"
// Web endpoint (docs/viewer.md): viewer + WebSocket poses, /metrics, /healthz.
#include "serve/http_server.hpp"
#include "skeleton/body_model.hpp"

namespace mocap::daemon {

/// Builds the body model from the config (the built-in body when no segment is listed).
/// Returns std::nullopt and sets *error if the model is invalid.
std::optional<skeleton::BodyModel> body_model_from_config(const DaemonConfig& config, std::string* error);

class Daemon {
public:
    /// config_path: where SIGHUP re-reads the config ("" = embedded default, nothing to reload).
    Daemon(DaemonConfig config, std::string config_path);
    ~Daemon();

    /// Creates every component and binds every socket. Returns false with a message on the
    /// first failure (bad filter name, port in use, missing CAN interface...).
    bool start(std::string* error);

    /// Blocks until SIGTERM/SIGINT (or request_stop()), then drains and stops everything.
    void run();

    /// Any thread: makes run() return after draining.
    void request_stop();

    // For tests and the stats reply.
    [[nodiscard]] std::uint16_t sink_port() const { return sink_listener_ ? sink_listener_->port() : 0; }
    [[nodiscard]] std::uint16_t pose_port() const { return server_ ? server_->port() : 0; }
    [[nodiscard]] std::uint16_t bvh_port() const { return bvh_server_ ? bvh_server_->port() : 0; }
    [[nodiscard]] serve::StatsSnapshot stats() const;
    // Web endpoint: what /metrics and /healthz show (any thread).
    [[nodiscard]] std::uint16_t http_port() const { return http_server_ ? http_server_->port() : 0; }
    [[nodiscard]] serve::MetricsSnapshot metrics() const;
    [[nodiscard]] serve::HealthStatus health() const;

private:
    void route(const SegmentSample& in);
    void assembler_loop();
    void reload();
    void log_stats();
    void arm_stats_timer();
    void shutdown();

    DaemonConfig config_;
    std::string config_path_;
    WallClock clock_;
    skeleton::BodyModel model_;
    std::array<std::int16_t, 64> node_to_segment_{};

    std::vector<std::unique_ptr<FilterProcessor>> processors_;
    std::unique_ptr<WorkerPool> pool_;
    std::unique_ptr<PoseSolver> solver_;
    std::unique_ptr<AssemblerSet> assemblers_;
    std::unique_ptr<serve::PoseServer> server_;
    // Outputs: encoder shared by the live BVH service and the BVH recorder; the raw
    // recorder is fed by route() (ingest thread) when [outputs].raw_record is on.
    std::unique_ptr<serve::BvhFrameEncoder> bvh_encoder_;
    std::unique_ptr<serve::BvhServer> bvh_server_;
    std::unique_ptr<serve::BvhRecorder> bvh_recorder_;
    std::unique_ptr<serve::RawRecorder> raw_recorder_;
    // Web endpoint; liveness stamps (wall clock µs) read by health().
    std::unique_ptr<serve::HttpServer> http_server_;
    std::atomic<std::int64_t> assembler_alive_us_{0};  // every assembler loop pass
    std::atomic<std::int64_t> first_sample_us_{0};     // ingest thread
    std::atomic<std::int64_t> last_sample_us_{0};      // ingest thread
    std::int64_t start_us_ = 0;

    asio::io_context ingest_io_;
    std::unique_ptr<ingest::SinkListener> sink_listener_;
    std::vector<std::unique_ptr<ingest::SocketCanReader>> can_readers_;
    std::thread ingest_thread_;
    std::thread assembler_thread_;

    asio::io_context main_io_;
    asio::signal_set signals_{main_io_};
    asio::steady_timer stats_timer_{main_io_};

    std::atomic<bool> assembler_stop_{false};
    std::atomic<bool> stopping_{false};
    std::uint64_t watchdog_usec_ = 0;

    // Written by the ingest thread only.
    SingleWriterLatencyHistogram ingest_latency_;  // sink_send_us -> received_us
    SingleWriterCounter unknown_nodes_, samples_routed_, samples_rejected_;
    bool wake_posted_ = false;  // a wake_workers() is posted to ingest_io_ (see route())
    CounterGroup route_counters_{"route"};
};

}  // namespace mocap::daemon
