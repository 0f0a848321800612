// nats_harness.hpp — what the cluster integration tests share (cluster_test.cpp,
// cluster_ha_test.cpp, cluster_faults_test.cpp, jetstream_test.cpp): a real nats-server on a
// loopback port with a user and password, the [cluster] config section that reaches it, a
// test-side subscriber (the C client), and mocapd's counters read through the Stats request
// of its pose service.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "harness.hpp"
#include "mocap/v1/mocap.pb.h"

struct __natsConnection;    // NOLINT(bugprone-reserved-identifier): libnats names its types so
struct __natsSubscription;  // NOLINT(bugprone-reserved-identifier): libnats names its types so

namespace mocap::itest {

inline constexpr const char* kNatsUser = "mocap";
inline constexpr const char* kNatsPassword = "cluster-pw-1";

/// Whether the nats-server binary the build found is there (tests skip with a reason if not).
bool have_nats_server();
/// The nats-server binary's path.
const char* nats_server_bin();

/// nats-server on 127.0.0.1:port with kNatsUser/kNatsPassword, plus `extra` arguments (e.g.
/// {"-js", "-sd", dir} for JetStream); returns once it accepts connections (EXPECTs that).
std::unique_ptr<Process> start_nats(std::uint16_t port, const std::string& log,
                                    const std::vector<std::string>& extra = {});
/// The same with other credentials (a server that refuses mocapd's password).
std::unique_ptr<Process> start_nats_as(std::uint16_t port, const std::string& user, const std::string& password,
                                       const std::string& log, const std::vector<std::string>& extra = {});

/// Every message of one subject pattern on one server, kept in order by the client library.
class NatsSubscriber {
public:
    NatsSubscriber(std::uint16_t port, const std::string& subject, const std::string& user = kNatsUser,
                   const std::string& password = kNatsPassword);
    ~NatsSubscriber();
    NatsSubscriber(const NatsSubscriber&) = delete;
    NatsSubscriber& operator=(const NatsSubscriber&) = delete;

    /// The next message (subject, payload), or nothing within `timeout`.
    std::optional<std::pair<std::string, std::string>> next(std::chrono::milliseconds timeout);

private:
    __natsConnection* nc_ = nullptr;
    __natsSubscription* sub_ = nullptr;
};

/// The SkeletonFrame of a pose-subject payload (a ServerMessage without a length prefix);
/// a test failure when it is not one.
v1::SkeletonFrame decode_pose_payload(const std::string& payload);

/// A test of one mocapd host against nats-server: skipped (with the reason) when there is no
/// nats-server binary; free loopback ports for the server, the host's sinks and its pose
/// service; at the end the simulator is stopped, the host must stop with exit 0, and its log
/// is shown when the test failed.
class OneHostClusterTest : public ::testing::Test {
protected:
    void SetUp() override;
    void TearDown() override;

    TempDir dir_;
    std::uint16_t nats_port_ = 0, sink_port_ = 0, pose_port_ = 0;
    std::unique_ptr<Process> nats_, daemon_, sim_;
};

/// What one mocapd host of the cluster tests sets; daemon_config() writes the rest.
struct HostConfig {
    std::uint16_t sink_port = 0;
    std::uint16_t pose_port = 0;
    std::string calibration_dir{};
    int workers = 2;
    std::string ingest{};                        ///< more [ingest] lines
    std::string skeleton{};                      ///< more [skeleton] lines
    std::string serve{};                         ///< more [serve] lines
    std::string outputs = "bvh_live = false\n";  ///< the [outputs] lines
    std::string http = "enabled = false\n";      ///< the [http] lines
    std::string cluster{};                       ///< the [cluster] section (cluster_section()), last
};
/// mocapd's config for one host: [log] at info without the periodic stats line, sinks and
/// pose clients on the loopback ports, [pipeline] workers and 4 subjects, the calibration
/// directory, then the host's own lines and sections.
std::string daemon_config(const HostConfig& host);
/// Writes daemon_config(host) to `dir`/`name`.toml and starts mocapd (the binary
/// `mocapd_bin`) on it, logging to `name`.log, in `dir`; returns once its pose and sink ports
/// accept connections (a test failure with its log when they do not within 10 s).
std::unique_ptr<Process> start_mocapd(const char* mocapd_bin, const HostConfig& host, const TempDir& dir,
                                      const std::string& name = "mocapd");

/// cluster_section()'s queue_frames that writes no line: the daemon's default queue.
inline constexpr std::size_t kDefaultQueueFrames = 0;
/// "[cluster]" with nats_url on the port, site, host_id, queue_frames (64 unless given), then
/// `more` (credentials and other keys, one per line).
std::string cluster_section(std::uint16_t nats_port, const std::string& site, const std::string& host_id,
                            const std::string& more, std::size_t queue_frames = 64);
/// user and password as config lines: kNatsUser and kNatsPassword unless given.
std::string cluster_credentials(const std::string& user = kNatsUser, const std::string& password = kNatsPassword);

/// `mocap-sim stream` (the binary `sim_bin`) to 127.0.0.1:sink_port: `subjects` at 100 Hz
/// for `seconds`, with its rate statistics (sim_syncs_skipped) in `log`.
std::unique_ptr<Process> stream_sim(const char* sim_bin, std::uint16_t sink_port, int subjects, int seconds,
                                    const std::string& log);

/// One counter of mocapd's Stats reply ("cluster.frames_dropped"); a test failure if absent.
std::uint64_t stats_counter(std::uint16_t pose_port, const std::string& name);
/// Polls stats_counter until `pred` holds or `limit` passes; returns the last value.
std::uint64_t wait_stats_counter(std::uint16_t pose_port, const std::string& name,
                                 const std::function<bool(std::uint64_t)>& pred, std::chrono::milliseconds limit);

/// "replayed N samples ..." of `mocapd --replay`/`--jetstream`.
std::optional<std::uint64_t> replayed_samples(const std::string& log);
/// `mocapd --jetstream nats://127.0.0.1:PORT --subject N`: the arguments that replay one
/// subject's take from the stream (credentials and site from the config given with them).
std::vector<std::string> jetstream_replay_args(std::uint16_t nats_port, std::uint32_t subject);

}  // namespace mocap::itest
