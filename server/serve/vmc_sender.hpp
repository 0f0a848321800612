// vmc_sender.hpp — the VMC output: one subject's frames as OSC bundles over UDP to a list
// of receivers (VSeeFace, Warudo, EVMC4U, VMC4UE, Blender add-ons; docs/outputs.md, "VMC (live
// link to Unity, Blender, VTuber apps)"). Rig and axes: serve/vmc_rig.hpp; bundle: serve/vmc_osc.hpp.
//
// Subject: the configured `subject`, or with 0 the subject of the first frame published.
// Threads:
//   producer (the assembler thread)  publish(): copies the frame's pose into a bounded SPSC
//       ring (core/spsc_ring.hpp) and wakes the sender; no lock, no allocation, no I/O. A full
//       ring drops the frame and counts it (frames_dropped): the sender, not the pipeline, lags.
//   the sender thread ("mocap-vmc", started by start())  resolves the destinations (getaddrinfo
//       may block: it runs here, never on the pipeline), converts and encodes each frame once
//       and send()s the same bytes on one connected non-blocking UDP socket per destination.
//       A destination that does not resolve or cannot be opened (a broadcast address) is
//       retried every resolve_retry_s and counted each time (resolve_errors); it is logged on
//       its first failure only, and once more when it opens. A send that fails (ECONNREFUSED after an ICMP port
//       unreachable, no route) is counted (send_errors) and logged at most once per 10 s; a full socket buffer (EAGAIN)
//       drops that bundle for that destination (sends_would_block).
//   set-up thread  construction, start(), stop(), register_metrics(); any thread reads counters.
// Cost on the producer: one copy of the pose (~2.7 kB) and an EventCount notify (~0.2 µs).
// Memory: queue_frames ring slots of ~2.7 kB, allocated at construction.
#pragma once

#include <sys/socket.h>

#include <atomic>
#include <cstdint>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "core/clock.hpp"
#include "core/counters.hpp"
#include "core/event_count.hpp"
#include "core/frame.hpp"
#include "core/metrics_registry.hpp"
#include "core/spsc_ring.hpp"
#include "serve/serve_counters.hpp"
#include "serve/vmc_rig.hpp"
#include "skeleton/skeleton_pose.hpp"

namespace mocap::serve {

struct VmcDestination {
    std::string host;  ///< name or address literal
    std::uint16_t port = 39539;
    [[nodiscard]] std::string str() const;
};

struct VmcSenderConfig {
    std::vector<VmcDestination> destinations;
    std::uint32_t subject = 0;      ///< 0 = the first subject with a frame
    std::size_t queue_frames = 64;  ///< ring slots between the pipeline and the sender (power of 2)
    double resolve_retry_s = 5.0;   ///< an unresolved destination is looked up again this often
};

/// A resolved UDP destination.
struct UdpAddress {
    sockaddr_storage address{};
    socklen_t length = 0;
};

/// getaddrinfo for a UDP destination (may block on DNS). nullopt + *error ("cannot resolve
/// host \"x\": ...") when the name does not resolve.
std::optional<UdpAddress> resolve_udp(const VmcDestination& destination, std::string* error);

/// One frame between the producer and the sender thread.
struct VmcQueuedFrame {
    std::int64_t sample_us = 0;
    bool calibrated = false;
    bool tracking = false;
    skeleton::SkeletonPose pose;
};

class VmcSender {
public:
    /// `clock`: times the resolve retries (not owned).
    VmcSender(VmcSenderConfig config, VmcRig rig, const Clock& clock);
    ~VmcSender();
    VmcSender(const VmcSender&) = delete;
    VmcSender& operator=(const VmcSender&) = delete;

    /// Starts the sender thread; logs the segments no bone carries, once.
    void start();
    /// Joins the sender thread and closes the sockets (frames still queued are not sent). Idempotent.
    void stop();

    /// Producer thread only (see above). Never blocks.
    void publish(const SubjectFrame& frame, const skeleton::SkeletonPose& pose) noexcept;

    [[nodiscard]] const VmcRig& rig() const { return rig_; }
    /// Component "vmc": frames_queued, frames_dropped (ring full), bundles_sent and bytes_sent
    /// (summed over destinations), send_errors, sends_would_block, resolve_errors, encode_errors.
    [[nodiscard]] const CounterGroup& counters() const { return group_; }
    /// The counters above and the gauges vmc_destinations_resolved, vmc_skipped_segments.
    void register_metrics(MetricsRegistry& registry) const;

private:
    using Item = VmcQueuedFrame;
    struct Target {
        VmcDestination destination;
        int fd = -1;
        std::uint64_t failures = 0;  ///< failed opens since the last success (logged: the first)
    };

    void run();
    void resolve_pending();
    void send(const Item& item);

    VmcSenderConfig config_;
    VmcRig rig_;
    const Clock& clock_;
    SpscRing<Item> ring_;
    EventCount ready_;
    std::atomic<bool> stop_{false};
    std::thread thread_;

    // Producer thread.
    std::uint32_t subject_;
    Item scratch_;
    SingleWriterCounter frames_queued_;
    SingleWriterCounter frames_dropped_;

    // Sender thread (set-up thread before start / after stop).
    std::vector<Target> targets_;
    std::int64_t next_resolve_us_ = 0;
    std::int64_t first_sample_us_ = -1;
    VmcPose vmc_pose_;
    std::vector<char> bundle_;
    LogLimiter log_;
    SingleWriterCounter bundles_sent_;
    SingleWriterCounter bytes_sent_;
    SingleWriterCounter send_errors_;
    SingleWriterCounter sends_would_block_;
    SingleWriterCounter resolve_errors_;
    SingleWriterCounter encode_errors_;
    std::atomic<std::uint32_t> resolved_{0};

    CounterGroup group_{"vmc"};
};

}  // namespace mocap::serve
