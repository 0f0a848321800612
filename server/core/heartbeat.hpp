// heartbeat.hpp — a thread that must make progress says so by adding one to a counter on
// every turn of its loop, busy or idle (an idle thread wakes at least every few hundred ms
// to do it). The daemon watches the counters (daemon/heartbeat_monitor.hpp): one that stops
// moving names a thread that is stuck or frozen, for /healthz and the systemd watchdog.
// A count, not a time, so that no thread below the daemon reads a clock (docs/style.md,
// "Inject time").
// Threads: the owning thread increments (relaxed); any thread reads.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>

namespace mocap {

/// One watched thread: its name as /healthz shows it and its counter (owned by the
/// component that runs the thread, which outlives the watcher's use of it).
struct Heartbeat {
    std::string name;
    const std::atomic<std::uint64_t>* beats = nullptr;
};

}  // namespace mocap
