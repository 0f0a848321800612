// nats_load_client.hpp — `mocap-client --nats URL load`: what `load` measures against the pose
// service (load_client.hpp), measured through a NATS cluster instead: N NATS connections,
// each subscribed to the site's pose subjects (all, or one subscription per --subject), for
// `duration`. Frames, gaps (SYNC jumps beyond the decimation, applied here as NatsPoseClient
// does), frames the client library dropped for a slow reader, and the latency from a frame's
// sink_send_us to its delivery here, so the NATS path and the direct path compare side by
// side (docs/cluster.md, "Measured").
//
// Each connection is a libnats connection with its own socket and reader thread; their
// message callbacks run on a shared delivery pool of two threads. A few hundred connections
// per process is practical; for more, run several processes.
#pragma once

#include "load_client.hpp"
#include "nats_pose_client.hpp"

namespace mocap::client {

LoadResult run_nats_load(const NatsOptions& nats, const LoadOptions& options);

}  // namespace mocap::client
