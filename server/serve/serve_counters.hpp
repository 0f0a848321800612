// serve_counters.hpp — counters of the pose service (docs/style.md, "Counters only go up") and a
// log limiter so that a flood of bad clients yields one log line per interval.
//
// Thread-safety: the counters are core/counters.hpp Counters, added to from any serve
// thread and the publishing thread; reads are not atomic across counters.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>

#include "serve/connection_counters.hpp"
#include "serve/control_access.hpp"
#include "serve/serve_config.hpp"

namespace mocap::serve {

struct ServeCounters {
    ConnectionCounters connections;  ///< connections_* and accept_errors (connection_counters.hpp)
    Counter frames_published;        ///< frames handed to publish()
    Counter frames_encoded;          ///< encodings (one per frame and field selection in use)
    Counter frames_sent;             ///< frame deliveries written to clients (sum over clients)
    Counter frames_dropped;          ///< oldest frames dropped from lagging clients' queues
    Counter backlog_dropped;         ///< frames dropped because a serve thread fell behind publish()
    Counter bytes_sent;
    Counter subscriptions;
    Counter malformed_messages;  ///< unparseable message or garbage length prefix
    Counter oversized_messages;  ///< length prefix above max_client_message_bytes
    Counter unknown_messages;    ///< parseable but no known body (newer client): ignored
    Counter idle_timeouts;       ///< no Subscribe/valid message within subscribe_timeout_ms
    Counter rate_limited;        ///< clients closed for sending too many messages
    /// Requests and connections refused because their address had no request in hand
    /// (address_budget.hpp): the connection closed with Goodbye(RATE_LIMITED).
    Counter address_rate_limited;
    Counter write_errors;
    Counter stats_requests;
    Counter subscribe_too_many_subjects;  ///< Subscribes naming more than max_subscribe_subjects
    Counter requests_deferred;            ///< requests that waited for their serve thread's next turn
    ControlCounters control;              ///< serve.control_* (control_access.hpp)

    /// Component "serve": every counter above by its member name, the connections' as
    /// connection_counters.hpp names them (the metrics registry's entry, core/metrics_registry.hpp).
    CounterGroup group{"serve"};

    ServeCounters();
};

/// Allows one log line per kind per interval and counts what it suppressed.
class LogLimiter {
public:
    enum Kind : std::size_t {
        kMalformed,
        kOversized,
        kIdle,
        kRateLimited,
        kControlRefused,
        kControlThrottled,
        kClientFull,
        kIoError,
        kOriginRefused,
        kHostRefused,
        kKinds
    };
    explicit LogLimiter(std::chrono::milliseconds interval = std::chrono::seconds(10))
        : interval_ms_(interval.count()) {}

    /// True if a line may be logged now; `suppressed` = lines held back since the last one.
    bool allow(Kind kind, std::uint64_t& suppressed) {
        const std::int64_t now =
            std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now().time_since_epoch())
                .count();
        std::int64_t last = last_ms_[kind].load(std::memory_order_relaxed);
        if (last != 0 && now - last < interval_ms_) {
            suppressed_[kind].fetch_add(1, std::memory_order_relaxed);
            return false;
        }
        if (!last_ms_[kind].compare_exchange_strong(last, now, std::memory_order_relaxed)) {
            suppressed_[kind].fetch_add(1, std::memory_order_relaxed);
            return false;
        }
        suppressed = suppressed_[kind].exchange(0, std::memory_order_relaxed);
        return true;
    }

private:
    std::int64_t interval_ms_;
    std::array<std::atomic<std::int64_t>, kKinds> last_ms_{};
    std::array<std::atomic<std::uint64_t>, kKinds> suppressed_{};
};

}  // namespace mocap::serve
