// peer_limits.hpp — the [limits] section of the config as one port's PeerLimits
// (core/connection_slots.hpp): the listeners of the daemon and of its outputs take it.
#pragma once

#include <cstdint>

#include "core/connection_slots.hpp"
#include "daemon/config.hpp"

namespace mocap::daemon {

/// `per_address` is the port's own key (sink_per_address, pose_per_address, ...).
inline PeerLimits peer_limits(const DaemonConfig& c, std::uint32_t per_address) {
    return PeerLimits{per_address, c.limits_on_loopback, c.stall_evict_s};
}

}  // namespace mocap::daemon
