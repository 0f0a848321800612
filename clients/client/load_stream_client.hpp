// load_stream_client.hpp — `mocap-client load --protocol bvh|ws`: the load tool's clients
// of the live BVH port and the viewer WebSocket (/ws), so the fan-out of those ports is
// measured the way the pose stream's is (load_client.hpp: one epoll loop, N sockets,
// exact percentiles, the same LoadResult).
//
// WebSocket: frames carry `sync` and `stamps.sink_send_us`, so latency (sink send → the
// read here, one host clock) and gaps (SYNC jumps beyond 1, per subject) are exact, and
// `drops` messages are summed. The subject is the first `--subject` (0 = the server's
// choice); the handshake is plain HTTP/1.1 (no extensions), messages are not masked by
// the server, fragmented ones are joined.
// Live BVH: a MOTION line has no timestamp and no frame number. Each distinct line gets the
// time and index of its first arrival on any client of the run; a client's latency is its
// arrival minus that first arrival — the fan-out spread, what serve threads change — and a
// client's gap is an index jump beyond 1. So every client must receive the same lines: a
// line only some clients get (a subject's line sent before "subject <id>", which the tool
// sends at connect, took effect: start mocapd with that [outputs] bvh_subject) or two
// identical lines (a subject that does not move at all) make the gap count wrong; the
// server's drop counters (bvh_live.frames_dropped, backlog_dropped) are the authority.
// Thread-safety: run_stream_load() is self-contained; call from one thread.
#pragma once

#include "load_client.hpp"

namespace mocap::client {

/// options.protocol is "bvh" or "ws"; stalled and churn clients are not supported (an error).
LoadResult run_stream_load(const LoadOptions& options);

}  // namespace mocap::client
