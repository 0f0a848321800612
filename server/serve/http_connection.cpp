// http_connection.cpp — an HTTP/1.1 connection: request routing, viewer files, /metrics,
// /healthz, control over HTTP (the rules in control_access.hpp), the WebSocket upgrade.
#include "serve/http_connection.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <chrono>

#include "serve/control_access.hpp"
#include "serve/http_query.hpp"
#include "serve/origin_check.hpp"
#include "serve/pose_json.hpp"
#include "serve/viewer_assets.hpp"

namespace mocap::serve {

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;

namespace {

constexpr std::size_t kMaxRequestHeaderBytes = std::size_t{8} * 1024;
constexpr std::size_t kMaxRequestBodyBytes = std::size_t{16} * 1024;

}  // namespace

HttpServer::HttpSession::HttpSession(asio::ip::tcp::socket socket, HttpServer& server, std::size_t lane,
                                     ServeThread::SlotPtr slot)
    : stream_(std::move(socket)), server_(server), lane_(lane), slot_(std::move(slot)), id_(slot_->id()) {}

template <class Body>
void HttpServer::HttpSession::send(http::response<Body>&& response) {
    auto res = std::make_shared<http::response<Body>>(std::move(response));
    keep_alive_ = res->keep_alive();
    response_ = res;
    http::async_write(stream_, *res,
                      [self = shared_from_this()](const beast::error_code& ec, std::size_t) { self->on_write(ec); });
}

void HttpServer::HttpSession::close() {
    if (closed_) return;
    closed_ = true;
    if (export_cancel_) export_cancel_->store(true);  // nobody will read it
    beast::error_code ignored;
    stream_.socket().shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
    stream_.close();
    server_.on_closed(lane_, id_);
}

void HttpServer::HttpSession::do_read() {
    parser_.emplace();
    parser_->header_limit(kMaxRequestHeaderBytes);
    parser_->body_limit(kMaxRequestBodyBytes);
    stream_.expires_after(std::chrono::seconds(server_.config_.idle_timeout_s));
    http::async_read(stream_, buffer_, *parser_,
                     [self = shared_from_this()](const beast::error_code& ec, std::size_t) { self->on_read(ec); });
}

void HttpServer::HttpSession::on_read(const beast::error_code& ec) {
    if (ec == http::error::end_of_stream) return close();
    if (ec) return fail(ec, "read");
    server_.counters_.requests.add();
    slot_->progress(ServeThread::now_us());
    Request request = parser_->release();
    const std::string_view target(request.target().data(), request.target().size());
    const std::size_t q = target.find('?');
    const std::string_view path = target.substr(0, q);
    const std::string_view query = q == std::string_view::npos ? "" : target.substr(q + 1);
    if (!host_allowed(request)) return;
    if (path == "/ws") return upgrade(std::move(request), query);
    respond(request, path, query);
}

// Every path: a page whose name was rebound to this address must read nothing, not even
// /healthz (docs/security.md, "DNS rebinding").
bool HttpServer::HttpSession::host_allowed(const Request& request) {
    const auto it = request.find(http::field::host);
    const std::string_view host =
        it == request.end() ? std::string_view() : std::string_view(it->value().data(), it->value().size());
    if (http_host_allowed(host, server_.config_.allowed_hosts)) return true;
    server_.counters_.host_refused.add();
    std::uint64_t suppressed = 0;
    if (server_.log_.allow(LogLimiter::kHostRefused, suppressed)) {
        spdlog::warn("http: request for host '{}' refused: not in allowed_hosts ({} suppressed)", host, suppressed);
    }
    send_text(request, http::status::forbidden,
              fmt::format("host '{}' not allowed: add it to [http] allowed_hosts to serve it\n", host));
    return false;
}

void HttpServer::HttpSession::upgrade(Request request, std::string_view query) {
    if (!websocket::is_upgrade(request)) return send_text(request, http::status::bad_request, "WebSocket only\n");
    std::uint32_t subject = 0;
    if (const auto v = query_value(query, "subject")) {
        const auto parsed = parse_u32(*v);
        if (!parsed) return send_text(request, http::status::bad_request, "subject must be a number\n");
        subject = *parsed;
    }
    // A browser sends the page's origin; a page from elsewhere must not read poses
    // (docs/security.md, "Origin of WebSocket requests").
    const auto header = [&request](http::field f) {
        const auto it = request.find(f);
        return it == request.end() ? std::string_view() : std::string_view(it->value().data(), it->value().size());
    };
    if (!websocket_origin_allowed(header(http::field::origin), header(http::field::host),
                                  server_.config_.allowed_origins)) {
        server_.counters_.ws_origin_refused.add();
        std::uint64_t suppressed = 0;
        if (server_.log_.allow(LogLimiter::kOriginRefused, suppressed)) {
            spdlog::warn(
                "http: WebSocket from origin '{}' refused: not the served host {} nor in allowed_origins "
                "({} suppressed)",
                header(http::field::origin), header(http::field::host), suppressed);
        }
        return send_text(request, http::status::forbidden, "origin not allowed\n");
    }
    // The WebSocket session takes the socket and this connection's id and slot.
    stream_.expires_never();
    closed_ = true;
    auto ws = std::make_shared<WsSession>(stream_.release_socket(), server_, lane_, slot_, subject);
    server_.sessions_[lane_]->put(id_, ws);
    ws->run(std::move(request));
}

void HttpServer::HttpSession::respond(const Request& request, std::string_view path, std::string_view query) {
    const bool read_only = request.method() == http::verb::get || request.method() == http::verb::head;
    if (path == "/metrics" && read_only) {
        server_.counters_.metrics_scrapes.add();
        return send_text(request, http::status::ok, server_.metrics_text(), "text/plain; version=0.0.4; charset=utf-8");
    }
    if (path == "/healthz" && read_only) {
        server_.counters_.health_checks.add();
        const HealthStatus h = server_.handlers_.health ? server_.handlers_.health() : HealthStatus{true, "ok"};
        return h.ok ? send_text(request, http::status::ok, "ok\n")
                    : send_text(request, http::status::service_unavailable, "unhealthy: " + h.detail + "\n");
    }
    if (path == "/api/takes" || path.starts_with("/api/takes/")) return takes(request, path, query);
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
        res.set(http::field::content_type, beast::string_view(asset.content_type.data(), asset.content_type.size()));
        res.set(http::field::cache_control, "no-cache");
        res.body() = beast::span<const char>(asset.body.data(), asset.body.size());
        res.keep_alive(request.keep_alive());
        res.prepare_payload();
        if (request.method() == http::verb::head) res.body() = {};
        return send(std::move(res));
    }
    send_text(request, http::status::not_found, "not found\n");
}

bool HttpServer::HttpSession::authorized(const Request& request, std::string_view path) {
    const HttpServerConfig& config = server_.config_;
    const auto token_field = request.find("X-Mocap-Token");
    const std::string_view token = token_field == request.end()
                                       ? std::string_view()
                                       : std::string_view(token_field->value().data(), token_field->value().size());
    const std::string who = fmt::format("http: control request {}", path);
    const auto refusal =
        authorize_control({config.control_token, config.control_loopback_only, config.control_attempts.get()},
                          remote_address(stream_.socket()), token, server_.counters_.control, server_.log_, who);
    if (!refusal) return true;
    const bool token_problem = refusal->kind == ControlRefusal::kNoToken || refusal->kind == ControlRefusal::kBadToken;
    // 401 tells the viewer to ask for the token again; 429: wait, too many failed
    // attempts (control_access.hpp); 403: no token would help.
    const http::status status = refusal->kind == ControlRefusal::kThrottled ? http::status::too_many_requests
                                : token_problem                             ? http::status::unauthorized
                                                                            : http::status::forbidden;
    send_text(request, status, encode_control_reply_json(ControlResult::failure(refusal->reason)), "application/json");
    return false;
}

// POST /api/...: token and loopback checks first, then the daemon's handler.
void HttpServer::HttpSession::control(const Request& request, std::string_view path, std::string_view query) {
    HttpServerCounters& counters = server_.counters_;
    auto reply = [&](http::status status, const ControlResult& r) {
        send_text(request, status, encode_control_reply_json(r), "application/json");
    };
    if (!authorized(request, path)) return;
    const ControlHandlers& h = server_.handlers_.control;
    std::optional<ControlResult> result;
    if (path == "/api/calibrate") {
        const auto subject = parse_u32(query_value(query, "subject").value_or(""));
        const std::string_view pose = query_value(query, "pose").value_or("t");
        if (!subject || (pose != "t" && pose != "n")) {
            counters.bad_requests.add();
            return reply(http::status::bad_request, ControlResult::failure("expected ?subject=<id>&pose=t|n"));
        }
        if (h.calibrate) result = h.calibrate(*subject, pose == "n" ? CalibrationPose::kN : CalibrationPose::kT);
    } else if (path == "/api/record/start") {
        if (h.start_recording) result = h.start_recording("");
    } else if (path == "/api/record/stop") {
        if (h.stop_recording) result = h.stop_recording();
    } else {
        counters.bad_requests.add();
        return reply(http::status::not_found, ControlResult::failure("unknown control action"));
    }
    if (!result) return reply(http::status::not_implemented, ControlResult::failure("not supported by this server"));
    counters.control.count_result(*result);
    reply(result->ok ? http::status::ok : http::status::conflict, *result);
}

void HttpServer::HttpSession::send_text(const Request& request, http::status status, std::string body,
                                        const char* content_type) {
    send_text({request.version(), request.keep_alive(), request.method() == http::verb::head}, status, std::move(body),
              content_type);
}

void HttpServer::HttpSession::send_text(const ReplyTo& to, http::status status, std::string body,
                                        const char* content_type) {
    if (static_cast<unsigned>(status) >= 400 && status != http::status::service_unavailable &&
        status != http::status::conflict) {
        server_.counters_.bad_requests.add();
    }
    http::response<http::string_body> res{status, to.version};
    res.set(http::field::server, "mocapd");
    res.set(http::field::content_type, content_type);
    res.set(http::field::cache_control, "no-store");
    res.body() = std::move(body);
    res.keep_alive(to.keep_alive);
    res.prepare_payload();
    if (to.head) res.body().clear();
    send(std::move(res));
}

void HttpServer::HttpSession::on_write(const beast::error_code& ec) {
    if (ec) {
        if (ec != asio::error::operation_aborted) {
            server_.counters_.write_errors.add();
        }
        return fail(ec, "write");
    }
    response_.reset();
    if (!keep_alive_) return close();
    do_read();
}

void HttpServer::HttpSession::fail(const beast::error_code& ec, const char* what) {
    if (ec != asio::error::operation_aborted && ec != beast::error::timeout && ec != asio::error::eof &&
        ec != asio::error::connection_reset) {
        if (std::string_view(what) == "read") {
            server_.counters_.bad_requests.add();
        }
        spdlog::debug("http: connection {} {}: {}", id_, what, ec.message());
    }
    close();
}

}  // namespace mocap::serve
