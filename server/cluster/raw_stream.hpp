// raw_stream.hpp — durable takes: every raw sample of every subject to the JetStream stream
// MOCAP_RAW (docs/outputs.md, "Durable takes (JetStream)"; payload in docs/client-protocol.md,
// "Raw samples over JetStream"), so a take survives the host that recorded it.
//
//   stream    MOCAP_RAW, subjects mocap.<site>.*.raw, file storage, [cluster] raw_replicas
//   subject   mocap.<site>.<subject id>.raw
//   payload   length-delimited mocap.v1.RawRecord samples (proto/mocap/v1/recording.proto),
//             the records of a raw recording file without its magic and header: one parser
//             (serve::RawRecordingReader) reads both. One message carries the samples of one
//             subject that arrived since the previous one (~10 ms, up to kRawMessageBytes).
//
// The cluster publisher (cluster_publisher.hpp) owns one and drives it from its publisher
// thread, on the publisher's NATS connection. push() runs on the ingest thread: a copy into a
// bounded queue under a mutex held for the push; when the queue is full its oldest sample is
// dropped and counted, so a slow or lost cluster never slows the pipeline. The publisher
// thread encodes, batches and publishes with JetStream asynchronous publish: it never waits
// for an acknowledgement (beyond max_pending unacknowledged messages it waits at most
// kRawStallWaitMs, then counts the message as failed). Acknowledgements arrive on the NATS
// client's thread, which counts them and records the publish-to-ack latency.
//
// What "acknowledged" promises: JetStream acknowledges a message once it is stored (on a
// quorum of raw_replicas servers), so a host killed mid-take loses at most the samples it
// had queued or in flight; raw_samples_acked counts what the stream holds for sure. A failed
// message (timeout, lost connection) may still have been stored: failed means "not known".
#pragma once

#include <atomic>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/counters.hpp"
#include "core/frame.hpp"
#include "core/latency_histogram.hpp"
#include "core/metrics_registry.hpp"

struct __natsConnection;  // NOLINT(bugprone-reserved-identifier): libnats names its types so
struct __natsMsg;         // NOLINT(bugprone-reserved-identifier): libnats names its types so
struct __jsCtx;           // NOLINT(bugprone-reserved-identifier): libnats names its types so
struct jsPubAck;
struct jsPubAckErr;

namespace mocap::cluster {

inline constexpr const char* kRawStreamName = "MOCAP_RAW";
/// A message is sent when a subject's batch reaches this size (or at every drain).
inline constexpr std::size_t kRawMessageBytes = 32u << 10;
/// Longest a publish waits when max_pending messages are unacknowledged.
inline constexpr std::int64_t kRawStallWaitMs = 20;

/// "mocap.<site>.<subject>.raw".
std::string raw_subject(const std::string& site, std::uint32_t subject_id);
/// "mocap.<site>.*.raw": the subjects of MOCAP_RAW for one site.
std::string raw_subject_pattern(const std::string& site);

struct RawStreamConfig {
    std::string site;
    std::uint32_t replicas = 1;
    std::size_t queue_samples = 65536;  ///< between ingest and the publisher thread
    int max_pending = 4096;             ///< unacknowledged messages in flight
    std::int64_t ack_wait_ms = 5000;    ///< an unacknowledged message fails after this
};

class RawStreamPublisher {
public:
    /// Registers its counters in `group` (the cluster publisher's "cluster" component).
    RawStreamPublisher(RawStreamConfig config, CounterGroup& group);
    ~RawStreamPublisher();
    RawStreamPublisher(const RawStreamPublisher&) = delete;
    RawStreamPublisher& operator=(const RawStreamPublisher&) = delete;

    /// Ingest thread: never blocks (a mutex held for a copy); drops the oldest when full.
    void push(const SegmentSample& sample);
    /// Any thread: samples waiting for the publisher thread.
    [[nodiscard]] std::size_t queued() const { return queued_.load(std::memory_order_relaxed); }

    /// Set-up thread: the JetStream context on the publisher's connection. False + *error
    /// if the client refuses (out of memory); an unreachable server is no error here.
    bool attach(__natsConnection* connection, std::string* error);
    /// Publisher thread, while connected: makes sure the stream exists (once per connection,
    /// then every kEnsureRetry while it fails), then publishes everything queued.
    void publish_queued();
    /// Publisher thread: the connection was lost; check the stream again when it is back.
    void connection_lost() {
        stream_ready_ = false;
        next_ensure_us_ = 0;  // at once when it is back, not after a retry wait of the old connection
    }
    /// Publisher thread, before a connection the client closed is destroyed: what it still
    /// owed an acknowledgement is counted as failed and the context is freed; the queue stays
    /// for the next attach().
    void detach();
    /// Set-up thread, after the publisher thread stopped and before the connection closes:
    /// publishes what is queued (when `connected`), waits up to `wait_ms` for outstanding
    /// acknowledgements, counts the rest as failed, frees the context.
    void finish(bool connected, std::int64_t wait_ms);

    void register_metrics(MetricsRegistry& registry) const;

private:
    struct InFlight {
        std::int64_t sent_us = 0;
        std::uint32_t samples = 0;
    };
    static void on_ack(__jsCtx* js, __natsMsg* msg, jsPubAck* pa, jsPubAckErr* pae, void* self);
    bool ensure_stream();
    /// Counts what the context still owes an acknowledgement as failed and frees it.
    void release_context();
    void send(const std::string& subject, const std::string& payload, std::uint32_t samples);

    RawStreamConfig config_;
    std::string pattern_;

    std::mutex queue_mutex_;
    std::deque<SegmentSample> queue_;  // guarded by queue_mutex_
    std::atomic<std::size_t> queued_{0};

    __jsCtx* js_ = nullptr;
    // Publisher thread.
    bool stream_ready_ = false;
    bool published_ = false;  // js_PublishMsgAsync was called at least once
    std::int64_t next_ensure_us_ = 0;
    bool ensure_logged_ = false;
    std::vector<SegmentSample> batch_;
    struct SubjectBatch {
        std::uint32_t subject_id = 0;
        std::string bytes;  // encoded records
        std::uint32_t samples = 0;
    };
    std::vector<SubjectBatch> batches_;  // one per subject seen, reused

    std::mutex flight_mutex_;
    std::unordered_map<const __natsMsg*, InFlight> in_flight_;  // guarded by flight_mutex_

    Counter samples_queued_;        // ingest thread
    Counter samples_dropped_;       // ingest thread (drop-oldest)
    Counter messages_sent_;         // publisher thread
    Counter bytes_sent_;            // publisher thread: payload bytes
    Counter messages_acked_;        // NATS client thread
    Counter samples_acked_;         // NATS client thread
    Counter messages_failed_;       // publisher thread (refused) and NATS client thread (error, timeout)
    Counter samples_failed_;        // likewise
    Counter stream_errors_;         // publisher thread: the stream could not be created or checked
    LatencyHistogram ack_latency_;  // NATS client thread
};

}  // namespace mocap::cluster
