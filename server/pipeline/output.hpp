// output.hpp — what the pipeline hands its results to: one interface for every consumer of
// skeleton frames (pose service, live BVH, web endpoint, BVH recorder, joint-angle CSV) and
// of raw samples (raw recorder). docs/outputs.md lists them and how each is registered.
//
// Threads:
//   set-up thread   construction, start(), stop() (stop only after the assembler thread
//                   and ingest have stopped: no call below runs concurrently with it)
//   assembler       on_frame(), once per solved subject frame, in SYNC order per subject.
//                   Must not block: it delays every other output and the next frame.
//   ingest          on_sample(), for every sample as it arrives (before routing drops
//                   unknown nodes), only if wants_samples() is true.
//   any thread      the health hooks (port, last_frame_us) and the readers registered by
//                   register_metrics(): read atomics or counters only.
// In the synchronous (replay) mode on_frame and on_sample run on the caller's thread.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/frame.hpp"
#include "core/heartbeat.hpp"
#include "core/imu_sample.hpp"
#include "core/metrics_registry.hpp"
#include "skeleton/skeleton_pose.hpp"

namespace mocap::pipeline {

class Output {
public:
    virtual ~Output() = default;

    /// Short stable name ("pose", "bvh_live", ...): logs and lookups.
    [[nodiscard]] virtual std::string_view name() const = 0;

    /// Set-up thread, before samples flow: binds sockets, opens files. False + *error stops
    /// the daemon from starting (an output that is only an aid logs and returns true).
    virtual bool start(std::string* error) = 0;

    /// Set-up thread, after the last frame: closes sockets, finishes files. False + *error
    /// when a file could not be completed (replay reports it; the daemon logs it).
    virtual bool stop(std::string* error) = 0;

    /// Assembler thread: one solved frame. Valid only during the call.
    virtual void on_frame(const SubjectFrame& frame, const skeleton::SkeletonPose& pose) = 0;

    /// Whether on_sample() wants every raw sample (the raw recorder); asked once at set-up.
    [[nodiscard]] virtual bool wants_samples() const { return false; }
    /// Ingest thread: one sample as received. Must not block.
    virtual void on_sample(const SegmentSample& /*sample*/) {}

    /// Set-up thread, once, after construction: registers this output's counters and gauges
    /// (read later from any thread) in the daemon's registry, which the Stats reply,
    /// /metrics and the periodic log line render.
    virtual void register_metrics(MetricsRegistry& /*registry*/) const {}

    // Health (any thread).
    /// The TCP port it listens on (0 = none): tests and logs.
    [[nodiscard]] virtual std::uint16_t port() const { return 0; }
    /// Wall clock µs of the last frame it delivered to a client (0 = none or not tracked):
    /// the health check's "samples arrive but no frame goes out".
    [[nodiscard]] virtual std::int64_t last_frame_us() const { return 0; }
    /// Set-up thread, after start(): the heartbeats of the threads this output runs that
    /// must make progress (core/heartbeat.hpp); /healthz and the watchdog watch them.
    [[nodiscard]] virtual std::vector<Heartbeat> heartbeats() const { return {}; }
};

}  // namespace mocap::pipeline
