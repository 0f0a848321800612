#include "daemon/daemon.hpp"

#include <spdlog/spdlog.h>
#include <systemd/sd-daemon.h>

#include <chrono>
#include <cmath>

#include "daemon/replay.hpp"
#include "filter/filter_factory.hpp"

namespace mocap::daemon {

namespace {

serve::StageLatencySummary summarize(std::string stage, const LatencySnapshot& s) {
    serve::StageLatencySummary out;
    out.stage = std::move(stage);
    out.count = s.count;
    out.p50_us = static_cast<double>(s.percentile_us(50));
    out.p90_us = static_cast<double>(s.percentile_us(90));
    out.p99_us = static_cast<double>(s.percentile_us(99));
    out.max_us = static_cast<double>(s.max_us);
    return out;
}

void append(std::vector<serve::NamedCounter>& out, const CounterGroup& g) {
    for (const auto& c : g.snapshot())
        out.push_back({g.component() + "." + c.name, c.value});
}

}  // namespace

std::optional<skeleton::BodyModel> body_model_from_config(const DaemonConfig& config, std::string* error) {
    skeleton::BodyModel model;
    if (config.segments.empty()) {
        model = skeleton::default_body_model(1.75, config.filter_name);
    } else {
        for (const auto& sc : config.segments) {
            skeleton::SegmentDef d;
            d.name = sc.name;
            d.parent = sc.parent.empty() ? -1 : model.index_of(sc.parent);
            d.offset_m = {sc.offset_m[0], sc.offset_m[1], sc.offset_m[2]};
            d.end_m = {sc.end_m[0], sc.end_m[1], sc.end_m[2]};
            d.node_id = sc.node;
            d.filter = sc.filter.empty() ? config.filter_name : sc.filter;
            model.segments.push_back(std::move(d));
        }
        model.root_height_m = config.root_height_m;
    }
    const auto problems = skeleton::validate(model);
    if (!problems.empty()) {
        *error = "skeleton: " + problems.front();
        return std::nullopt;
    }
    return model;
}

Daemon::Daemon(DaemonConfig config, std::string config_path)
    : config_(std::move(config)), config_path_(std::move(config_path)) {
    route_counters_.add("samples_routed", samples_routed_);
    route_counters_.add("samples_unknown_node", unknown_nodes_);
    route_counters_.add("samples_rejected", samples_rejected_);
}

Daemon::~Daemon() {
    shutdown();
}

bool Daemon::start(std::string* error) {
    auto model = body_model_from_config(config_, error);
    if (!model) return false;
    model_ = std::move(*model);
    node_to_segment_.fill(-1);
    for (std::size_t i = 0; i < model_.size(); ++i) {
        const int node = model_.segments[i].node_id;
        if (node >= 0 && node < static_cast<int>(node_to_segment_.size())) {
            node_to_segment_[static_cast<std::size_t>(node)] = static_cast<std::int16_t>(i);
        }
    }

    // Filters: one per segment per possible subject, built before any thread starts.
    WorkerPoolConfig pc;
    pc.workers = config_.workers;
    pc.input_capacity = config_.ring_capacity;
    pc.output_capacity = config_.ring_capacity;
    pool_ = std::make_unique<WorkerPool>(pc, &clock_);
    std::vector<std::uint32_t> subject_ids;
    for (std::uint32_t id = 1; id <= config_.max_subjects; ++id)
        subject_ids.push_back(id);
    for (const auto& can : config_.socketcan) {
        if (can.subject > config_.max_subjects) subject_ids.push_back(can.subject);
    }
    for (std::uint32_t id : subject_ids) {
        for (std::size_t i = 0; i < model_.size(); ++i) {
            const auto& seg = model_.segments[i];
            auto f = filter::make_filter(seg.filter, config_.filter_params, error);
            if (!f) {
                *error = "filter for segment " + seg.name + ": " + *error;
                return false;
            }
            // A particle filter costs tens of times a complementary filter: weigh it so
            // the pool balances work, not segment counts.
            const std::uint32_t weight = seg.filter == "pf" ? 20 : 1;
            processors_.push_back(std::make_unique<FilterProcessor>(std::move(f)));
            pool_->add_segment(id, static_cast<std::uint16_t>(i), *processors_.back(), weight);
        }
    }

    // Skeleton solver -> pose service.
    serve::ServeConfig sc;
    sc.bind_address = config_.pose_listen.host;
    sc.port = config_.pose_listen.port;
    sc.max_clients = config_.max_clients;
    sc.queue_frames = config_.client_queue_frames;
    sc.subscribe_timeout_ms = static_cast<std::uint32_t>(config_.handshake_timeout_s * 1000.0);
    sc.max_client_message_bytes = config_.max_message_bytes;
    sc.max_client_messages_per_s = config_.max_client_messages_per_s;
    sc.client_message_burst = config_.client_message_burst;
    sc.control_token = config_.control_token;
    sc.control_loopback_only = config_.control_loopback_only;
    sc.io_threads = config_.serve_threads;
    sc.wall_clock_us = [this] { return clock_.now_us(); };
    sc.server_version = "mocapd";

    serve::ControlHandlers handlers;
    handlers.calibrate = [this](std::uint32_t subject, serve::CalibrationPose pose) {
        const auto p =
            pose == serve::CalibrationPose::kN ? skeleton::CalibrationPose::kNPose : skeleton::CalibrationPose::kTPose;
        const std::string err = solver_->request_calibration(subject, p);
        return err.empty() ? serve::ControlResult::success() : serve::ControlResult::failure(err);
    };
    handlers.reload = [this] {
        asio::post(main_io_, [this] { reload(); });
        return serve::ControlResult::success();
    };
    handlers.stats = [this] { return stats(); };

    // --- outputs (docs/outputs.md) ---
    bvh_encoder_ = std::make_unique<serve::BvhFrameEncoder>(model_, bvh_options_from_config(config_));
    serve::BvhRecorderConfig brc;
    brc.directory = config_.record_dir;
    brc.subject = config_.bvh_subject;
    brc.flush_interval_s = config_.record_flush_interval_s;
    bvh_recorder_ = std::make_unique<serve::BvhRecorder>(brc, *bvh_encoder_);
    handlers.start_recording = [this](const std::string& path) {
        std::string err, opened;
        return bvh_recorder_->start(path, &err, &opened) ? serve::ControlResult::success()
                                                         : serve::ControlResult::failure(err);
    };
    handlers.stop_recording = [this] {
        std::string err;
        return bvh_recorder_->stop(&err) ? serve::ControlResult::success() : serve::ControlResult::failure(err);
    };
    if (config_.bvh_live) {
        serve::BvhServerConfig bc;
        bc.bind_address = config_.bvh_listen.host;
        bc.port = config_.bvh_listen.port;
        bc.max_clients = config_.bvh_max_clients;
        bc.queue_frames = config_.client_queue_frames;
        bc.subject = config_.bvh_subject;
        bvh_server_ = std::make_unique<serve::BvhServer>(bc, *bvh_encoder_);
    }
    if (config_.raw_record) {
        serve::RawRecorderConfig rrc;
        rrc.directory = config_.record_dir;
        rrc.flush_interval_s = config_.record_flush_interval_s;
        rrc.rotate_bytes = static_cast<std::uint64_t>(config_.raw_rotate_mb * 1024.0 * 1024.0);
        rrc.rotate_s = config_.raw_rotate_s;
        rrc.ring_capacity = config_.raw_ring_capacity;
        raw_recorder_ = std::make_unique<serve::RawRecorder>(rrc, clock_);
    }
    // --- end outputs ---
    server_ = std::make_unique<serve::PoseServer>(sc, handlers);
    // --- web endpoint (docs/viewer.md) ---
    if (config_.http_enabled) {
        serve::HttpServerConfig hc;
        hc.bind_address = config_.http_listen.host;
        hc.port = config_.http_listen.port;
        hc.max_clients = config_.http_max_clients;
        hc.ws_queue_frames = config_.http_ws_queue_frames;
        hc.control_token = config_.control_token;
        hc.control_loopback_only = config_.control_loopback_only;
        hc.wall_clock_us = [this] { return clock_.now_us(); };
        serve::HttpDescription hd;
        for (const auto& seg : model_.segments)
            hd.segments.push_back({seg.name, seg.parent, {seg.end_m.x(), seg.end_m.y(), seg.end_m.z()}});
        hd.subjects = subject_ids;
        serve::HttpHandlers hh;
        hh.control = handlers;
        hh.metrics = [this] { return metrics(); };
        hh.health = [this] { return health(); };
        http_server_ = std::make_unique<serve::HttpServer>(std::move(hc), std::move(hd), std::move(hh));
    }
    // --- end web endpoint ---

    PoseSolverOptions so = pose_solver_options_from_config(config_);  // shared with replay
    so.max_subjects = *std::max_element(subject_ids.begin(), subject_ids.end());
    solver_ = std::make_unique<PoseSolver>(model_, so, [this](const SubjectFrame& f, const serve::SkeletonPose& p) {
        server_->publish(f, p);
        if (bvh_server_) bvh_server_->publish(f, p);
        bvh_recorder_->publish(f, p);
        if (http_server_) http_server_->publish(f, p);
    });
    for (const auto& line : solver_->load_calibrations())
        spdlog::info("{}", line);

    AssemblerConfig ac;
    ac.deadline_us = static_cast<std::int64_t>(config_.assembly_deadline_ms * 1000.0);
    assemblers_ = std::make_unique<AssemblerSet>(ac, *solver_);
    for (std::uint32_t id : subject_ids)
        assemblers_->add_subject(id, static_cast<std::uint16_t>(model_.size()));

    serve::ServeDescription desc;
    for (const auto& s : model_.segments) {
        desc.segments.push_back({s.name,
                                 s.parent,
                                 {s.offset_m.x(), s.offset_m.y(), s.offset_m.z()},
                                 static_cast<std::uint32_t>(std::max(0, s.node_id))});
    }
    for (const auto& j : solver_->joints()) {
        for (const char* axis : {"flexion", "abduction", "rotation"})
            desc.joint_angle_names.push_back(j.name + "." + axis);
    }
    for (std::uint32_t id : subject_ids)
        desc.subjects.push_back({id, "subject-" + std::to_string(id)});
    server_->set_description(desc);

    // Ingest.
    ingest::SinkListenerConfig lc;
    lc.host = config_.sink_listen.host;
    lc.port = config_.sink_listen.port;
    lc.max_sinks = config_.max_sinks;
    lc.max_subjects = std::min<std::uint32_t>(config_.max_subjects, 255);
    lc.idle_timeout_s = config_.sink_idle_timeout_s;
    const auto sink = [this](const SegmentSample& s) { route(s); };
    sink_listener_ = std::make_unique<ingest::SinkListener>(ingest_io_, lc, clock_, sink);
    for (const auto& can : config_.socketcan) {
        ingest::SocketCanConfig cc;
        cc.interface = can.interface;
        cc.subject = can.subject;
        can_readers_.push_back(std::make_unique<ingest::SocketCanReader>(ingest_io_, cc, clock_, sink));
    }

    // Bind everything before announcing readiness: a failure here exits non-zero. The start
    // time is set before any thread starts: /metrics reads it from the HTTP thread.
    start_us_ = clock_.now_us();
    assembler_alive_us_ = start_us_;
    pool_->start();
    if (!server_->start(*error)) return false;
    if (bvh_server_ && !bvh_server_->start(*error)) return false;
    if (http_server_) {
        // The web endpoint is an aid, not the pose service: a taken port is logged, not fatal.
        std::string http_error;
        if (!http_server_->start(http_error)) {
            spdlog::error("{}; the viewer, /metrics and /healthz are off", http_error);
            http_server_.reset();
        }
    }
    if (raw_recorder_ && !raw_recorder_->start(error)) return false;
    if (!sink_listener_->start(error)) return false;
    for (auto& r : can_readers_) {
        if (!r->start(error)) return false;
    }
    ingest_thread_ = std::thread([this] {
        auto guard = asio::make_work_guard(ingest_io_);
        ingest_io_.run();
    });
    if (sd_watchdog_enabled(0, &watchdog_usec_) <= 0) watchdog_usec_ = 0;
    assembler_thread_ = std::thread([this] { assembler_loop(); });

    signals_.add(SIGTERM);
    signals_.add(SIGINT);
    signals_.add(SIGHUP);
    spdlog::info("mocapd ready: sinks on {}, poses on {}, {} segments x {} subjects, {} workers",
                 config_.sink_listen.str(), config_.pose_listen.str(), model_.size(), subject_ids.size(),
                 pool_->worker_count());
    sd_notify(0, "READY=1\nSTATUS=serving");
    return true;
}

void Daemon::route(const SegmentSample& in) {
    if (in.times.sink_send_us != 0) ingest_latency_.record(in.times.received_us - in.times.sink_send_us);
    if (raw_recorder_) raw_recorder_->push(in);  // every node, before the model filters it
    if (first_sample_us_.load(std::memory_order_relaxed) == 0) first_sample_us_.store(in.times.received_us);
    last_sample_us_.store(in.times.received_us, std::memory_order_relaxed);
    const std::int16_t seg = in.node_id < node_to_segment_.size() ? node_to_segment_[in.node_id] : -1;
    if (seg < 0) {
        unknown_nodes_.add();
        return;
    }
    SegmentSample s = in;
    s.segment_index = static_cast<std::uint16_t>(seg);
    // Wake the workers once per ingest handler run (one TCP read: a packet or more), not
    // once per sample: a per-sample wake cost the ingest thread a futex call and a context
    // switch per sample (a third of its time in the profile, docs/performance.md).
    if (pool_->submit(s, /*wake=*/false) == SubmitResult::kQueued) {
        samples_routed_.add();
        if (!wake_posted_) {
            wake_posted_ = true;
            asio::post(ingest_io_, [this] {
                wake_posted_ = false;
                pool_->wake_workers();
            });
        }
    } else {
        samples_rejected_.add();
    }
}

void Daemon::assembler_loop() {
    auto last_ping = std::chrono::steady_clock::now();
    while (!assembler_stop_.load(std::memory_order_acquire)) {
        const std::int64_t now = clock_.now_us();
        const std::int64_t next = assemblers_->next_deadline_us();
        const std::int64_t wait = next == kNoDeadline ? 50'000 : std::clamp<std::int64_t>(next - now, 0, 50'000);
        pool_->wait_for_output(wait);
        pool_->drain([this](const PoseUpdate& u) { assemblers_->on_pose(u, clock_.now_us()); });
        assemblers_->advance(clock_.now_us());
        assembler_alive_us_.store(clock_.now_us(), std::memory_order_relaxed);
        if (watchdog_usec_ != 0) {
            const auto t = std::chrono::steady_clock::now();
            if (t - last_ping > std::chrono::microseconds(watchdog_usec_ / 4)) {
                sd_notify(0, "WATCHDOG=1");
                last_ping = t;
            }
        }
    }
    // Drain what the workers still produce, then emit every open instant.
    pool_->drain([this](const PoseUpdate& u) { assemblers_->on_pose(u, clock_.now_us()); }, SIZE_MAX);
    assemblers_->flush(clock_.now_us());
}

serve::StatsSnapshot Daemon::stats() const {
    serve::StatsSnapshot s;
    if (sink_listener_) append(s.counters, sink_listener_->counters());
    for (const auto& r : can_readers_)
        append(s.counters, r->counters());
    append(s.counters, route_counters_);
    if (pool_) append(s.counters, pool_->counters());
    if (assemblers_) append(s.counters, assemblers_->counters());
    if (solver_) append(s.counters, solver_->counters());
    if (bvh_server_) {
        for (const auto& c : bvh_server_->counters().snapshot())
            s.counters.push_back(c);
    }
    if (bvh_recorder_) append(s.counters, bvh_recorder_->counters());
    if (raw_recorder_) append(s.counters, raw_recorder_->counters());
    const LatencySnapshot ingest = ingest_latency_.snapshot();
    // A sink clock ahead of the host gives negative latencies: not in the histogram, counted.
    s.counters.push_back({"latency.ingest_negative", ingest.negative});
    s.latencies.push_back(summarize("ingest", ingest));
    if (pool_) {
        s.latencies.push_back(summarize("queue_wait", pool_->queue_wait_snapshot()));
        s.latencies.push_back(summarize("filter", pool_->filter_snapshot()));
    }
    if (assemblers_) s.latencies.push_back(summarize("assembly", assemblers_->assembly_snapshot()));
    return s;
}

// --- web endpoint (docs/viewer.md) ---
serve::MetricsSnapshot Daemon::metrics() const {
    serve::MetricsSnapshot m;
    m.counters = stats().counters;
    for (auto& c : server_->counter_snapshot())
        m.counters.push_back(std::move(c));
    auto gauge = [&m](std::string name, std::string help, double value) {
        m.gauges.push_back({std::move(name), std::move(help), value});
    };
    gauge("pose_clients", "Protobuf pose clients connected now", static_cast<double>(server_->client_count()));
    if (bvh_server_)
        gauge("bvh_live_clients", "Live BVH clients connected now", static_cast<double>(bvh_server_->client_count()));
    if (sink_listener_) {
        const auto& g = sink_listener_->counters();
        const auto opened = g.value("connections_accepted").value_or(0);
        const auto closed = g.value("connections_closed").value_or(0);
        gauge("sinks_connected", "Sink TCP connections open now",
              static_cast<double>(opened - std::min(opened, closed)));
    }
    gauge("subjects_configured", "Subjects the pipeline was built for",
          static_cast<double>(assemblers_ ? assemblers_->subject_count() : 0));
    gauge("start_time_seconds", "Start of mocapd, Unix time in seconds", static_cast<double>(start_us_) * 1e-6);
    m.latencies.push_back({"ingest", ingest_latency_.snapshot()});
    if (pool_) {
        m.latencies.push_back({"queue_wait", pool_->queue_wait_snapshot()});
        m.latencies.push_back({"filter", pool_->filter_snapshot()});
    }
    if (assemblers_) m.latencies.push_back({"assembly", assemblers_->assembly_snapshot()});
    return m;
}

// Alive: the assembler loop turns (it wakes at least every 50 ms), the ingest thread's
// io_context runs, and samples that arrive turn into frames within 2 s.
serve::HealthStatus Daemon::health() const {
    constexpr std::int64_t kWindowUs = 2'000'000;
    const std::int64_t now = clock_.now_us();
    if (stopping_.load()) return {false, "stopping"};
    if (now - assembler_alive_us_.load(std::memory_order_relaxed) > kWindowUs)
        return {false, "assembler thread stalled"};
    if (ingest_io_.stopped()) return {false, "ingest thread stopped"};
    const std::int64_t last_sample = last_sample_us_.load(std::memory_order_relaxed);
    if (last_sample == 0) return {true, "no sink data yet"};
    const std::int64_t last_frame =
        std::max(http_server_ ? http_server_->last_frame_us() : 0, first_sample_us_.load(std::memory_order_relaxed));
    if (now - last_sample <= kWindowUs && now - last_frame > kWindowUs)
        return {false, "samples arrive but no frame was assembled for 2 s"};
    return {true, "ok"};
}
// --- end web endpoint ---

void Daemon::log_stats() {
    const auto s = stats();
    std::string line;
    for (const auto& c : s.counters) {
        if (c.value != 0) line += " " + c.name + "=" + std::to_string(c.value);
    }
    for (const auto& c : server_->counter_snapshot()) {
        if (c.value != 0) line += " " + c.name + "=" + std::to_string(c.value);
    }
    for (const auto& l : s.latencies) {
        if (l.count != 0) line += fmt::format(" {}_p99_us={:.0f}", l.stage, l.p99_us);
    }
    spdlog::info("stats:{} clients={}", line, server_->client_count());
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
    auto next = load_config_file(config_path_, &err);
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
    if (!pool_) return;
    sd_notify(0, "STOPPING=1");
    // Ingest first (no new samples), then the workers finish what is queued, then the
    // assembler emits what is open, then clients get the last frames and are closed.
    if (ingest_thread_.joinable()) {
        asio::post(ingest_io_, [this] {
            sink_listener_->stop();
            for (auto& r : can_readers_)
                r->stop();
            ingest_io_.stop();
        });
        ingest_thread_.join();
    }
    if (raw_recorder_) raw_recorder_->stop();  // ingest (its producer) has stopped
    pool_->stop();
    assembler_stop_.store(true, std::memory_order_release);
    if (assembler_thread_.joinable()) assembler_thread_.join();
    if (server_) server_->stop();
    if (bvh_server_) bvh_server_->stop();
    if (http_server_) http_server_->stop();
    if (bvh_recorder_ && bvh_recorder_->recording()) {
        std::string ignored;
        bvh_recorder_->stop(&ignored);  // patches the frame count
    }
    pool_.reset();
    spdlog::info("mocapd stopped");
}

}  // namespace mocap::daemon
