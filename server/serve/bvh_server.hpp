// bvh_server.hpp — live BVH text over TCP (default port 7002).
//
// Framing (docs/outputs.md): a client receives
//     the HIERARCHY block (BvhFrameEncoder::hierarchy(), ends with the root's "}\n")
//     "MOTION\n"
//     "Frame Time: <seconds>\n"
// as soon as its subject's Frame Time is known (configured, or measured over at least
// kMeasuredIntervals SYNC instants of that subject: serve/frame_interval.hpp; until then its
// lines wait in its queue), and then one '\n'-terminated MOTION line per frame of ONE subject, live. There is no
// "Frames:" line (the count is open); a reader that wants a file counts the lines it
// received and writes "Frames: <count>" before "Frame Time:".
// Subject: the configured `subject`, or with 0 the subject of the first frame published
// after the client connected. A client may switch by sending the text line
// "subject <id>\n" at any time (a client may half-close its side after it; other
// input: counted as bad lines; a line longer than
// 64 bytes closes the connection).
// Lag: each client has a ClientSendQueue of queue_frames lines; when it is full the
// OLDEST line is dropped and counted (frames_dropped), so a slow reader sees a gap, never
// a stall of the pipeline; the HIERARCHY greeting is never queued, so never dropped.
// One write in flight per client.
//
// Threads: a ServeThread with `threads` lanes (each its own io_context and thread) runs the
// acceptor (lane 0) and the sessions, spread round-robin over the lanes; each lane keeps
// its own session table. publish() may be called from any thread (the assembler thread);
// it encodes the line once (nothing when no client is connected) and hands the same
// shared bytes to every lane through a PublishBacklog of publish_backlog_frames per lane
// (beyond: dropped, counted once per lane that refused).
// Ownership: the daemon owns the server; stop() (or the destructor) closes everything.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/asio.hpp"
#include "core/frame.hpp"
#include "core/metrics_registry.hpp"
#include "serve/bvh_frame_encoder.hpp"
#include "serve/frame_interval.hpp"
#include "serve/publish_backlog.hpp"
#include "serve/serve_config.hpp"
#include "serve/serve_thread.hpp"
#include "serve/session_table.hpp"
#include "skeleton/skeleton_pose.hpp"

namespace mocap::serve {

/// SYNC intervals a subject's Frame Time is measured over before a client is greeted with it.
inline constexpr std::uint64_t kMeasuredIntervals = 10;

struct BvhServerConfig {
    std::string bind_address = "0.0.0.0";
    std::uint16_t port = 7002;      ///< 0 = any free port (tests)
    std::size_t max_clients = 64;   ///< slots; see ServeThread for who gets one when full
    std::size_t queue_frames = 64;  ///< per-client queue; the oldest line is dropped beyond it
    std::uint32_t subject = 0;      ///< 0 = first subject with a frame (per client)
    std::size_t publish_backlog_frames = 1024;
    PeerLimits limits{};  ///< [limits] bvh_per_address, loopback, stall_evict_s
    /// SO_SNDBUF per client: bounded, so a stalled reader's lines are dropped from its
    /// queue (counted) instead of piling up in the kernel (0 = kernel default).
    std::uint32_t send_buffer_bytes = 128 * 1024;
    std::size_t threads = 1;  ///< serve threads ([outputs] bvh_threads); clients spread over them
};

struct BvhServerCounters {
    ConnectionCounters connections;  ///< connections_* and accept_errors (connection_counters.hpp)
    Counter frames_published;        ///< frames handed to publish() while clients were connected
    Counter frames_sent;             ///< lines written (sum over clients)
    Counter frames_dropped;          ///< oldest lines dropped from lagging clients
    Counter backlog_dropped;         ///< the serve thread fell behind publish()
    Counter bad_client_lines;        ///< client input that is not "subject <id>"
    Counter write_errors;

    /// Component "bvh_live": every counter above by its member name, the connections' as
    /// connection_counters.hpp names them (the metrics registry's entry, core/metrics_registry.hpp).
    CounterGroup group{"bvh_live"};

    BvhServerCounters();
};

class BvhServer {
public:
    /// `encoder` is shared with whoever else writes BVH; must outlive the server.
    BvhServer(BvhServerConfig config, const BvhFrameEncoder& encoder);
    ~BvhServer();
    BvhServer(const BvhServer&) = delete;
    BvhServer& operator=(const BvhServer&) = delete;

    /// Binds and starts the serve thread. Returns false and sets `error` on failure.
    [[nodiscard]] bool start(std::string& error);
    /// Closes every client and joins the thread. Idempotent.
    void stop();

    /// Any thread; never blocks on a client.
    void publish(const SubjectFrame& frame, const skeleton::SkeletonPose& pose);

    [[nodiscard]] std::uint16_t port() const { return serve_.port(); }
    [[nodiscard]] std::size_t client_count() const;
    /// Clients served by lane (serve thread) `lane` now; any thread (how they are spread).
    [[nodiscard]] std::size_t lane_client_count(std::size_t lane) const { return sessions_.at(lane)->open(); }
    [[nodiscard]] const BvhServerCounters& counters() const { return counters_; }
    /// Set-up: counter group "bvh_live" and gauge "bvh_live_clients".
    void register_metrics(MetricsRegistry& registry) const;

    class Session;  // one client (bvh_server.cpp)

private:
    void admit(std::size_t lane, asio::ip::tcp::socket socket, ServeThread::SlotPtr slot);
    void on_closed(std::size_t lane, std::uint64_t id);
    void deliver(std::size_t lane, const SubjectText& line);
    /// HIERARCHY + MOTION + Frame Time (the configured one, else `measured_s`).
    [[nodiscard]] std::shared_ptr<const std::string> greeting(double measured_s) const;
    /// The subject's measured Frame Time after this frame, 0 while unknown.
    double measure(const SubjectFrame& frame);

    BvhServerConfig config_;
    const BvhFrameEncoder& encoder_;
    std::shared_ptr<const std::string> fixed_greeting_;           // when the Frame Time is configured
    std::mutex intervals_mutex_;                                  // publish() may run on several threads
    std::unordered_map<std::uint32_t, FrameInterval> intervals_;  // by subject
    BvhServerCounters counters_;

    ServeThread serve_;  // before the sessions and the backlog, which use its io_contexts
    /// One table per lane, used on that lane's thread (open(): any thread).
    std::vector<std::unique_ptr<SessionTable<Session>>> sessions_;
    PublishBacklog backlog_;
};

}  // namespace mocap::serve
