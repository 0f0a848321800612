// heartbeat_monitor.hpp — which of the threads that must make progress has stopped: the
// ingest thread, every pipeline worker and every pose serve thread beat a counter on each
// turn of their loops, idle or busy (core/heartbeat.hpp); a counter that has not moved for
// the window names its thread in /healthz's 503 and withholds the systemd watchdog ping
// (issue 24, item 7; before, a thread frozen alone left /healthz at 200).
//
// The monitor remembers, per counter, the value it saw last and when (steady clock, µs)
// it last saw it move; it learns only when asked, so every caller (the /healthz handler, the
// assembler thread's watchdog hook every ~50 ms) refreshes it.
// Threads: add() at set-up, before any caller; stale() from any thread (one mutex).
#pragma once

#include <cstdint>
#include <mutex>
#include <string>
#include <vector>

#include "core/heartbeat.hpp"

namespace mocap::daemon {

class HeartbeatMonitor {
public:
    void add(Heartbeat heartbeat);
    /// The names of the threads whose counter has not moved for more than `window_us` up to
    /// `now_us`, joined with ", "; "" when every thread made progress.
    [[nodiscard]] std::string stale(std::int64_t now_us, std::int64_t window_us);
    [[nodiscard]] std::size_t size() const { return parts_.size(); }

private:
    struct Part {
        Heartbeat heartbeat;
        std::uint64_t seen = 0;
        std::int64_t moved_us = -1;  ///< -1: not looked at yet
    };
    std::mutex mutex_;
    std::vector<Part> parts_;  // guarded once callers run
};

}  // namespace mocap::daemon
