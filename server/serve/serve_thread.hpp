// serve_thread.hpp — the serve thread(s) of one port: `threads` lanes, each an io_context
// run by its own thread, and a TCP acceptor (on lane 0) whose connection slots follow
// core/connection_slots.hpp: what the live BVH server and the HTTP server share (each keeps
// its own session table and sessions per lane).
//
// start() binds through listen_tcp (same error text as every service, prefixed with
// "<service>: "), runs each lane's io_context on a thread called `thread_name` (one lane)
// or `thread_name`-<lane> (several) and logs "<service>: <serves> on <address>:<port>".
// Accept loop, on lane 0's thread: the slot table (one for the port, shared by the
// lanes) decides (docs/security.md, "Connection slots"). Refused (per-address limit, or the
// port full of connections that all make progress) the new socket is closed at once and
// counted in `refused_per_address` / `rejected_full`. Admitted, it is counted in
// `accepted`; if it took the slot of a connection that had not proven itself or had
// stalled longest, `evict` closes that one (counted in `evicted`). The socket gets
// TCP_NODELAY (poses are small and urgent) and a bounded SO_SNDBUF (send_buffer_bytes:
// the kernel would otherwise hoard MiBs for a reader that stalls, while the session's
// drop-oldest queue drops nothing), then goes to `admit` on the lane whose turn it is
// (round-robin; a client stays on its lane), which starts a session whose id is the
// slot's id. With one lane `admit` and `evict` run inline, as before there were lanes;
// with several, `admit` is posted to the chosen lane and `evict` to every lane (only
// the victim's own lane finds it in its table; lane 0 inline). A failed accept (EMFILE...) is counted in
// `accept_errors` and retried after a pause (core/accept_backoff.hpp). Sessions report progress on their slot and call
// release(id) when they close. stop() closes the acceptor (on lane 0), and on every lane
// calls `close_all(lane)` and stops its io_context, then joins the threads.
//
// The pose server (pose_server.cpp) keeps its own accept loop on purpose: it writes a
// Goodbye to a refused client; it uses the same slot table, back-off and round-robin.
//
// Thread-safety: start()/stop() from the owning thread; running(), port() and lanes() from
// any thread; the hooks run on the thread of the lane they name (evict's and admit's lane);
// release() from any lane (the slot table locks). Ownership: the server owns this object
// and declares it before its sessions, which use io(lane), so they go first.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "core/accept_backoff.hpp"
#include "core/asio.hpp"
#include "core/connection_slots.hpp"
#include "core/counters.hpp"
#include "serve/connection_counters.hpp"

namespace mocap::serve {

class ServeThread {
public:
    struct Names {
        std::string service;      ///< prefix of the log line and errors: "bvh", "http"
        std::string thread_name;  ///< at most 15 characters: "mocap-bvh"
        std::string serves;       ///< what the start-up line says is served: "live BVH"
    };
    using SlotPtr = std::shared_ptr<ConnectionSlots::Slot>;
    struct Hooks {
        /// On lane `lane`: start a session on `socket` (bound to io(lane)); its id is
        /// slot->id(), and it reports progress on `slot`.
        std::function<void(std::size_t lane, asio::ip::tcp::socket socket, SlotPtr slot)> admit;
        /// On lane `lane`: close session `id` if it is that lane's (its slot is taken).
        std::function<void(std::size_t lane, std::uint64_t id)> evict;
        std::function<void(std::size_t lane)> close_all;  ///< at stop(), on each lane
    };
    struct Options {
        SlotPolicy slots;                              ///< max_clients and the [limits] of the port
        std::uint32_t send_buffer_bytes = 128 * 1024;  ///< SO_SNDBUF per connection; 0 = kernel default
        std::size_t threads = 1;                       ///< lanes (0 is taken as 1)
    };

    /// `counters` (the server's; this object counts all but `closed`) must outlive it.
    ServeThread(Names names, const Options& options, ConnectionCounters& counters, Hooks hooks);
    /// Calls stop().
    ~ServeThread();
    ServeThread(const ServeThread&) = delete;
    ServeThread& operator=(const ServeThread&) = delete;

    /// Binds bind_address:port and starts the thread. False with `error` set on failure
    /// (e.g. "bvh: bind 0.0.0.0:7002: Address already in use"). Call once.
    [[nodiscard]] bool start(const std::string& bind_address, std::uint16_t port, std::string& error);
    /// Closes the acceptor and every session, joins the threads. Idempotent.
    void stop();

    /// Serve thread: session `id` closed; frees its slot (no-op for an evicted one).
    void release(std::uint64_t id) { slots_.release(id); }
    /// The clock of Slot::progress() (steady, µs).
    [[nodiscard]] static std::int64_t now_us();

    [[nodiscard]] asio::io_context& io(std::size_t lane) { return lanes_[lane]->io; }
    [[nodiscard]] std::size_t lanes() const { return lanes_.size(); }
    /// Every lane's io_context, in lane order (for a PublishBacklog).
    [[nodiscard]] std::vector<asio::io_context*> ios() {
        std::vector<asio::io_context*> out;
        for (auto& lane : lanes_)
            out.push_back(&lane->io);
        return out;
    }
    [[nodiscard]] bool running() const { return running_.load(std::memory_order_relaxed); }
    /// The bound port (useful with port 0); 0 before start().
    [[nodiscard]] std::uint16_t port() const { return bound_port_.load(); }

private:
    void do_accept();
    void on_accept(const boost::system::error_code& ec, asio::ip::tcp::socket socket);
    void evict(std::uint64_t id);
    void log_refusal(const char* what, const std::string& ip);

    Names names_;
    Options options_;
    ConnectionCounters& counters_;
    Hooks hooks_;
    struct Lane {
        asio::io_context io{1};
        std::thread thread;
    };

    ConnectionSlots slots_;
    std::vector<std::unique_ptr<Lane>> lanes_;
    std::unique_ptr<asio::ip::tcp::acceptor> acceptor_;  // lane 0
    AcceptBackoff backoff_;                              // lane 0
    std::size_t next_lane_ = 0;                          // lane 0 thread only
    std::chrono::steady_clock::time_point last_refusal_log_{};
    std::uint64_t refusals_unlogged_ = 0;
    bool refusal_logged_ = false;
    std::atomic<std::uint16_t> bound_port_{0};
    std::atomic<bool> running_{false};
};

}  // namespace mocap::serve
