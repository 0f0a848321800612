#include "daemon/daemon.hpp"

#include <pthread.h>
#include <spdlog/spdlog.h>
#include <systemd/sd-daemon.h>

#include <chrono>
#include <cmath>

#include "cluster/calibration_bucket.hpp"
#include "daemon/config_check.hpp"
#include "daemon/peer_limits.hpp"
#include "daemon/take_export.hpp"

namespace mocap::daemon {

Daemon::Daemon(DaemonConfig config, std::string config_path)
    : config_(std::move(config)), config_path_(std::move(config_path)) {}

Daemon::~Daemon() {
    shutdown();
}

serve::ControlHandlers Daemon::control_handlers() {
    serve::ControlHandlers handlers;
    handlers.calibrate = [this](std::uint32_t subject, serve::CalibrationPose pose) {
        const auto p =
            pose == serve::CalibrationPose::kN ? skeleton::CalibrationPose::kNPose : skeleton::CalibrationPose::kTPose;
        const std::string err = pipeline_->solver().request_calibration(subject, p);
        return err.empty() ? serve::ControlResult::success() : serve::ControlResult::failure(err);
    };
    handlers.reload = [this] {
        asio::post(main_io_, [this] { reload(); });
        return serve::ControlResult::success();
    };
    handlers.stats = [this] { return metrics(); };
    handlers.start_recording = [this](const std::string& path) {
        std::string err;
        return bvh_recorder_->start_recording(path, &err) ? serve::ControlResult::success()
                                                          : serve::ControlResult::failure(err);
    };
    handlers.stop_recording = [this] {
        std::string err;
        return bvh_recorder_->stop_recording(&err) ? serve::ControlResult::success()
                                                   : serve::ControlResult::failure(err);
    };
    handlers.start_take = [this](const std::string& name, const std::string& notes) {
        return take_recorder_->start_take(name, notes);
    };
    handlers.stop_take = [this] { return take_recorder_->stop_take(); };
    return handlers;
}

bool Daemon::start(std::string* error) {
    // Catch the signals before any port opens: a SIGTERM from a service manager (or a test)
    // that sees a port and stops the daemon at once must drain it, not kill it with the
    // default action. Asio keeps a signal that arrives before run() waits for it.
    signals_.add(SIGTERM);
    signals_.add(SIGINT);
    signals_.add(SIGHUP);
    if (!play_.files.empty() && !config_.cluster_nats_url.empty()) {
        // A played take is not the venue's: publishing it would put old samples with fresh
        // times into the site's durable takes and its calibrations into the shared bucket.
        spdlog::warn("play: the cluster ([cluster] nats_url) is off while a take is played");
        config_.cluster_nats_url.clear();
    }
    auto pc = pipeline_config_from_config(config_, error);
    if (!pc) return false;
    if (!config_.cluster_nats_url.empty()) {
        // Calibrations are shared across the site's hosts; the files stay the fallback.
        pc->calibration_store = std::make_unique<cluster::CalibrationBucket>(cluster_config_from_config(config_),
                                                                             std::move(pc->calibration_store));
    }
    pipeline_ = pipeline::Pipeline::create(std::move(*pc), clock_, error);
    if (!pipeline_) return false;
    pipeline_->solver().load_calibrations();

    // Outputs (docs/outputs.md): every one comes from the registry in outputs.cpp.
    // Takes live under the record directory (docs/outputs.md, "Takes"); a download re-solves
    // one with this config (daemon/take_export.hpp), on the web endpoint's export thread.
    auto takes = std::make_shared<serve::TakeStore>(config_.record_dir + "/takes");
    takes->remove_unfinished_deletes();
    serve::TakeExporter exporter = [config = config_, takes](const serve::TakeExportRequest& request,
                                                             const std::atomic<bool>& cancel) {
        return export_take(config, *takes, request, cancel);
    };
    const OutputContext outputs{config_,
                                *pipeline_,
                                clock_,
                                control_handlers(),
                                [this] { return metrics(); },
                                [this] { return health(); },
                                nullptr,
                                std::make_shared<serve::ControlAttemptLimiter>(),
                                takes,
                                std::move(exporter)};
    add_outputs(outputs, *pipeline_);
    for (const auto& o : pipeline_->outputs()) {
        if (auto* r = dynamic_cast<BvhRecorderOutput*>(o.get())) bvh_recorder_ = r;
        if (auto* t = dynamic_cast<TakeRecorderOutput*>(o.get())) take_recorder_ = t;
    }

    // Ingest: the sinks and the CAN buses, or a recorded take played as if live.
    const auto sink = [this](const SegmentSample& s) { route(s); };
    if (!play_.files.empty()) {
        player_ = std::make_unique<TakePlayer>(ingest_io_, play_, clock_, sink);
    } else {
        ingest::SinkListenerConfig lc;
        lc.host = config_.sink_listen.host;
        lc.port = config_.sink_listen.port;
        lc.max_sinks = config_.max_sinks;
        lc.max_subjects = std::min<std::uint32_t>(config_.max_subjects, 255);
        lc.subject_id_base = config_.subject_id_base;
        lc.keepalive_period_ms = static_cast<std::uint16_t>(std::lround(config_.keepalive_period_s * 1000.0));
        lc.idle_timeout_s = config_.sink_idle_timeout_s;
        lc.limits = peer_limits(config_, config_.sink_per_address);
        sink_listener_ = std::make_unique<ingest::SinkListener>(ingest_io_, lc, clock_, sink);
        for (const auto& can : config_.socketcan) {
            ingest::SocketCanConfig cc;
            cc.interface = can.interface;
            cc.subject = can.subject;
            can_readers_.push_back(std::make_unique<ingest::SocketCanReader>(ingest_io_, cc, clock_, sink));
        }
    }

    // Every metric, registered once before any thread that reads them starts (docs/performance.md,
    // "Metrics registry").
    if (sink_listener_) sink_listener_->register_metrics(metrics_);
    for (const auto& r : can_readers_)
        r->register_metrics(metrics_);
    if (player_) player_->register_metrics(metrics_);
    pipeline_->register_metrics(metrics_);
    const double start_s = static_cast<double>(clock_.now_us()) * 1e-6;
    metrics_.add_gauge("start_time_seconds", "Start of mocapd, Unix time in seconds", [start_s] { return start_s; });

    // Bind everything before announcing readiness: a failure here exits non-zero.
    if (!pipeline_->start_outputs(error)) return false;
    pipeline_->start_workers();
    if (sink_listener_ && !sink_listener_->start(error)) return false;
    if (player_ && !player_->start(error)) return false;
    for (auto& r : can_readers_) {
        if (!r->start(error)) return false;
    }
    // The threads that must make progress, for /healthz and the watchdog.
    heartbeats_.add({"ingest thread", &ingest_beats_});
    for (std::size_t i = 0; i < pipeline_->pool().worker_count(); ++i)
        heartbeats_.add({"worker " + std::to_string(i), &pipeline_->pool().worker_beats(i)});
    for (const auto& o : pipeline_->outputs()) {
        for (Heartbeat& h : o->heartbeats())
            heartbeats_.add(std::move(h));
    }
    beat_ingest();
    ingest_thread_ = std::thread([this] {
        pthread_setname_np(pthread_self(), "mocap-ingest");
        auto guard = asio::make_work_guard(ingest_io_);
        ingest_io_.run();
    });
    if (sd_watchdog_enabled(0, &watchdog_usec_) <= 0) watchdog_usec_ = 0;
    assembler_thread_ = std::thread([this] {
        auto last_ping = std::chrono::steady_clock::now();
        bool withheld = false;
        pipeline_->run_assembler([this, &last_ping, &withheld] {
            if (watchdog_usec_ == 0) return;
            const auto t = std::chrono::steady_clock::now();
            if (t - last_ping <= std::chrono::microseconds(watchdog_usec_ / 4)) return;
            // A thread that stopped withholds the ping: systemd restarts a daemon that is
            // alive in part only (WatchdogSec), as it would one that hangs.
            if (const std::string stale = heartbeats_.stale(steady_us(), kHeartbeatWindowUs); !stale.empty()) {
                if (!withheld) spdlog::error("watchdog: not pinging systemd: {} made no progress", stale);
                withheld = true;
                return;
            }
            if (withheld) spdlog::info("watchdog: every thread makes progress again");
            withheld = false;
            sd_notify(0, "WATCHDOG=1");
            last_ping = t;
        });
    });

    spdlog::info("mocapd ready: {}, poses on {}, {} segments x {} subjects, {} workers",
                 player_ ? "playing " + std::to_string(play_.files.size()) + " raw recording(s)" +
                               (play_.loop ? " in a loop" : "")
                         : "sinks on " + config_.sink_listen.str(),
                 config_.pose_listen.str(), pipeline_->model().size(), pipeline_->subjects().size(),
                 pipeline_->pool().worker_count());
    sd_notify(0, "READY=1\nSTATUS=serving");
    return true;
}

void Daemon::route(const SegmentSample& in) {
    // Wake the workers once per ingest handler run (one TCP read: a packet or more), not
    // once per sample: a per-sample wake cost the ingest thread a futex call and a context
    // switch per sample (a third of its time in the profile, docs/performance.md).
    if (!pipeline_->route(in) || wake_posted_) return;
    wake_posted_ = true;
    asio::post(ingest_io_, [this] {
        wake_posted_ = false;
        pipeline_->wake_workers();
    });
}

std::uint16_t Daemon::output_port(std::string_view name) const {
    if (!pipeline_) return 0;
    for (const auto& o : pipeline_->outputs()) {
        if (o->name() == name) return o->port();
    }
    return 0;
}

std::int64_t Daemon::steady_us() {
    return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

// Every 250 ms on the ingest thread, whether sinks send or not: the thread's heartbeat.
void Daemon::beat_ingest() {
    ingest_beats_.fetch_add(1, std::memory_order_relaxed);
    ingest_beat_timer_.expires_after(std::chrono::milliseconds(250));
    ingest_beat_timer_.async_wait([this](const boost::system::error_code& ec) {
        if (!ec) beat_ingest();
    });
}

void Daemon::arm_stats_timer() {
    if (config_.stats_interval_s <= 0) return;
    stats_timer_.expires_after(std::chrono::milliseconds(static_cast<std::int64_t>(config_.stats_interval_s * 1000)));
    stats_timer_.async_wait([this](const boost::system::error_code& ec) {
        if (ec) return;
        log_stats();
        arm_stats_timer();
    });
}

void Daemon::reload() {
    if (config_path_.empty()) {
        spdlog::info("reload: running on the embedded default config; nothing to reload");
        return;
    }
    std::string err;
    auto next = load_checked_config(config_path_, &err);
    if (!next) {
        spdlog::error("reload: keeping the running config: {}", err);
        return;
    }
    // Only [log] changes at run time; the rest is reported so nobody believes it applied.
    spdlog::set_level(spdlog::level::from_str(next->log_level));
    const bool timer_changed = next->stats_interval_s != config_.stats_interval_s;
    config_.log_level = next->log_level;
    config_.stats_interval_s = next->stats_interval_s;
    if (timer_changed) {
        stats_timer_.cancel();
        arm_stats_timer();
    }
    next->log_level = config_.log_level;
    next->stats_interval_s = config_.stats_interval_s;
    if (!(*next == config_)) spdlog::warn("reload: settings other than [log] need a restart to apply");
    spdlog::info("reload: log level {}, stats every {} s", config_.log_level, config_.stats_interval_s);
}

void Daemon::request_stop() {
    asio::post(main_io_, [this] {
        stopping_ = true;
        signals_.cancel();
        stats_timer_.cancel();
    });
}

void Daemon::run() {
    std::function<void()> wait_signal = [&] {
        signals_.async_wait([&](const boost::system::error_code& ec, int sig) {
            if (ec) return;
            if (sig == SIGHUP) {
                sd_notify(0, "RELOADING=1");
                reload();
                sd_notify(0, "READY=1");
                wait_signal();
                return;
            }
            spdlog::info("signal {}: draining and stopping", sig);
            stopping_ = true;
            stats_timer_.cancel();
        });
    };
    wait_signal();
    arm_stats_timer();
    main_io_.run();
    shutdown();
}

void Daemon::shutdown() {
    if (!pipeline_ || shut_down_) return;
    shut_down_ = true;
    sd_notify(0, "STOPPING=1");
    // Ingest first (no new samples), then the workers finish what is queued, then the
    // assembler emits what is open, then the outputs send the last frames and close.
    if (ingest_thread_.joinable()) {
        asio::post(ingest_io_, [this] {
            if (sink_listener_) sink_listener_->stop();
            for (auto& r : can_readers_)
                r->stop();
            ingest_beat_timer_.cancel();
            ingest_io_.stop();
        });
        ingest_thread_.join();
    }
    pipeline_->stop_workers();
    pipeline_->request_assembler_stop();
    if (assembler_thread_.joinable()) assembler_thread_.join();
    std::string err;
    if (!pipeline_->stop_outputs(&err)) spdlog::error("stopping outputs: {}", err);
    spdlog::info("mocapd stopped");
}

}  // namespace mocap::daemon
