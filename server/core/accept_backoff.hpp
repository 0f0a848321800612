// accept_backoff.hpp — what every listener does when accept() fails (sinks, poses, live
// BVH, HTTP): count the failure, log it at most once per interval, and try again after a
// pause instead of at once.
//
// Why: EMFILE/ENFILE (no descriptor left), ENOBUFS and ENOMEM leave the connection in the
// listen queue, so the listening socket stays readable and an immediate retry fails again
// at once: the accept loop spun at 100 % CPU until a descriptor came free. With the pause
// it costs one failed accept per `pause` (10 a second by default), and the first accept
// after a descriptor is freed succeeds.
//
// Threading: on_error() and cancel() on the thread that runs the acceptor's executor (the
// timer is bound to it); the error counter may be read from any thread.
// Header-only: it needs Asio and spdlog, which mocap_core itself does not link; ingest and
// serve, which use it, do.
#pragma once

#include <spdlog/spdlog.h>

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <utility>

#include "core/asio.hpp"
#include "core/counters.hpp"

namespace mocap {

class AcceptBackoff {
public:
    /// `service` prefixes the log line ("sink listener", "http"). `errors` counts every
    /// failed accept and must outlive this object.
    AcceptBackoff(const asio::any_io_executor& executor, std::string service, Counter& errors,
                  std::chrono::milliseconds pause = std::chrono::milliseconds(100),
                  std::chrono::milliseconds log_interval = std::chrono::seconds(10))
        : timer_(executor), service_(std::move(service)), errors_(errors), pause_(pause), log_interval_(log_interval) {}

    /// Counts `ec`, logs it (the first one, then one line per interval with the number of
    /// failures since the last line) and calls `retry` after the pause. Not called for
    /// operation_aborted (the acceptor was closed).
    void on_error(const boost::system::error_code& ec, std::function<void()> retry) {
        errors_.add();
        ++unlogged_;
        const auto now = std::chrono::steady_clock::now();
        if (!logged_once_ || now - last_log_ >= log_interval_) {
            spdlog::warn("{}: accept: {} ({} failed accepts since the last line; retrying every {} ms)", service_,
                         ec.message(), unlogged_, pause_.count());
            logged_once_ = true;
            last_log_ = now;
            unlogged_ = 0;
        }
        timer_.expires_after(pause_);
        timer_.async_wait([retry = std::move(retry)](const boost::system::error_code& wait_ec) {
            if (!wait_ec) retry();
        });
    }

    /// Drops a pending retry (at stop()).
    void cancel() { timer_.cancel(); }

private:
    asio::steady_timer timer_;
    std::string service_;
    Counter& errors_;
    std::chrono::milliseconds pause_;
    std::chrono::milliseconds log_interval_;
    std::chrono::steady_clock::time_point last_log_{};
    std::uint64_t unlogged_ = 0;
    bool logged_once_ = false;
};

}  // namespace mocap
