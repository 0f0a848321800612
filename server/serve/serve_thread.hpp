// serve_thread.hpp — one serve thread with its own io_context and a TCP acceptor whose
// connection slots follow core/connection_slots.hpp: what the live BVH server and the HTTP
// server share (each keeps its own session table and sessions).
//
// start() binds through listen_tcp (same error text as every service, prefixed with
// "<service>: "), runs the io_context on a thread called `thread_name` and logs
// "<service>: <serves> on <address>:<port>". Accept loop, on the serve thread: the slot
// table decides (docs/security.md, "Connection slots"). Refused (per-address limit, or the
// port full of connections that all make progress) the new socket is closed at once and
// counted in `refused_per_address` / `rejected_full`. Admitted, it is counted in
// `accepted`; if it took the slot of a connection that had not proven itself or had
// stalled longest, `evict` closes that one (counted in `evicted`). The socket gets
// TCP_NODELAY (poses are small and urgent) and a bounded SO_SNDBUF (send_buffer_bytes:
// the kernel would otherwise hoard MiBs for a reader that stalls, while the session's
// drop-oldest queue drops nothing), then goes to `admit`, which starts a session whose id
// is the slot's id. A failed accept (EMFILE...) is counted in `accept_errors` and retried
// after a pause (core/accept_backoff.hpp). Sessions report progress on their slot and call
// release(id) when they close. stop() closes the acceptor, calls `close_all` and stops
// the io_context, all on the serve thread, then joins it.
//
// The pose server (pose_server.cpp) keeps its own accept loop on purpose: it spreads
// clients round-robin over several threads and writes a Goodbye to a refused client; it
// uses the same slot table and back-off.
//
// Thread-safety: start()/stop() from the owning thread; running() and port() from any
// thread; the hooks and release() run on the serve thread only. Ownership: the server owns
// this object and declares it before its sessions, which use io(), so they go first.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "core/accept_backoff.hpp"
#include "core/asio.hpp"
#include "core/connection_slots.hpp"
#include "core/counters.hpp"

namespace mocap::serve {

class ServeThread {
public:
    struct Counters {
        Counter& accepted;
        Counter& rejected_full;
        Counter& refused_per_address;
        Counter& evicted;
        Counter& accept_errors;
    };
    struct Names {
        std::string service;      ///< prefix of the log line and errors: "bvh", "http"
        std::string thread_name;  ///< at most 15 characters: "mocap-bvh"
        std::string serves;       ///< what the start-up line says is served: "live BVH"
    };
    using SlotPtr = std::shared_ptr<ConnectionSlots::Slot>;
    struct Hooks {
        /// Start a session on `socket`; its id is slot->id(), and it reports progress on `slot`.
        std::function<void(asio::ip::tcp::socket socket, SlotPtr slot)> admit;
        std::function<void(std::uint64_t id)> evict;  ///< close session `id` (its slot is taken)
        std::function<void()> close_all;              ///< at stop()
    };
    struct Options {
        SlotPolicy slots;                              ///< max_clients and the [limits] of the port
        std::uint32_t send_buffer_bytes = 128 * 1024;  ///< SO_SNDBUF per connection; 0 = kernel default
    };

    ServeThread(Names names, const Options& options, const Counters& counters, Hooks hooks);
    /// Calls stop().
    ~ServeThread();
    ServeThread(const ServeThread&) = delete;
    ServeThread& operator=(const ServeThread&) = delete;

    /// Binds bind_address:port and starts the thread. False with `error` set on failure
    /// (e.g. "bvh: bind 0.0.0.0:7002: Address already in use"). Call once.
    [[nodiscard]] bool start(const std::string& bind_address, std::uint16_t port, std::string& error);
    /// Closes the acceptor and every session, joins the thread. Idempotent.
    void stop();

    /// Serve thread: session `id` closed; frees its slot (no-op for an evicted one).
    void release(std::uint64_t id) { slots_.release(id); }
    /// The clock of Slot::progress() (steady, µs).
    [[nodiscard]] static std::int64_t now_us();

    [[nodiscard]] asio::io_context& io() { return io_; }
    [[nodiscard]] bool running() const { return running_.load(std::memory_order_relaxed); }
    /// The bound port (useful with port 0); 0 before start().
    [[nodiscard]] std::uint16_t port() const { return bound_port_.load(); }

private:
    void do_accept();
    void on_accept(const boost::system::error_code& ec, asio::ip::tcp::socket socket);
    void log_refusal(const char* what, const std::string& ip);

    Names names_;
    Options options_;
    Counters counters_;
    Hooks hooks_;
    ConnectionSlots slots_;
    asio::io_context io_{1};
    std::unique_ptr<asio::ip::tcp::acceptor> acceptor_;
    AcceptBackoff backoff_;
    std::thread thread_;
    std::chrono::steady_clock::time_point last_refusal_log_{};
    std::uint64_t refusals_unlogged_ = 0;
    bool refusal_logged_ = false;
    std::atomic<std::uint16_t> bound_port_{0};
    std::atomic<bool> running_{false};
};

}  // namespace mocap::serve
