// control_access.hpp — who may send control requests (calibrate, record, reload), shared
// by the pose service (ClientSession) and HTTP (POST /api/...), so both apply the same
// rules in the same order and count refusals the same way (docs/security.md):
//
//   1. no token configured          -> refused ("control disabled (no token configured)")
//   2. loopback_only and the peer is not on loopback (IPv4 127/8, ::1, or ::ffff:127.x)
//                                   -> refused ("control only from loopback")
//   3. no token given               -> refused ("token required")
//   4. the peer's address, or all peers together, failed too often lately
//                                   -> refused without comparing ("too many failed control
//                                      attempts, try again later")
//   5. token differs (compared in constant time) -> refused ("bad token"), charged to the
//      peer's address and to the global limit (ControlAttemptLimiter below)
//
// The address rule comes before the token check so a remote peer learns nothing about
// the token. Rule 4 makes guessing slow whatever the attacker does with connections: the
// limits belong to addresses, not connections, and the daemon shares one limiter between
// the pose service and HTTP (docs/security.md, "Guessing the token"). Counters only go up (docs/style.md, "Counters
// only go up"); each owner exposes them under its own prefix (serve.control_*, http.control_*), names that dashboards
// depend on.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/asio.hpp"
#include "core/counters.hpp"
#include "serve/serve_config.hpp"

namespace mocap::serve {

class LogLimiter;

/// Constant-time token comparison (time depends only on the longer length).
bool token_equal(std::string_view expected, std::string_view given);

/// True for IPv4 and IPv6 loopback, including IPv4 loopback mapped into IPv6.
bool is_loopback(const asio::ip::address& address);

/// The connected peer is on loopback; false when the peer is unknown (socket closed).
bool peer_on_loopback(const asio::ip::tcp::socket& socket);

/// The connected peer's address; nullopt when it is unknown (socket closed).
std::optional<asio::ip::address> remote_address(const asio::ip::tcp::socket& socket);

/// Limits on FAILED control attempts (a token given, and wrong): token buckets that hold
/// failures, one per peer address and one for all peers together. The defaults let an
/// operator who mistypes fail 5 times at once and then once per 2 s, and everybody
/// together 20 times at once and then 2 per second (docs/security.md has what each costs).
struct ControlAttemptLimits {
    double per_address_burst = 5.0;
    double per_address_per_s = 0.5;
    double global_burst = 20.0;
    double global_per_s = 2.0;
    std::size_t max_addresses = 256;  ///< table size; IPv6 peers count by their /64
};

/// The buckets. Thread-safe (one mutex, taken only by control requests that reach the
/// token check). A comparison needs a failure in hand in the peer's bucket and in the
/// global one; it reserves both before comparing and gives them back when the token was
/// right, so the right token costs nothing. The table is bounded: when it is full, the
/// entry with the most failures in hand (the least suspect) makes room; an attacker with
/// many addresses gains fresh buckets that way, and still meets the global one.
class ControlAttemptLimiter {
public:
    /// `now_us`: a monotonic clock in µs (tests inject a manual one); empty = steady_clock.
    explicit ControlAttemptLimiter(const ControlAttemptLimits& limits = {}, std::function<std::int64_t()> now_us = {});

    /// Reserves one failure of `peer`'s bucket and of the global one; false (nothing
    /// reserved) when either is empty: refuse without comparing.
    [[nodiscard]] bool try_begin(const asio::ip::address& peer);
    /// The token was right: gives back what try_begin() reserved.
    void succeeded(const asio::ip::address& peer);

    [[nodiscard]] std::size_t tracked_addresses() const;
    [[nodiscard]] const ControlAttemptLimits& limits() const { return limits_; }

    /// One peer's key in the table: an IPv4 address (also mapped into IPv6) as ::ffff:a.b.c.d,
    /// an IPv6 address by its /64 (the block one host usually holds). Shared with the
    /// pose service's per-address request budget (address_budget.hpp).
    using Key = std::array<std::uint8_t, 16>;
    static Key key_of(const asio::ip::address& peer);

private:
    /// A token bucket kept as one time (the generic cell rate algorithm, in integer µs, so
    /// nothing drifts): every failure moves `full_at_us` one interval later; a failure is
    /// in hand while full_at_us lies less than (burst - 1) intervals after now.
    struct Bucket {
        std::int64_t full_at_us = 0;
    };
    struct Rate {
        std::int64_t interval_us;  ///< one failure comes back per interval
        std::int64_t window_us;    ///< burst x interval
    };
    static Rate rate(double burst, double per_s);
    static bool in_hand(const Bucket& bucket, const Rate& rate, std::int64_t now_us);
    Bucket* lookup(const Key& key);
    Bucket& insert(const Key& key, std::int64_t now_us);

    ControlAttemptLimits limits_;
    Rate per_address_;
    Rate global_rate_;
    std::function<std::int64_t()> now_us_;
    mutable std::mutex mutex_;
    std::vector<std::pair<Key, Bucket>> table_;  ///< at most max_addresses, scanned linearly
    Bucket global_;
};

struct ControlCounters {
    Counter ok;
    Counter failed;            ///< authorised, but the action reported an error
    Counter refused_disabled;  ///< no token configured
    Counter refused_not_loopback;
    Counter refused_no_token;
    Counter refused_bad_token;
    Counter refused_throttled;  ///< too many failed attempts lately: refused without comparing

    /// Set-up: adds every counter to the server's group as "control_<name>".
    void register_in(CounterGroup& group) const;
    /// Counts an authorised request's outcome in ok or failed.
    void count_result(const ControlResult& result);
};

struct ControlPolicy {
    std::string_view token;  ///< empty = every control request is refused
    bool loopback_only = true;
    ControlAttemptLimiter* attempts = nullptr;  ///< failed-attempt limits (the servers always set one)
};

struct ControlRefusal {
    enum Kind { kDisabled, kNotLoopback, kNoToken, kBadToken, kThrottled } kind;
    const char* reason;  ///< shown to the client
};

/// Applies the rules above. nullopt = authorised; otherwise the refusal, already counted
/// and logged through `log` as "<who> refused: <reason>", one line per interval (`who`
/// e.g. "http: control request /api/calibrate"; tests count those lines).
/// `peer`: the request's peer address (nullopt = unknown: not loopback, limited as "::").
std::optional<ControlRefusal> authorize_control(const ControlPolicy& policy,
                                                const std::optional<asio::ip::address>& peer,
                                                std::string_view given_token, ControlCounters& counters,
                                                LogLimiter& log, std::string_view who);

}  // namespace mocap::serve
