// cluster_publisher.hpp — the cluster output: every pose frame to a NATS cluster, and a host
// heartbeat once a second (docs/outputs.md, "Cluster publisher"; subjects and payload in
// docs/client-protocol.md, "Poses over NATS").
//
//   mocap.<site>.<subject id>.pose     mocap.v1.ServerMessage{frame}, every field, no length
//                                      prefix (the bytes the pose service sends after it)
//   mocap.<site>.host.<host_id>        JSON status, once a second
//   mocap.<site>.<subject id>.raw      every raw sample, to the JetStream stream MOCAP_RAW
//                                      (raw_stream.hpp: durable takes)
//
// Publishing never blocks the pipeline: on_frame() encodes the frame (once, on the assembler
// thread) and pushes it into a bounded queue; when the queue is full its oldest frame is
// dropped and counted. One publisher thread drains the queue into the NATS C client, whose
// own thread writes to the socket and reconnects by itself (forever, every reconnect_wait).
// While the client is not connected the publisher thread leaves frames in the queue, so a
// lost cluster shows as cluster.frames_dropped, never as a slower pipeline, and publishing
// resumes with the newest frames once the client is back. A server that stops reading (its
// socket full: a PING flood it never reads the PONGs of, a frozen process) fails the
// client's writes after the write deadline (cluster_config.hpp), which drops the connection
// and reconnects; so no write, publish or stop waits on a server for longer than that. The
// first connect runs on the publisher thread too: a server that accepts and says nothing
// never delays the daemon's start.
//
// Raw samples take the same path with their own bounded queue (raw_stream.hpp): on_sample()
// copies the sample on the ingest thread, the publisher thread batches them per subject and
// publishes them asynchronously to JetStream every kRawDrain (20 ms).
//
// Threads: on_frame on the assembler thread (a mutex held for a push); on_sample on the
// ingest thread (another mutex held for a copy); the publisher thread; the NATS client's
// threads run the connection callbacks and the JetStream acknowledgements (counters only).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "cluster/cluster_config.hpp"
#include "cluster/nats_errors.hpp"
#include "cluster/raw_stream.hpp"
#include "core/counters.hpp"
#include "pipeline/output.hpp"
#include "serve/pose_encoder.hpp"

namespace mocap::cluster {

/// "mocap.<site>.<subject>.pose".
std::string pose_subject(const std::string& site, std::uint32_t subject_id);
/// "mocap.<site>.host.<host_id>".
std::string host_subject(const std::string& site, const std::string& host_id);

class ClusterPublisher final : public pipeline::Output {
public:
    explicit ClusterPublisher(ClusterConfig config);
    ~ClusterPublisher() override;
    ClusterPublisher(const ClusterPublisher&) = delete;
    ClusterPublisher& operator=(const ClusterPublisher&) = delete;

    [[nodiscard]] std::string_view name() const override { return "cluster"; }
    /// Sets up the client and starts connecting; an unreachable cluster is not an error (the
    /// client keeps retrying), bad options (an unreadable credentials file) are.
    bool start(std::string* error) override;
    bool stop(std::string* error) override;
    void on_frame(const SubjectFrame& frame, const skeleton::SkeletonPose& pose) override;
    /// Every raw sample goes to JetStream (raw_stream.hpp).
    [[nodiscard]] bool wants_samples() const override { return true; }
    void on_sample(const SegmentSample& sample) override { raw_.push(sample); }
    void register_metrics(MetricsRegistry& registry) const override;

    /// Any thread: whether the client is connected now.
    [[nodiscard]] bool connected() const { return connected_.load(std::memory_order_relaxed); }

private:
    struct Queued {
        std::uint32_t subject_id = 0;
        serve::SharedBytes bytes;  ///< length-prefixed, as the pose service sends it
    };
    static void on_disconnected(__natsConnection* nc, void* self);
    static void on_reconnected(__natsConnection* nc, void* self);
    static void on_connected(__natsConnection* nc, void* self);
    static void on_closed(__natsConnection* nc, void* self);
    void run();
    /// Publisher thread, first: the connection (retrying in the background when it fails).
    void connect_first();
    /// Publisher thread: replaces a connection the client closed for good.
    void reopen();
    void publish_frames(std::vector<Queued>& batch);
    void publish_heartbeat(std::int64_t now_us, double interval_s);

    ClusterConfig config_;
    serve::PoseEncoder encoder_;  // assembler thread only

    std::mutex mutex_;
    std::condition_variable wake_;
    std::deque<Queued> queue_;  // guarded by mutex_
    bool stopping_ = false;     // guarded by mutex_
    bool closed_ = false;       // guarded by mutex_: the client delivered its last callback

    __natsOptions* options_ = nullptr;
    __natsConnection* connection_ = nullptr;
    std::thread thread_;
    std::atomic<bool> connected_{false};
    std::atomic<std::size_t> queued_{0};

    // Heartbeat rates (publisher thread only): frames per subject since the last heartbeat.
    std::vector<std::pair<std::uint32_t, std::uint64_t>> subject_frames_;
    std::int64_t started_us_ = 0;
    std::uint64_t reopens_ = 0;  // publisher thread only

    Counter frames_queued_;                        // assembler thread
    Counter frames_dropped_;                       // assembler thread (drop-oldest)
    Counter frames_published_;                     // publisher thread
    Counter publish_errors_;                       // publisher thread
    Counter heartbeats_;                           // publisher thread
    Counter disconnects_;                          // NATS client thread
    Counter reconnects_;                           // NATS client thread
    NatsErrors nats_errors_{"cluster publisher"};  // permission_errors: NATS client thread
    CounterGroup group_{"cluster"};
    RawStreamPublisher raw_;  // after group_: registers its counters there
};

}  // namespace mocap::cluster
