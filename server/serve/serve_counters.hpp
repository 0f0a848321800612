// serve_counters.hpp — counters of the pose service (docs/style.md, "Counters only go up") and a
// log limiter so that a flood of bad clients yields one log line per interval.
//
// Thread-safety: all members are atomics, updated with relaxed ordering from any serve
// thread and the publishing thread; snapshots are not atomic across counters.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <vector>

#include "serve/control_access.hpp"
#include "serve/serve_config.hpp"

namespace mocap::serve {

struct ServeCounters {
    using C = std::atomic<std::uint64_t>;
    C connections_accepted{0};
    C connections_rejected_full{0};  ///< client limit reached
    C connections_closed{0};
    C accept_errors{0};
    C frames_published{0};  ///< frames handed to publish()
    C frames_encoded{0};    ///< encodings (one per frame and field selection in use)
    C frames_sent{0};       ///< frame deliveries written to clients (sum over clients)
    C frames_dropped{0};    ///< oldest frames dropped from lagging clients' queues
    C backlog_dropped{0};   ///< frames dropped because a serve thread fell behind publish()
    C bytes_sent{0};
    C subscriptions{0};
    C malformed_messages{0};  ///< unparseable message or garbage length prefix
    C oversized_messages{0};  ///< length prefix above max_client_message_bytes
    C unknown_messages{0};    ///< parseable but no known body (newer client): ignored
    C idle_timeouts{0};       ///< no Subscribe/valid message within subscribe_timeout_ms
    C rate_limited{0};        ///< clients closed for sending too many messages
    C write_errors{0};
    C stats_requests{0};
    ControlCounters control;  ///< serve.control_* (control_access.hpp)

    /// Every counter as "serve.<name>".
    [[nodiscard]] std::vector<NamedCounter> snapshot() const;
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
        kClientFull,
        kAcceptError,
        kIoError,
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
