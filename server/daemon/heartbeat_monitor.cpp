// heartbeat_monitor.cpp — counters that stopped moving (heartbeat_monitor.hpp).
#include "daemon/heartbeat_monitor.hpp"

#include <utility>

namespace mocap::daemon {

void HeartbeatMonitor::add(Heartbeat heartbeat) {
    std::lock_guard lock(mutex_);
    parts_.push_back({std::move(heartbeat)});
}

std::string HeartbeatMonitor::stale(std::int64_t now_us, std::int64_t window_us) {
    std::lock_guard lock(mutex_);
    std::string out;
    for (Part& p : parts_) {
        const std::uint64_t beats = p.heartbeat.beats->load(std::memory_order_relaxed);
        if (p.moved_us < 0 || beats != p.seen || now_us < p.moved_us) {
            p.seen = beats;
            p.moved_us = now_us;
        } else if (now_us - p.moved_us > window_us) {
            out += (out.empty() ? "" : ", ") + p.heartbeat.name;
        }
    }
    return out;
}

}  // namespace mocap::daemon
