// pose_server.hpp — the protobuf pose service (TCP, default port 7001).
//
// How the daemon uses it:
//
//   serve::PoseServer server(config, handlers);   // ServeConfig + ControlHandlers
//   server.set_description(description);          // segments, joint names, subjects
//   std::string error;
//   if (!server.start(error)) { ... }             // binds, starts io_threads threads
//   ... assembler thread, per subject frame:
//   server.publish(subject_frame, skeleton_pose); // encode once, fan out, never blocks
//   ... on SIGTERM:
//   server.stop();                                // closes every client, joins threads
//
// Threads: start() runs `io_threads` serve threads, each with its own io_context (a
// "lane"). Lane 0 also runs the acceptor; accepted clients are spread round-robin over
// the lanes and stay on theirs (see client_session.hpp for one client's model).
// Control and stats callbacks run on serve threads. publish() may be called from any
// thread; set_description() too (clients connecting later see the new Hello).
//
// Metrics: counters() for tests; register_metrics() puts them in the daemon's registry, which
// the Stats reply renders (a server without a stats handler answers with its own counters).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "core/asio.hpp"
#include "core/frame.hpp"
#include "core/heartbeat.hpp"
#include "core/metrics_registry.hpp"
#include "serve/client_session.hpp"
#include "serve/pose_broadcaster.hpp"
#include "serve/request_budget.hpp"
#include "serve/serve_config.hpp"
#include "serve/serve_counters.hpp"
#include "serve/serve_thread.hpp"
#include "skeleton/skeleton_pose.hpp"

namespace mocap::serve {

class PoseServer {
public:
    explicit PoseServer(ServeConfig config, ControlHandlers handlers = {});
    /// Calls stop().
    ~PoseServer();
    PoseServer(const PoseServer&) = delete;
    PoseServer& operator=(const PoseServer&) = delete;

    /// Any thread. Builds the Hello that clients connecting from now on receive.
    void set_description(const ServeDescription& description);

    /// Binds bind_address:port and starts the serve threads. On failure returns false
    /// and sets `error` (e.g. "bind 0.0.0.0:7001: Address already in use"). Call once.
    [[nodiscard]] bool start(std::string& error);

    /// Closes the acceptor and every client, joins the serve threads. Idempotent.
    void stop();

    /// The bound port (useful with port 0); 0 before start().
    [[nodiscard]] std::uint16_t port() const { return bound_port_.load(); }

    /// Any thread; see PoseBroadcaster::publish.
    void publish(const SubjectFrame& frame, const skeleton::SkeletonPose& pose) { broadcaster_->publish(frame, pose); }

    /// Connected clients (including ones still handshaking).
    [[nodiscard]] std::size_t client_count() const { return active_clients_.load(); }
    [[nodiscard]] const ServeCounters& counters() const { return counters_; }
    /// Set-up: counter group "serve" and gauge "pose_clients" (logged as "clients").
    void register_metrics(MetricsRegistry& registry) const;
    [[nodiscard]] const ServeConfig& config() const { return config_; }
    /// Set-up: one heartbeat per serve thread ("pose serve thread N"), beating at least
    /// every 250 ms while the thread runs its io_context (core/heartbeat.hpp).
    [[nodiscard]] std::vector<Heartbeat> heartbeats() const;

private:
    struct Lane {
        asio::io_context io{1};
        RequestBudget requests;  ///< lane thread; declared after io, destroyed before it
        std::unordered_map<std::uint64_t, std::shared_ptr<ClientSession>> sessions;  // lane thread
        std::thread thread;
        asio::steady_timer beat_timer{io};    ///< lane thread: beats while no client does
        std::atomic<std::uint64_t> beats{0};  ///< heartbeat (core/heartbeat.hpp)
        explicit Lane(std::size_t requests_per_turn) : requests(io, requests_per_turn) {}
    };
    void beat(Lane& lane);

    void do_accept();
    void on_accept(const boost::system::error_code& ec, asio::ip::tcp::socket socket);
    void start_session(std::size_t lane, asio::ip::tcp::socket socket, ServeThread::SlotPtr slot);
    void reject(asio::ip::tcp::socket& socket, const std::string& goodbye);
    void evict(std::uint64_t id);
    void on_session_closed(std::size_t lane, std::uint64_t id);
    SharedBytes hello() const;

    ServeConfig config_;
    ControlHandlers handlers_;
    ServeCounters counters_;
    LogLimiter log_;

    mutable std::mutex hello_mutex_;
    SharedBytes hello_;
    SharedBytes goodbye_full_;
    SharedBytes goodbye_per_address_;
    SharedBytes goodbye_address_budget_;
    /// Requests per peer address across connections (address_budget.hpp); before the
    /// session context, which points at it.
    AddressBudget address_budget_{
        {static_cast<double>(config_.address_message_burst), config_.max_address_messages_per_s}};

    // Lanes (io_contexts) are declared before the broadcaster and the session context,
    // which refer to them, and destroyed after them.
    std::vector<std::unique_ptr<Lane>> lanes_;
    std::unique_ptr<PoseBroadcaster> broadcaster_;
    std::unique_ptr<SessionContext> session_context_;
    std::unique_ptr<asio::ip::tcp::acceptor> acceptor_;  // lane 0
    std::unique_ptr<AcceptBackoff> accept_backoff_;      // lane 0: pause after EMFILE and the like

    std::size_t next_lane_ = 0;                                               // lane 0 thread only
    ConnectionSlots slots_{SlotPolicy{config_.max_clients, config_.limits}};  // lane 0 admits; any lane releases
    std::atomic<std::size_t> active_clients_{0};
    std::atomic<std::uint16_t> bound_port_{0};
    std::atomic<bool> running_{false};
};

}  // namespace mocap::serve
