// raw_take_reader.hpp — reads a durable take back from JetStream (raw_stream.hpp): the raw
// samples of one subject from the stream MOCAP_RAW, in the order they were published, for
// `mocapd --replay --jetstream` (daemon/replay.hpp).
//
// How: an ordered consumer (libnats creates, watches and, on a gap, recreates an ephemeral
// push consumer with no acknowledgements) filtered on mocap.<site>.<subject>.raw, starting at
// the stream time `from_us` - kTakeClockMarginUs (or at the start). The last message of the
// subject when the reader opened ends the take, as does a message stored later than
// `to_us` + kTakeClockMarginUs. The margin covers samples that waited in the publisher's queue
// and clocks of the recording host and the servers that disagree: the caller filters samples
// by their received_us exactly (replay does, for files too).
// Each message's records are parsed by serve::RawRecordingReader, as a file's are.
//
// Threads: one thread owns a reader. The NATS client runs its own threads meanwhile.
#pragma once

#include <cstdint>
#include <limits>
#include <string>

#include "cluster/cluster_config.hpp"
#include "core/frame.hpp"
#include "serve/raw_recorder.hpp"

struct __natsConnection;    // NOLINT(bugprone-reserved-identifier): libnats names its types so
struct __natsSubscription;  // NOLINT(bugprone-reserved-identifier): libnats names its types so
struct __jsCtx;             // NOLINT(bugprone-reserved-identifier): libnats names its types so

namespace mocap::cluster {

/// Stream time and sample time may differ by this much (queueing, clocks of two hosts).
inline constexpr std::int64_t kTakeClockMarginUs = 60'000'000;

struct RawTakeQuery {
    std::uint32_t subject_id = 1;
    std::int64_t from_us = std::numeric_limits<std::int64_t>::min();  ///< wall clock µs; min = from the start
    std::int64_t to_us = std::numeric_limits<std::int64_t>::max();    ///< max = to the last message
    std::int64_t message_wait_ms = 10000;  ///< longest wait for the next message before giving up
};

class RawTakeReader {
public:
    /// `connection`: nats_url, site and credentials ([cluster]).
    RawTakeReader(ClusterConfig connection, RawTakeQuery query);
    ~RawTakeReader();
    RawTakeReader(const RawTakeReader&) = delete;
    RawTakeReader& operator=(const RawTakeReader&) = delete;

    /// Connects and subscribes. False + error: unreachable, refused, no stream, nothing of
    /// this subject on it.
    bool open(std::string* error);
    /// Next sample: 1 = got one, 0 = the take ended, -1 = error (a corrupt message, the
    /// cluster stopped answering).
    int next(SegmentSample& out, std::string* error);
    /// JetStream messages read so far.
    [[nodiscard]] std::uint64_t messages() const { return messages_; }
    /// The subject read, "mocap.<site>.<subject>.raw".
    [[nodiscard]] const std::string& subject() const { return subject_; }

private:
    void close();

    ClusterConfig connection_;
    RawTakeQuery query_;
    std::string subject_;
    __natsOptions* options_ = nullptr;
    __natsConnection* nc_ = nullptr;
    __jsCtx* js_ = nullptr;
    __natsSubscription* sub_ = nullptr;
    std::uint64_t last_seq_ = 0;  // stream sequence of the subject's last message at open()
    bool done_ = false;
    bool have_records_ = false;
    serve::RawRecordingReader records_;
    std::uint64_t messages_ = 0;
};

}  // namespace mocap::cluster
