// nats_pose_client.hpp — reads pose frames from a NATS cluster that mocapd publishes to
// (docs/client-protocol.md, "Poses over NATS"), with the PoseClient's reading interface.
//
//   mocap::client::NatsPoseClient c;
//   std::string err;
//   if (!c.connect({.url = "nats://u:p@127.0.0.1:4222", .site = "venue"}, 2s, err)) ...
//   c.subscribe({.subject_ids = {1}}, 2s, err);   // then waits up to 2 s for a heartbeat
//   mocap::v1::SkeletonFrame f;
//   while (c.next_frame(f, 1s) == ReadStatus::kMessage) ...
//
// There is no Hello on NATS: the segment and joint-angle names come from the first host
// heartbeat (mocap.<site>.host.*), so hello() is filled once one arrived. Frames carry every
// field; subscribe()'s field selection and decimation are applied here, so what next_frame()
// returns equals what the pose service sends for the same subscription.
//
// Thread-safety: none; one NatsPoseClient per thread at a time.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <optional>
#include <string>

#include "mocap/v1/mocap.pb.h"
#include "pose_client.hpp"

struct __natsConnection;    // NOLINT(bugprone-reserved-identifier): libnats names its types so
struct __natsSubscription;  // NOLINT(bugprone-reserved-identifier): libnats names its types so

namespace mocap::client {

struct NatsOptions {
    std::string url;  ///< one URL or a comma-separated list; may carry user:password@
    std::string site = "venue";
    std::string user, password;
    std::string creds_file;
};

class NatsPoseClient {
public:
    NatsPoseClient() = default;
    ~NatsPoseClient();
    NatsPoseClient(const NatsPoseClient&) = delete;
    NatsPoseClient& operator=(const NatsPoseClient&) = delete;

    bool connect(const NatsOptions& options, std::chrono::milliseconds timeout, std::string& error);
    /// Subscribes to the subjects' pose subjects (all: mocap.<site>.*.pose) and waits up to
    /// `heartbeat_wait` for a host heartbeat to name the segments.
    bool subscribe(const SubscribeOptions& options, std::chrono::milliseconds heartbeat_wait, std::string& error);
    ReadStatus next_frame(v1::SkeletonFrame& out, std::chrono::milliseconds timeout);

    [[nodiscard]] const v1::Hello& hello() const { return hello_; }
    /// The JSON text of the heartbeat subscribe() waited for ("" = none arrived): it also
    /// describes the body and the live BVH encoding (mocap-client --nats record).
    [[nodiscard]] const std::string& heartbeat() const { return heartbeat_; }
    /// CLOCK_REALTIME µs when the last frame was taken from the client library.
    [[nodiscard]] std::int64_t last_receive_us() const { return last_receive_us_; }
    /// Frames the client library dropped because this reader was too slow.
    [[nodiscard]] std::uint64_t drops_announced() const;
    /// NATS has no Goodbye: always empty (PoseClient's interface, for code serving both).
    [[nodiscard]] const std::optional<v1::Goodbye>& goodbye() const { return goodbye_; }
    [[nodiscard]] const std::string& error() const { return error_; }

private:
    void close();

    NatsOptions options_;
    SubscribeOptions subscription_;
    __natsConnection* connection_ = nullptr;
    __natsSubscription* poses_ = nullptr;
    v1::Hello hello_;
    std::string heartbeat_;
    v1::ServerMessage scratch_;
    std::map<std::uint32_t, std::uint64_t> seen_per_subject_;  // for decimation
    std::int64_t last_receive_us_ = 0;
    std::string error_;
    std::optional<v1::Goodbye> goodbye_;
};

}  // namespace mocap::client
