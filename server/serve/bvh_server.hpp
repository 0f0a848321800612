// bvh_server.hpp — live BVH text over TCP (default port 7002).
//
// Framing (docs/outputs.md): on connect a client receives, at once,
//     the HIERARCHY block (BvhFrameEncoder::hierarchy(), ends with the root's "}\n")
//     "MOTION\n"
//     "Frame Time: <seconds>\n"
// and then one '\n'-terminated MOTION line per frame of ONE subject, live. There is no
// "Frames:" line (the count is open); a reader that wants a file counts the lines it
// received and writes "Frames: <count>" before "Frame Time:".
// Subject: the configured `subject`, or with 0 the subject of the first frame published
// after the client connected. A client may switch by sending the text line
// "subject <id>\n" at any time (a client may half-close its side after it; other
// input: counted as bad lines; a line longer than
// 64 bytes closes the connection).
// Lag: each client has a bounded queue of queue_frames lines; when it is full the OLDEST
// line is dropped and counted (frames_dropped), so a slow reader sees a gap, never a
// stall of the pipeline. One write in flight per client.
//
// Threads: one serve thread (its own io_context) runs the acceptor and every session.
// publish() may be called from any thread (the assembler thread); it encodes the line
// once (nothing when no client is connected) and hands it to the serve thread through a
// mutex-guarded backlog of publish_backlog_frames (beyond: dropped, counted).
// Ownership: the daemon owns the server; stop() (or the destructor) closes everything.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "core/asio.hpp"
#include "core/frame.hpp"
#include "serve/bvh_frame_encoder.hpp"
#include "serve/pose_frame.hpp"
#include "serve/serve_config.hpp"

namespace mocap::serve {

struct BvhServerConfig {
    std::string bind_address = "0.0.0.0";
    std::uint16_t port = 7002;        ///< 0 = any free port (tests)
    std::size_t max_clients = 64;     ///< more are closed at once (counted)
    std::size_t queue_frames = 64;    ///< per-client queue; the oldest line is dropped beyond it
    std::uint32_t subject = 0;        ///< 0 = first subject with a frame (per client)
    std::size_t publish_backlog_frames = 1024;
};

struct BvhServerCounters {
    using C = std::atomic<std::uint64_t>;
    C connections_accepted{0};
    C connections_rejected_full{0};
    C connections_closed{0};
    C frames_published{0};  ///< frames handed to publish() while clients were connected
    C frames_sent{0};       ///< lines written (sum over clients)
    C frames_dropped{0};    ///< oldest lines dropped from lagging clients
    C backlog_dropped{0};   ///< the serve thread fell behind publish()
    C bad_client_lines{0};  ///< client input that is not "subject <id>"
    C write_errors{0};
    /// Every counter as "bvh_live.<name>".
    [[nodiscard]] std::vector<NamedCounter> snapshot() const;
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
    void publish(const SubjectFrame& frame, const SkeletonPose& pose);

    [[nodiscard]] std::uint16_t port() const { return bound_port_.load(); }
    [[nodiscard]] std::size_t client_count() const { return clients_.load(); }
    [[nodiscard]] const BvhServerCounters& counters() const { return counters_; }

    class Session;  // one client (bvh_server.cpp)

private:
    struct Line {
        std::uint32_t subject_id = 0;
        std::shared_ptr<const std::string> text;
    };
    void do_accept();
    void drain();
    void on_closed(std::uint64_t id);

    BvhServerConfig config_;
    const BvhFrameEncoder& encoder_;
    std::shared_ptr<const std::string> greeting_;  // HIERARCHY + MOTION + Frame Time
    BvhServerCounters counters_;

    asio::io_context io_{1};
    std::unique_ptr<asio::ip::tcp::acceptor> acceptor_;
    std::unordered_map<std::uint64_t, std::shared_ptr<Session>> sessions_;  // serve thread
    std::thread thread_;
    std::uint64_t next_id_ = 1;  // serve thread

    std::mutex backlog_mutex_;
    std::vector<Line> backlog_;  // guarded; reserved at construction
    std::vector<Line> draining_;  // serve thread

    std::atomic<std::size_t> clients_{0};
    std::atomic<std::uint16_t> bound_port_{0};
    std::atomic<bool> running_{false};
};

}  // namespace mocap::serve
