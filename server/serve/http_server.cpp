// http_server.cpp — the web endpoint's server: acceptor and session table (through
// ServeThread), publish() and frame delivery to the WebSockets, /metrics text. The
// connections are in http_connection.cpp and ws_connection.cpp, the JSON in pose_json.cpp.
#include "serve/http_server.hpp"

#include <algorithm>
#include <chrono>

#include "serve/http_connection.hpp"
#include "serve/pose_json.hpp"
#include "serve/ws_connection.hpp"

namespace mocap::serve {

HttpServerCounters::HttpServerCounters() {
    connections.register_in(group);
    group.add("requests", requests);
    group.add("bad_requests", bad_requests);
    group.add("metrics_scrapes", metrics_scrapes);
    group.add("health_checks", health_checks);
    group.add("ws_connections", ws_connections);
    group.add("ws_origin_refused", ws_origin_refused);
    group.add("host_refused", host_refused);
    group.add("ws_frames_encoded", ws_frames_encoded);
    group.add("ws_frames_sent", ws_frames_sent);
    group.add("ws_frames_dropped", ws_frames_dropped);
    group.add("ws_backlog_dropped", ws_backlog_dropped);
    group.add("ws_client_messages", ws_client_messages);
    group.add("write_errors", write_errors);
    group.add("takes_listed", takes_listed);
    group.add("take_downloads", take_downloads);
    group.add("take_exports_busy", take_exports_busy);
    group.add("take_exports_failed", take_exports_failed);
    group.add("take_exports_over_budget", take_exports_over_budget);
    group.add("take_exports_abandoned", take_exports_abandoned);
    group.add("takes_deleted", takes_deleted);
    control.register_in(group);
}

// --------------------------------------------------------------------------- server

HttpServer::HttpServer(HttpServerConfig config, HttpDescription description, HttpHandlers handlers)
    : config_(std::move(config)),
      description_(std::move(description)),
      handlers_(std::move(handlers)),
      serve_({"http", "mocap-http", "viewer, /metrics and /healthz"},
             {{config_.max_clients, config_.limits}, config_.send_buffer_bytes, config_.threads}, counters_.connections,
             {[this](std::size_t lane, asio::ip::tcp::socket s, ServeThread::SlotPtr slot) {
                  admit(lane, std::move(s), std::move(slot));
              },
              [this](std::size_t lane, std::uint64_t id) { sessions_[lane]->close(id); },
              [this](std::size_t lane) { sessions_[lane]->close_all(); }}),
      sessions_(make_session_tables<Session>(serve_.lanes(), counters_.connections.closed)),
      ws_sessions_(serve_.lanes()),
      backlog_(serve_.ios(), config_.publish_backlog_frames,
               [this](std::size_t lane, const SubjectText& frame) { deliver(lane, frame); }),
      exports_(config_.export_waiting),
      export_budget_(config_.export_memory_bytes, config_.export_memory_per_address_bytes) {
    register_metrics(own_metrics_);
    if (!config_.control_attempts) config_.control_attempts = std::make_shared<ControlAttemptLimiter>();
    if (!config_.wall_clock_us) {
        config_.wall_clock_us = [] {
            return std::chrono::duration_cast<std::chrono::microseconds>(
                       std::chrono::system_clock::now().time_since_epoch())
                .count();
        };
    }
}

HttpServer::~HttpServer() {
    stop();
}

bool HttpServer::start(std::string& error) {
    return serve_.start(config_.bind_address, config_.port, error);
}

void HttpServer::stop() {
    // Exports first: a running one is cancelled and answers its client while the lanes run.
    exports_.stop();
    serve_.stop();
}

void HttpServer::admit(std::size_t lane, asio::ip::tcp::socket socket, ServeThread::SlotPtr slot) {
    const std::uint64_t id = slot->id();
    auto s = std::make_shared<HttpSession>(std::move(socket), *this, lane, std::move(slot));
    sessions_[lane]->put(id, s);
    s->start();
}

void HttpServer::on_ws_open(std::size_t lane, std::uint64_t id, const std::shared_ptr<WsSession>& session) {
    counters_.ws_connections.add();
    if (ws_sessions_[lane].insert_or_assign(id, session).second) ws_clients_.fetch_add(1);
}

void HttpServer::on_closed(std::size_t lane, std::uint64_t id) {
    sessions_[lane]->remove(id);
    serve_.release(id);
    if (ws_sessions_[lane].erase(id) != 0) ws_clients_.fetch_sub(1);
}

std::size_t HttpServer::active_subjects(std::int64_t window_us) const {
    const std::int64_t now = now_us();
    std::lock_guard lock(subjects_mutex_);
    std::size_t n = 0;
    for (const auto& [id, last_us] : subject_last_us_)
        n += now - last_us <= window_us ? 1 : 0;
    return n;
}

std::string HttpServer::hello_json(std::uint32_t subject) const {
    return encode_hello_json(description_, {subject, config_.ws_queue_frames, !config_.control_token.empty(),
                                            config_.control_loopback_only});
}

void HttpServer::register_metrics(MetricsRegistry& registry) const {
    registry.add(counters_.group);
    registry.add_gauge("http_clients", "HTTP and WebSocket connections open now",
                       [this] { return static_cast<double>(client_count()); });
    registry.add_gauge("http_ws_clients", "Viewer WebSocket connections open now",
                       [this] { return static_cast<double>(ws_clients_.load()); });
    registry.add_gauge("http_take_export_bytes", "Bytes take exports hold in memory now (the export budget)",
                       [this] { return static_cast<double>(export_budget_.held()); });
    registry.add_gauge("subjects_active", "Subjects that delivered a frame in the last 2 s",
                       [this] { return static_cast<double>(active_subjects(2'000'000)); });
}

std::string HttpServer::metrics_text() {
    return render_prometheus(handlers_.metrics ? handlers_.metrics() : own_metrics_.snapshot());
}

void HttpServer::publish(const SubjectFrame& frame, const skeleton::SkeletonPose& pose) {
    const std::int64_t now = now_us();
    last_frame_us_.store(now, std::memory_order_relaxed);
    {
        std::lock_guard lock(subjects_mutex_);
        auto it = std::find_if(subject_last_us_.begin(), subject_last_us_.end(),
                               [&](const auto& p) { return p.first == frame.subject_id; });
        if (it == subject_last_us_.end()) {
            subject_last_us_.emplace_back(frame.subject_id, now);  // once per subject
        } else {
            it->second = now;
        }
    }
    if (ws_clients_.load(std::memory_order_relaxed) == 0 || !serve_.running()) return;

    auto json = std::make_shared<std::string>(encode_frame_json(frame, pose, now));
    counters_.ws_frames_encoded.add();

    // One encoding, shared by every lane and browser.
    if (const std::size_t refused = backlog_.push({frame.subject_id, std::move(json)}); refused > 0) {
        counters_.ws_backlog_dropped.add(refused);
    }
}

void HttpServer::deliver(std::size_t lane, const SubjectText& frame) {
    WsTable& ws_sessions = ws_sessions_[lane];
    for (auto it = ws_sessions.begin(); it != ws_sessions.end();) {
        auto s = (it++)->second;  // offer() may close and erase the session
        s->offer(frame);
    }
}

}  // namespace mocap::serve
