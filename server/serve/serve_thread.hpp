// serve_thread.hpp — one serve thread with its own io_context and a TCP acceptor that
// admits at most max_clients connections at once: what the live BVH server and the
// HTTP server share (each keeps its own session table and sessions).
//
// start() binds through listen_tcp (same error text as every service, prefixed with
// "<service>: "), runs the io_context on a thread called `thread_name` and logs
// "<service>: <serves> on <address>:<port>". Accept loop, on the serve thread: when
// `open_clients()` is at max_clients the new socket is closed at once and counted in
// `rejected_full`; otherwise it is counted in `accepted`, gets TCP_NODELAY (poses are
// small and urgent) and goes to `admit`, which starts a session. Any other accept error
// is skipped and the next accept starts at once. stop() closes the acceptor, calls
// `close_all` and stops the io_context, all on the serve thread, then joins it.
//
// The pose server (pose_server.cpp) keeps its own accept loop on purpose: it spreads
// clients round-robin over several threads, writes a Goodbye to a refused client, logs
// refusals (rate-limited) and backs off after accept errors such as EMFILE.
//
// Thread-safety: start()/stop() from the owning thread; running() and port() from any
// thread; the hooks run on the serve thread only. Ownership: the server owns this
// object and declares it before its sessions, which use io(), so they go first.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "core/asio.hpp"
#include "core/counters.hpp"

namespace mocap::serve {

class ServeThread {
public:
    struct Counters {
        Counter& accepted;
        Counter& rejected_full;
    };
    struct Names {
        std::string service;      ///< prefix of the log line and errors: "bvh", "http"
        std::string thread_name;  ///< at most 15 characters: "mocap-bvh"
        std::string serves;       ///< what the start-up line says is served: "live BVH"
    };
    struct Hooks {
        std::function<std::size_t()> open_clients;                ///< connections open now
        std::function<void(asio::ip::tcp::socket socket)> admit;  ///< start a session
        std::function<void()> close_all;                          ///< at stop()
    };

    ServeThread(Names names, std::size_t max_clients, Counters counters, Hooks hooks);
    /// Calls stop().
    ~ServeThread();
    ServeThread(const ServeThread&) = delete;
    ServeThread& operator=(const ServeThread&) = delete;

    /// Binds bind_address:port and starts the thread. False with `error` set on failure
    /// (e.g. "bvh: bind 0.0.0.0:7002: Address already in use"). Call once.
    [[nodiscard]] bool start(const std::string& bind_address, std::uint16_t port, std::string& error);
    /// Closes the acceptor and every session, joins the thread. Idempotent.
    void stop();

    [[nodiscard]] asio::io_context& io() { return io_; }
    [[nodiscard]] bool running() const { return running_.load(std::memory_order_relaxed); }
    /// The bound port (useful with port 0); 0 before start().
    [[nodiscard]] std::uint16_t port() const { return bound_port_.load(); }

private:
    void do_accept();
    void on_accept(const boost::system::error_code& ec, asio::ip::tcp::socket socket);

    Names names_;
    std::size_t max_clients_;
    Counters counters_;
    Hooks hooks_;
    asio::io_context io_{1};
    std::unique_ptr<asio::ip::tcp::acceptor> acceptor_;
    std::thread thread_;
    std::atomic<std::uint16_t> bound_port_{0};
    std::atomic<bool> running_{false};
};

}  // namespace mocap::serve
