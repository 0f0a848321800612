// connection_counters.hpp — the connection counters every TCP service of serve/ keeps (pose
// service, live BVH, HTTP), under the same names in each service's counter group
// (docs/style.md, "Counters only go up"). The accept path counts the first five
// (serve_thread.hpp, pose_server.cpp), the session tables count `closed` (session_table.hpp).
//
// Thread-safety: core/counters.hpp Counters, added to from any serve thread.
#pragma once

#include "core/counters.hpp"

namespace mocap::serve {

struct ConnectionCounters {
    Counter accepted;
    Counter rejected_full;        ///< every slot held by a client making progress
    Counter refused_per_address;  ///< the port's per-address limit ([limits] <port>_per_address) reached
    Counter evicted;              ///< closed to give their slot to a new client
    Counter closed;
    Counter accept_errors;  ///< failed accepts (EMFILE...), retried after a pause

    /// Set-up: adds the six to the service's group as connections_accepted,
    /// connections_rejected_full, connections_refused_per_address, connections_evicted,
    /// connections_closed and accept_errors.
    void register_in(CounterGroup& group) const {
        group.add("connections_accepted", accepted);
        group.add("connections_rejected_full", rejected_full);
        group.add("connections_refused_per_address", refused_per_address);
        group.add("connections_evicted", evicted);
        group.add("connections_closed", closed);
        group.add("accept_errors", accept_errors);
    }
};

}  // namespace mocap::serve
