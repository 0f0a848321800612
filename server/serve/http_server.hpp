// http_server.hpp — mocapd's web endpoint (Boost.Beast HTTP/1.1 + WebSocket, default
// port 8080; docs/viewer.md):
//
//   GET  /, /index.html, /viewer.js, /three/...   the live 3D viewer (embedded files)
//   GET  /metrics    Prometheus text format 0.0.4 (prometheus_text.hpp)
//   GET  /healthz    200 "ok" while HttpHandlers::health says so, else 503 + reason
//   GET  /ws?subject=N   WebSocket: JSON poses of subject N (0 or absent = the first
//                        subject that delivers a frame); see "WebSocket messages"
//   POST /api/calibrate?subject=N&pose=t|n, /api/record/start, /api/record/stop
//        control: header "X-Mocap-Token: <token>" compared in constant time with the
//        [control] token; refused when no token is configured, and from non-loopback
//        peers when loopback_only. A custom header cannot be sent cross-site without a
//        CORS preflight, which this server never grants. Reply: JSON {"ok":..,"error":..}.
//   GET    /api/takes                       the takes, JSON (take_store.hpp)
//   GET    /api/takes/NAME                  one take, JSON
//   GET    /api/takes/NAME/download?format=raw|bvh|csv[&filter=F][&subject=N]
//          raw: the recorded file as is; bvh/csv: re-solved from it by the daemon's exporter
//          (HttpHandlers::export_take) on the TakeExportQueue's thread, never on a serve
//          thread; 503 when that queue is full
//   POST   /api/takes/start[?name=N][&notes=TEXT], /api/takes/stop     control (token)
//   DELETE /api/takes/NAME                                             control (token)
//   docs/client-protocol.md, "Takes" has the details and the replies.
//
// WebSocket messages (text, one JSON object each; numbers in SI units, wall-clock µs):
//   {"type":"hello","subject":N,"subjects":[..],"world_frame":"ENU","queue_frames":Q,
//    "control":{"enabled":b,"loopback_only":b},
//    "segments":[{"name":"pelvis","parent":-1,"end_m":[x,y,z]},..]}        once, first
//   {"type":"frame","subject":N,"sync":S,"sample_us":T,
//    "stamps":{"sink_send_us":..,"received_us":..,"filtered_us":..,"assembled_us":..,
//              "encoded_us":..},
//    "pos":[x0,y0,z0,x1,..],      segment origins (joint with the parent), world, metres
//    "q":[w0,x0,y0,z0,w1,..],     world-from-segment orientations
//    "flags":[f0,f1,..]}          SegmentFlags bits (1 stale, 2 never seen, 4 calibrated)
//   {"type":"drops","dropped":k,"dropped_total":n}    before the next frame after drops
// A segment's distal tip is pos_i + rotate(q_i, end_m_i). Client messages are read and
// ignored (counted); the subject is chosen by reconnecting.
//
// Lag: each WebSocket has a ClientSendQueue of ws_queue_frames encoded frames; when it is
// full the OLDEST is dropped (counted, and announced by a "drops" message), so a slow
// browser sees gaps, never stalls the pipeline; the hello is never queued with frames.
// One write in flight per connection. Frames are encoded once, shared by every client.
//
// Threads: a ServeThread with `threads` lanes (each its own io_context and thread) runs
// the acceptor (lane 0); HTTP connections are spread round-robin over the lanes and a
// WebSocket stays on the lane of the connection it upgraded; each lane keeps its own
// session tables and runs its sessions' metrics/health/control callbacks. publish() may
// be called from any thread (the assembler): it encodes only while a WebSocket is open and
// hands the same shared bytes to every lane through a PublishBacklog of
// publish_backlog_frames per lane (beyond: dropped, counted once per lane that refused).
// Ownership: the daemon owns the server; stop() or the destructor closes all.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "core/asio.hpp"
#include "core/frame.hpp"
#include "serve/control_access.hpp"
#include "serve/prometheus_text.hpp"
#include "serve/publish_backlog.hpp"
#include "serve/serve_config.hpp"
#include "serve/serve_counters.hpp"
#include "serve/serve_thread.hpp"
#include "serve/session_table.hpp"
#include "serve/take_export_budget.hpp"
#include "serve/take_export_queue.hpp"
#include "serve/take_store.hpp"
#include "skeleton/skeleton_pose.hpp"

namespace mocap::serve {

struct HttpServerConfig {
    std::string bind_address = "0.0.0.0";
    std::uint16_t port = 8080;         ///< 0 = any free port (tests)
    std::size_t max_clients = 64;      ///< HTTP + WebSocket slots; see ServeThread for who gets one when full
    std::size_t ws_queue_frames = 16;  ///< per WebSocket; oldest dropped beyond it
    std::size_t publish_backlog_frames = 1024;
    std::uint32_t idle_timeout_s = 30;  ///< an HTTP connection idle this long is closed
    std::string control_token;          ///< empty = control refused
    bool control_loopback_only = true;
    /// Origins besides the served host that may open /ws (origin_check.hpp), e.g.
    /// "https://viewer.lab:8443".
    std::vector<std::string> allowed_origins;
    /// Host names a request's Host header may carry (origin_check.hpp: IP literals always
    /// may); the daemon puts localhost, this machine's names and `[http] allowed_hosts` here.
    std::vector<std::string> allowed_hosts{"localhost"};
    PeerLimits limits{};  ///< [limits] http_per_address, loopback, stall_evict_s
    /// SO_SNDBUF per connection: bounded, so a stalled browser's frames are dropped from its
    /// queue (counted) instead of piling up in the kernel (0 = kernel default).
    std::uint32_t send_buffer_bytes = 128 * 1024;
    /// Failed-attempt limits shared with the pose service (the daemon makes one); null =
    /// the server makes its own with the default limits (control_access.hpp).
    std::shared_ptr<ControlAttemptLimiter> control_attempts;
    /// Wall clock (CLOCK_REALTIME µs) for encoded_us; empty = system_clock.
    std::function<std::int64_t()> wall_clock_us;
    std::size_t threads = 1;         ///< serve threads ([http] threads); connections spread over them
    std::size_t export_waiting = 4;  ///< take exports that may wait behind the running one
    /// Memory finished take exports may hold until read, all peers / one peer address
    /// (take_export_budget.hpp; [outputs] export_memory_mb, export_memory_per_address_mb).
    std::uint64_t export_memory_bytes = std::uint64_t{256} << 20;
    std::uint64_t export_memory_per_address_bytes = std::uint64_t{128} << 20;
};

struct HttpSegment {
    std::string name;
    int parent = -1;
    std::array<double, 3> end_m{};  ///< distal tip in the segment's frame
};

/// What the viewer needs to draw frames: segment order of the frames, subjects.
struct HttpDescription {
    std::vector<HttpSegment> segments;
    std::vector<std::uint32_t> subjects;
    std::string world_frame = "ENU";
};

struct HealthStatus {
    bool ok = false;
    std::string detail;  ///< why not (shown in the 503 body), or a short state
};

/// Called on the serve thread; must return quickly and be safe from any thread.
struct HttpHandlers {
    ControlHandlers control;  ///< calibrate, start/stop_recording used
    /// What /metrics renders: the daemon's registry, which holds this server's metrics too
    /// (register_metrics). Empty = this server's own metrics only.
    std::function<MetricsSnapshot()> metrics;
    std::function<HealthStatus()> health;  ///< empty = always healthy
    std::shared_ptr<TakeStore> takes;      ///< null = no /api/takes
    /// Re-solves a take into BVH or CSV; called on the export queue's thread, not a serve
    /// thread. Empty = those formats answer 501.
    TakeExporter export_take;
};

struct HttpServerCounters {
    ConnectionCounters connections;  ///< connections_* and accept_errors (connection_counters.hpp)
    Counter requests;
    Counter bad_requests;  ///< unparseable, unknown path or method (4xx)
    Counter metrics_scrapes;
    Counter health_checks;
    Counter ws_connections;
    Counter ws_origin_refused;  ///< /ws upgrades refused with 403: a foreign Origin
    Counter host_refused;       ///< requests refused with 403: a Host not allowed (DNS rebinding)
    Counter ws_frames_encoded;
    Counter ws_frames_sent;
    Counter ws_frames_dropped;   ///< oldest frames dropped from lagging browsers
    Counter ws_backlog_dropped;  ///< the serve thread fell behind publish()
    Counter ws_client_messages;  ///< messages browsers sent (ignored)
    Counter write_errors;
    Counter takes_listed;              ///< GET /api/takes and /api/takes/NAME answered
    Counter take_downloads;            ///< downloads whose file started to go out
    Counter take_exports_busy;         ///< bvh/csv downloads refused: the export queue was full
    Counter take_exports_failed;       ///< bvh/csv exports that failed or were cancelled
    Counter take_exports_over_budget;  ///< bvh/csv downloads refused with 507: export memory full
    Counter take_exports_abandoned;    ///< bvh/csv exports cancelled: their connection closed
    Counter takes_deleted;
    ControlCounters control;  ///< http.control_* (control_access.hpp)

    /// Component "http": every counter above by its member name, the connections' as
    /// connection_counters.hpp names them (the metrics registry's entry, core/metrics_registry.hpp).
    CounterGroup group{"http"};

    HttpServerCounters();
};

class HttpServer {
public:
    HttpServer(HttpServerConfig config, HttpDescription description, HttpHandlers handlers);
    ~HttpServer();
    HttpServer(const HttpServer&) = delete;
    HttpServer& operator=(const HttpServer&) = delete;

    /// Binds and starts the serve thread. Returns false and sets `error` on failure.
    [[nodiscard]] bool start(std::string& error);
    /// Closes every connection and joins the thread. Idempotent.
    void stop();

    /// Any thread; never blocks on a client. Also records the subject as active.
    void publish(const SubjectFrame& frame, const skeleton::SkeletonPose& pose);

    [[nodiscard]] std::uint16_t port() const { return serve_.port(); }
    [[nodiscard]] std::size_t client_count() const { return open_sessions(sessions_); }
    /// HTTP and WebSocket connections served by lane (serve thread) `lane` now; any thread.
    [[nodiscard]] std::size_t lane_client_count(std::size_t lane) const { return sessions_.at(lane)->open(); }
    [[nodiscard]] std::size_t ws_client_count() const { return ws_clients_.load(); }
    [[nodiscard]] const HttpServerCounters& counters() const { return counters_; }
    /// Set-up: counter group "http" and gauges "http_clients", "http_ws_clients",
    /// "http_take_export_bytes" (what the export budget holds) and "subjects_active" (frames
    /// in the last 2 s).
    void register_metrics(MetricsRegistry& registry) const;
    /// Subjects whose last frame is at most `window_us` old (wall clock); any thread.
    [[nodiscard]] std::size_t active_subjects(std::int64_t window_us) const;
    /// Wall-clock time of the newest published frame (0 = none yet); any thread.
    [[nodiscard]] std::int64_t last_frame_us() const { return last_frame_us_.load(); }

    class Session;      // ws_connection.hpp: base of the two below
    class HttpSession;  // http_connection.hpp
    class WsSession;    // ws_connection.hpp

private:
    friend class HttpSession;
    friend class WsSession;
    using WsTable = std::unordered_map<std::uint64_t, std::shared_ptr<WsSession>>;
    void admit(std::size_t lane, asio::ip::tcp::socket socket, ServeThread::SlotPtr slot);
    void deliver(std::size_t lane, const SubjectText& frame);
    void on_closed(std::size_t lane, std::uint64_t id);
    void on_ws_open(std::size_t lane, std::uint64_t id, const std::shared_ptr<WsSession>& session);
    std::string hello_json(std::uint32_t subject) const;
    std::string metrics_text();
    std::int64_t now_us() const { return config_.wall_clock_us(); }

    HttpServerConfig config_;
    HttpDescription description_;
    HttpHandlers handlers_;
    HttpServerCounters counters_;
    MetricsRegistry own_metrics_;  ///< this server's alone: /metrics without a metrics handler
    LogLimiter log_;               ///< one refusal line per 10 s, not one per request

    ServeThread serve_;  // before the sessions, the backlog and the exports, which use its io_contexts
    /// HTTP and WebSocket, one table per lane, used on that lane's thread (open(): any thread).
    std::vector<std::unique_ptr<SessionTable<Session>>> sessions_;
    std::vector<WsTable> ws_sessions_;  // one per lane, used on that lane's thread
    PublishBacklog backlog_;
    TakeExportQueue exports_;  // posts its results to the lanes' io_contexts
    TakeExportBudget export_budget_;

    mutable std::mutex subjects_mutex_;
    std::vector<std::pair<std::uint32_t, std::int64_t>> subject_last_us_;  // guarded

    std::atomic<std::int64_t> last_frame_us_{0};
    std::atomic<std::size_t> ws_clients_{0};
};

}  // namespace mocap::serve
