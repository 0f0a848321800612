// http_server.cpp — Beast sessions: HttpSession reads requests (keep-alive) and either
// answers them or hands its socket to a WsSession after an Upgrade on /ws.
#include "serve/http_server.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <charconv>
#include <chrono>
#include <cmath>
#include <deque>
#include <optional>

#include "core/parse_number.hpp"
#include "serve/client_send_queue.hpp"
#include "serve/client_session.hpp"  // token_equal
#include "serve/viewer_assets.hpp"

namespace mocap::serve {

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;

namespace {

constexpr std::size_t kMaxRequestHeaderBytes = std::size_t{8} * 1024;
constexpr std::size_t kMaxRequestBodyBytes = std::size_t{16} * 1024;
constexpr std::size_t kMaxWsMessageBytes = std::size_t{4} * 1024;

bool peer_on_loopback(const asio::ip::tcp::socket& socket) {
    boost::system::error_code ec;
    const auto address = socket.remote_endpoint(ec).address();
    if (ec) return false;
    if (address.is_v6() && address.to_v6().is_v4_mapped()) {
        return asio::ip::make_address_v4(asio::ip::v4_mapped, address.to_v6()).is_loopback();
    }
    return address.is_loopback();
}

void append_json_string(std::string& out, std::string_view s) {
    out += '"';
    for (const char c : s) {
        if (c == '"' || c == '\\') {
            out += '\\';
            out += c;
        } else if (static_cast<unsigned char>(c) < 0x20) {
            fmt::format_to(std::back_inserter(out), "\\u{:04x}", static_cast<unsigned>(c));
        } else {
            out += c;
        }
    }
    out += '"';
}

// JSON has no NaN/Inf: a non-finite value is written as null.
void append_number(std::string& out, double v, int decimals) {
    if (!std::isfinite(v)) {
        out += "null";
        return;
    }
    fmt::format_to(std::back_inserter(out), "{:.{}f}", v, decimals);
}

// "a=1&b=x" -> value of `key` (no percent-decoding: the keys and values used are plain).
std::optional<std::string_view> query_value(std::string_view query, std::string_view key) {
    while (!query.empty()) {
        const std::size_t amp = query.find('&');
        const std::string_view pair = query.substr(0, amp);
        const std::size_t eq = pair.find('=');
        if (pair.substr(0, eq) == key) return eq == std::string_view::npos ? "" : pair.substr(eq + 1);
        if (amp == std::string_view::npos) break;
        query.remove_prefix(amp + 1);
    }
    return std::nullopt;
}

std::optional<std::uint32_t> parse_u32(std::string_view s) {
    std::uint32_t v = 0;
    if (!core::parse_number(s, v)) return std::nullopt;
    return v;
}

}  // namespace

std::vector<NamedCounter> HttpServerCounters::snapshot() const {
    auto v = [](const C& c) { return c.load(std::memory_order_relaxed); };
    return {{"http.connections_accepted", v(connections_accepted)},
            {"http.connections_rejected_full", v(connections_rejected_full)},
            {"http.connections_closed", v(connections_closed)},
            {"http.requests", v(requests)},
            {"http.bad_requests", v(bad_requests)},
            {"http.metrics_scrapes", v(metrics_scrapes)},
            {"http.health_checks", v(health_checks)},
            {"http.ws_connections", v(ws_connections)},
            {"http.ws_frames_encoded", v(ws_frames_encoded)},
            {"http.ws_frames_sent", v(ws_frames_sent)},
            {"http.ws_frames_dropped", v(ws_frames_dropped)},
            {"http.ws_backlog_dropped", v(ws_backlog_dropped)},
            {"http.ws_client_messages", v(ws_client_messages)},
            {"http.write_errors", v(write_errors)},
            {"http.control_ok", v(control_ok)},
            {"http.control_failed", v(control_failed)},
            {"http.control_refused_disabled", v(control_refused_disabled)},
            {"http.control_refused_not_loopback", v(control_refused_not_loopback)},
            {"http.control_refused_bad_token", v(control_refused_bad_token)}};
}

// ------------------------------------------------------------------------- sessions

class HttpServer::Session {
public:
    virtual ~Session() = default;
    virtual void close() = 0;
};

// One WebSocket viewer. Serve thread only: no locks.
class HttpServer::WsSession : public Session, public std::enable_shared_from_this<WsSession> {
public:
    WsSession(asio::ip::tcp::socket socket, HttpServer& server, std::uint64_t id, std::uint32_t subject)
        : ws_(std::move(socket)),
          server_(server),
          id_(id),
          subject_(subject),
          frames_(server.config_.ws_queue_frames, server.counters_.ws_frames_dropped) {}

    void run(http::request<http::string_body> request) {
        request_ = std::move(request);
        beast::get_lowest_layer(ws_).expires_never();  // the WebSocket timeouts take over
        ws_.set_option(websocket::stream_base::timeout::suggested(beast::role_type::server));
        ws_.set_option(websocket::stream_base::decorator(
            [](websocket::response_type& res) { res.set(http::field::server, "mocapd"); }));
        ws_.read_message_max(kMaxWsMessageBytes);
        ws_.async_accept(request_, [self = shared_from_this()](const beast::error_code& ec) { self->on_accept(ec); });
    }

    // A frame for whoever watches its subject; oldest queued frame dropped when full.
    void offer(const SubjectText& frame) {
        if (closed_ || !open_) return;
        if (subject_ == 0) subject_ = frame.subject_id;  // first subject with a frame
        if (frame.subject_id != subject_) return;
        frames_.push(frame.text);
        if (!writing_) do_write();
    }

    void close() override {
        if (closed_) return;
        closed_ = true;
        beast::error_code ignored;
        auto& socket = beast::get_lowest_layer(ws_).socket();
        socket.shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
        socket.close(ignored);
        server_.on_closed(id_);
    }

private:
    void on_accept(const beast::error_code& ec) {
        if (ec) return fail(ec, "accept");
        open_ = true;
        server_.on_ws_open(id_, shared_from_this());
        replies_.push_back(std::make_shared<const std::string>(server_.hello_json(subject_)));
        do_write();
        do_read();
    }

    void do_read() {
        ws_.async_read(read_buf_,
                       [self = shared_from_this()](const beast::error_code& ec, std::size_t) { self->on_read(ec); });
    }

    void on_read(const beast::error_code& ec) {
        if (ec) return fail(ec, "read");
        server_.counters_.ws_client_messages.fetch_add(1, std::memory_order_relaxed);
        read_buf_.consume(read_buf_.size());
        do_read();
    }

    void do_write() {
        if (closed_ || writing_) return;
        in_flight_is_frame_ = false;
        if (const std::uint64_t dropped = frames_.take_unreported_drops(); dropped > 0) {
            in_flight_ = std::make_shared<const std::string>(
                fmt::format(R"({{"type":"drops","dropped":{},"dropped_total":{}}})", dropped, frames_.dropped_total()));
        } else if (!replies_.empty()) {
            in_flight_ = std::move(replies_.front());
            replies_.pop_front();
        } else if (!frames_.empty()) {
            in_flight_ = frames_.pop();
            in_flight_is_frame_ = true;
        } else {
            return;
        }
        writing_ = true;
        ws_.text(true);
        ws_.async_write(asio::buffer(*in_flight_),
                        [self = shared_from_this()](const beast::error_code& ec, std::size_t) { self->on_write(ec); });
    }

    void on_write(const beast::error_code& ec) {
        writing_ = false;
        if (ec) {
            if (ec != asio::error::operation_aborted) {
                server_.counters_.write_errors.fetch_add(1, std::memory_order_relaxed);
            }
            return fail(ec, "write");
        }
        if (in_flight_is_frame_) server_.counters_.ws_frames_sent.fetch_add(1, std::memory_order_relaxed);
        in_flight_.reset();
        do_write();
    }

    void fail(const beast::error_code& ec, const char* what) {
        if (ec != asio::error::operation_aborted && ec != websocket::error::closed && ec != asio::error::eof &&
            ec != asio::error::connection_reset) {
            spdlog::debug("http: websocket {} {}: {}", id_, what, ec.message());
        }
        close();
    }

    websocket::stream<beast::tcp_stream> ws_;
    HttpServer& server_;
    std::uint64_t id_;
    std::uint32_t subject_;
    http::request<http::string_body> request_;
    beast::flat_buffer read_buf_;
    ClientSendQueue frames_;  // capacity ws_queue_frames; drops announced before the next frame
    std::deque<std::shared_ptr<const std::string>> replies_;  // hello only
    std::shared_ptr<const std::string> in_flight_;
    bool in_flight_is_frame_ = false;
    bool writing_ = false;
    bool open_ = false;
    bool closed_ = false;
};

// One HTTP/1.1 connection (keep-alive). Serve thread only.
class HttpServer::HttpSession : public Session, public std::enable_shared_from_this<HttpSession> {
public:
    HttpSession(asio::ip::tcp::socket socket, HttpServer& server, std::uint64_t id)
        : stream_(std::move(socket)), server_(server), id_(id) {}

    void start() { do_read(); }

    void close() override {
        if (closed_) return;
        closed_ = true;
        beast::error_code ignored;
        stream_.socket().shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
        stream_.close();
        server_.on_closed(id_);
    }

private:
    void do_read() {
        parser_.emplace();
        parser_->header_limit(kMaxRequestHeaderBytes);
        parser_->body_limit(kMaxRequestBodyBytes);
        stream_.expires_after(std::chrono::seconds(server_.config_.idle_timeout_s));
        http::async_read(stream_, buffer_, *parser_,
                         [self = shared_from_this()](const beast::error_code& ec, std::size_t) { self->on_read(ec); });
    }

    void on_read(const beast::error_code& ec) {
        if (ec == http::error::end_of_stream) return close();
        if (ec) return fail(ec, "read");
        server_.counters_.requests.fetch_add(1, std::memory_order_relaxed);
        http::request<http::string_body> request = parser_->release();
        const std::string_view target(request.target().data(), request.target().size());
        const std::size_t q = target.find('?');
        const std::string_view path = target.substr(0, q);
        const std::string_view query = q == std::string_view::npos ? "" : target.substr(q + 1);
        if (path == "/ws") return upgrade(std::move(request), query);
        respond(request, path, query);
    }

    void upgrade(http::request<http::string_body> request, std::string_view query) {
        if (!websocket::is_upgrade(request)) return send_text(request, http::status::bad_request, "WebSocket only\n");
        std::uint32_t subject = 0;
        if (const auto v = query_value(query, "subject")) {
            const auto parsed = parse_u32(*v);
            if (!parsed) return send_text(request, http::status::bad_request, "subject must be a number\n");
            subject = *parsed;
        }
        // The WebSocket session takes the socket and this connection's id and slot.
        stream_.expires_never();
        closed_ = true;
        auto ws = std::make_shared<WsSession>(stream_.release_socket(), server_, id_, subject);
        server_.sessions_.put(id_, ws);
        ws->run(std::move(request));
    }

    void respond(const http::request<http::string_body>& request, std::string_view path, std::string_view query) {
        const bool read_only = request.method() == http::verb::get || request.method() == http::verb::head;
        if (path == "/metrics" && read_only) {
            server_.counters_.metrics_scrapes.fetch_add(1, std::memory_order_relaxed);
            return send_text(request, http::status::ok, server_.metrics_text(),
                             "text/plain; version=0.0.4; charset=utf-8");
        }
        if (path == "/healthz" && read_only) {
            server_.counters_.health_checks.fetch_add(1, std::memory_order_relaxed);
            const HealthStatus h = server_.handlers_.health ? server_.handlers_.health() : HealthStatus{true, "ok"};
            return h.ok ? send_text(request, http::status::ok, "ok\n")
                        : send_text(request, http::status::service_unavailable, "unhealthy: " + h.detail + "\n");
        }
        if (path.substr(0, 5) == "/api/") {
            if (request.method() != http::verb::post) {
                return send_text(request, http::status::method_not_allowed, "POST only\n");
            }
            return control(request, path, query);
        }
        const std::string_view file = path == "/" ? std::string_view("/index.html") : path;
        for (const StaticAsset& asset : viewer_assets()) {
            if (asset.path != file) continue;
            if (!read_only) return send_text(request, http::status::method_not_allowed, "GET only\n");
            http::response<http::span_body<const char>> res{http::status::ok, request.version()};
            res.set(http::field::server, "mocapd");
            res.set(http::field::content_type,
                    beast::string_view(asset.content_type.data(), asset.content_type.size()));
            res.set(http::field::cache_control, "no-cache");
            res.body() = beast::span<const char>(asset.body.data(), asset.body.size());
            res.keep_alive(request.keep_alive());
            res.prepare_payload();
            if (request.method() == http::verb::head) res.body() = {};
            return send(std::move(res));
        }
        send_text(request, http::status::not_found, "not found\n");
    }

    // POST /api/...: token and loopback checks first, then the daemon's handler.
    void control(const http::request<http::string_body>& request, std::string_view path, std::string_view query) {
        const HttpServerConfig& config = server_.config_;
        HttpServerCounters& counters = server_.counters_;
        auto reply = [&](http::status status, const ControlResult& r) {
            std::string body = R"({"ok":)";
            body += r.ok ? "true" : "false";
            body += R"(,"error":)";
            append_json_string(body, r.error);
            body += "}\n";
            send_text(request, status, std::move(body), "application/json");
        };
        auto refuse = [&](HttpServerCounters::C& counter, http::status status, const char* why) {
            counter.fetch_add(1, std::memory_order_relaxed);
            std::uint64_t suppressed = 0;
            if (server_.log_.allow(LogLimiter::kControlRefused, suppressed)) {
                spdlog::warn("http: control request {} refused: {} ({} suppressed)", path, why, suppressed);
            }
            reply(status, ControlResult::failure(why));
        };
        const auto token_field = request.find("X-Mocap-Token");
        const std::string_view token = token_field == request.end()
                                           ? std::string_view()
                                           : std::string_view(token_field->value().data(), token_field->value().size());
        if (config.control_token.empty()) {
            return refuse(counters.control_refused_disabled, http::status::forbidden,
                          "control disabled (no token configured)");
        }
        if (config.control_loopback_only && !peer_on_loopback(stream_.socket())) {
            return refuse(counters.control_refused_not_loopback, http::status::forbidden, "control only from loopback");
        }
        if (!token_equal(config.control_token, token)) {
            return refuse(counters.control_refused_bad_token, http::status::unauthorized, "missing or bad token");
        }
        const ControlHandlers& h = server_.handlers_.control;
        std::optional<ControlResult> result;
        if (path == "/api/calibrate") {
            const auto subject = parse_u32(query_value(query, "subject").value_or(""));
            const std::string_view pose = query_value(query, "pose").value_or("t");
            if (!subject || (pose != "t" && pose != "n")) {
                counters.bad_requests.fetch_add(1, std::memory_order_relaxed);
                return reply(http::status::bad_request, ControlResult::failure("expected ?subject=<id>&pose=t|n"));
            }
            if (h.calibrate) result = h.calibrate(*subject, pose == "n" ? CalibrationPose::kN : CalibrationPose::kT);
        } else if (path == "/api/record/start") {
            if (h.start_recording) result = h.start_recording("");
        } else if (path == "/api/record/stop") {
            if (h.stop_recording) result = h.stop_recording();
        } else {
            counters.bad_requests.fetch_add(1, std::memory_order_relaxed);
            return reply(http::status::not_found, ControlResult::failure("unknown control action"));
        }
        if (!result)
            return reply(http::status::not_implemented, ControlResult::failure("not supported by this server"));
        (result->ok ? counters.control_ok : counters.control_failed).fetch_add(1, std::memory_order_relaxed);
        reply(result->ok ? http::status::ok : http::status::conflict, *result);
    }

    void send_text(const http::request<http::string_body>& request, http::status status, std::string body,
                   const char* content_type = "text/plain; charset=utf-8") {
        if (static_cast<unsigned>(status) >= 400 && status != http::status::service_unavailable &&
            status != http::status::conflict) {
            server_.counters_.bad_requests.fetch_add(1, std::memory_order_relaxed);
        }
        http::response<http::string_body> res{status, request.version()};
        res.set(http::field::server, "mocapd");
        res.set(http::field::content_type, content_type);
        res.set(http::field::cache_control, "no-store");
        res.body() = std::move(body);
        res.keep_alive(request.keep_alive());
        res.prepare_payload();
        if (request.method() == http::verb::head) res.body().clear();
        send(std::move(res));
    }

    template <class Body>
    void send(http::response<Body>&& response) {
        auto res = std::make_shared<http::response<Body>>(std::move(response));
        keep_alive_ = res->keep_alive();
        response_ = res;
        http::async_write(stream_, *res, [self = shared_from_this()](const beast::error_code& ec, std::size_t) {
            self->on_write(ec);
        });
    }

    void on_write(const beast::error_code& ec) {
        if (ec) {
            if (ec != asio::error::operation_aborted) {
                server_.counters_.write_errors.fetch_add(1, std::memory_order_relaxed);
            }
            return fail(ec, "write");
        }
        response_.reset();
        if (!keep_alive_) return close();
        do_read();
    }

    void fail(const beast::error_code& ec, const char* what) {
        if (ec != asio::error::operation_aborted && ec != beast::error::timeout && ec != asio::error::eof &&
            ec != asio::error::connection_reset) {
            if (std::string_view(what) == "read") {
                server_.counters_.bad_requests.fetch_add(1, std::memory_order_relaxed);
            }
            spdlog::debug("http: connection {} {}: {}", id_, what, ec.message());
        }
        close();
    }

    beast::tcp_stream stream_;
    HttpServer& server_;
    std::uint64_t id_;
    beast::flat_buffer buffer_;
    std::optional<http::request_parser<http::string_body>> parser_;
    std::shared_ptr<void> response_;  // the response being written
    bool keep_alive_ = false;
    bool closed_ = false;
};

// --------------------------------------------------------------------------- server

HttpServer::HttpServer(HttpServerConfig config, HttpDescription description, HttpHandlers handlers)
    : config_(std::move(config)),
      description_(std::move(description)),
      handlers_(std::move(handlers)),
      serve_({"http", "mocap-http", "viewer, /metrics and /healthz"}, config_.max_clients,
             {counters_.connections_accepted, counters_.connections_rejected_full},
             {[this] { return sessions_.size(); }, [this](asio::ip::tcp::socket s) { admit(std::move(s)); },
              [this] { sessions_.close_all(); }}),
      sessions_(counters_.connections_closed),
      backlog_(serve_.io(), config_.publish_backlog_frames, [this](const SubjectText& frame) { deliver(frame); }) {
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
    serve_.stop();
}

void HttpServer::admit(asio::ip::tcp::socket socket) {
    const std::uint64_t id = sessions_.next_id();
    auto s = std::make_shared<HttpSession>(std::move(socket), *this, id);
    sessions_.put(id, s);
    s->start();
}

void HttpServer::on_ws_open(std::uint64_t id, const std::shared_ptr<WsSession>& session) {
    counters_.ws_connections.fetch_add(1, std::memory_order_relaxed);
    ws_sessions_[id] = session;
    ws_clients_.store(ws_sessions_.size());
}

void HttpServer::on_closed(std::uint64_t id) {
    sessions_.remove(id);
    ws_sessions_.erase(id);
    ws_clients_.store(ws_sessions_.size());
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
    std::string out = R"({"type":"hello","subject":)";
    fmt::format_to(std::back_inserter(out), "{},\"subjects\":[", subject);
    for (std::size_t i = 0; i < description_.subjects.size(); ++i) {
        fmt::format_to(std::back_inserter(out), "{}{}", i == 0 ? "" : ",", description_.subjects[i]);
    }
    out += R"(],"world_frame":)";
    append_json_string(out, description_.world_frame);
    fmt::format_to(std::back_inserter(out), R"(,"queue_frames":{},"control":{{"enabled":{},"loopback_only":{}}},)",
                   config_.ws_queue_frames, !config_.control_token.empty(), config_.control_loopback_only);
    out += R"("segments":[)";
    for (std::size_t i = 0; i < description_.segments.size(); ++i) {
        const HttpSegment& s = description_.segments[i];
        out += i == 0 ? "{\"name\":" : ",{\"name\":";
        append_json_string(out, s.name);
        fmt::format_to(std::back_inserter(out), R"(,"parent":{},"end_m":[)", s.parent);
        for (std::size_t k = 0; k < 3; ++k) {
            if (k) out += ',';
            append_number(out, s.end_m[k], 4);
        }
        out += "]}";
    }
    out += "]}";
    return out;
}

std::string HttpServer::metrics_text() {
    MetricsSnapshot m = handlers_.metrics ? handlers_.metrics() : MetricsSnapshot{};
    for (NamedCounter& c : counters_.snapshot())
        m.counters.push_back(std::move(c));
    m.gauges.push_back(
        {"http_clients", "HTTP and WebSocket connections open now", static_cast<double>(sessions_.open())});
    m.gauges.push_back(
        {"http_ws_clients", "Viewer WebSocket connections open now", static_cast<double>(ws_clients_.load())});
    m.gauges.push_back({"subjects_active", "Subjects that delivered a frame in the last 2 s",
                        static_cast<double>(active_subjects(2'000'000))});
    return render_prometheus(m);
}

void HttpServer::publish(const SubjectFrame& frame, const SkeletonPose& pose) {
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

    const std::size_t n = std::min<std::size_t>(frame.segment_count, pose.segment_count);
    auto json = std::make_shared<std::string>();
    json->reserve(256 + n * 96);
    std::string& out = *json;
    const StageTimes& t = frame.times;
    fmt::format_to(std::back_inserter(out),
                   R"({{"type":"frame","subject":{},"sync":{},"sample_us":{},"stamps":{{"sink_send_us":{},)"
                   R"("received_us":{},"filtered_us":{},"assembled_us":{},"encoded_us":{}}},"pos":[)",
                   frame.subject_id, frame.sync, frame.sample_us, t.sink_send_us, t.received_us, t.filtered_us,
                   t.assembled_us, now);
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t k = 0; k < 3; ++k) {
            if (i + k) out += ',';
            append_number(out, pose.position_m[i][k], 4);
        }
    }
    out += R"(],"q":[)";
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t k = 0; k < 4; ++k) {
            if (i + k) out += ',';
            append_number(out, pose.q_world_segment_wxyz[i][k], 5);
        }
    }
    out += R"(],"flags":[)";
    for (std::size_t i = 0; i < n; ++i) {
        fmt::format_to(std::back_inserter(out), "{}{}", i ? "," : "",
                       static_cast<unsigned>(frame.segments[i].flags | pose.extra_flags[i]));
    }
    out += "]}";
    counters_.ws_frames_encoded.fetch_add(1, std::memory_order_relaxed);

    if (!backlog_.push({frame.subject_id, std::move(json)})) {
        counters_.ws_backlog_dropped.fetch_add(1, std::memory_order_relaxed);
    }
}

void HttpServer::deliver(const SubjectText& frame) {
    for (auto it = ws_sessions_.begin(); it != ws_sessions_.end();) {
        auto s = (it++)->second;  // offer() may close and erase the session
        s->offer(frame);
    }
}

}  // namespace mocap::serve
