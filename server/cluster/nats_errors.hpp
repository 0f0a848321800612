// nats_errors.hpp — what a NATS server says about one connection only asynchronously: a
// publish or a subscription its user may not make ("Permissions Violation for Publish to
// \"$KV.mocap_calibration.venue.1\""). The server drops such a publish and sends -ERR; the
// client reports it to the connection's error handler only, so a JetStream put that waits
// for its acknowledgement just times out. This keeps the refusal, counts it and logs each
// distinct text once, so a timed-out request can be named for what it is (docs/cluster.md,
// "What happens when things fail").
//
// Threads: install() at set-up; the NATS client's callback thread calls the handler;
// take_violation() from the connection owner's thread. A mutex guards the text.
#pragma once

#include <cstddef>
#include <mutex>
#include <set>
#include <string>
#include <utility>

#include "core/counters.hpp"

struct __natsOptions;  // NOLINT(bugprone-reserved-identifier): libnats names its types so

namespace mocap::cluster {

class NatsErrors {
public:
    /// who: how the log names the connection ("cluster publisher", "calibration bucket ...").
    explicit NatsErrors(std::string who) : who_(std::move(who)) {}

    /// Sets the options' error handler to this (which must outlive every connection made
    /// with them).
    void install(__natsOptions* options);
    /// The connection's last permission violation since the previous call ("" none).
    std::string take_violation();
    /// Permission violations the server reported on the connection.
    [[nodiscard]] const Counter& permission_errors() const { return permission_errors_; }

    /// The client's error callback (public for the C callback adapter only).
    void on_error(int status, const char* text);

private:
    static constexpr std::size_t kLoggedTexts = 64;  // distinct texts logged, then counted only
    std::string who_;
    std::mutex mutex_;
    std::string violation_;         // guarded by mutex_
    std::set<std::string> logged_;  // guarded by mutex_
    Counter permission_errors_;
};

}  // namespace mocap::cluster
