// cluster_config.hpp — how mocapd reaches a NATS cluster ([cluster] in the config, read by
// daemon/outputs.cpp and daemon/replay.cpp), and the client options built from it: the
// cluster publisher (cluster_publisher.hpp) and the JetStream take reader (raw_take_reader.hpp)
// connect with the same credentials and TLS.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "serve/bvh_frame_encoder.hpp"
#include "skeleton/body_model.hpp"

struct __natsOptions;  // NOLINT(bugprone-reserved-identifier): libnats names its types so

namespace mocap::cluster {

struct ClusterConfig {
    std::string nats_url;  ///< one URL or a comma-separated list
    std::string site;      ///< a NATS subject token
    std::string host_id;   ///< a NATS subject token
    std::string user, password;
    std::string creds_file;
    std::string nkey_seed_file;  ///< the seed and the public user key, one per line
    std::string tls_ca_file, tls_cert_file, tls_key_file;
    std::size_t queue_frames = 1024;
    std::int64_t reconnect_wait_ms = 250;
    std::function<std::int64_t()> wall_clock_us;  ///< frame encoded_us stamps and heartbeats
    /// Described in every heartbeat, so a subscriber can name what a frame carries.
    std::vector<std::string> segment_names;
    std::vector<std::string> joint_angle_names;
    /// Also in every heartbeat ("body", "bvh"): the body model and the live BVH encoding, so
    /// a subscriber writes the BVH file the live BVH port would (mocap-client --nats record).
    skeleton::BodyModel model;
    serve::BvhOutputOptions bvh;
    /// Durable takes (raw_stream.hpp): JetStream replicas of MOCAP_RAW, and the samples
    /// waiting for the publisher thread (beyond it the oldest are dropped).
    std::uint32_t raw_replicas = 1;
    std::size_t raw_queue_samples = 65536;
    /// Shared calibration (calibration_bucket.hpp): the subjects this host serves (sorted;
    /// calibrations of any other subject are refused), and the site's calibration key file
    /// ("" = values are not signed; calibration_trust.hpp).
    std::vector<std::uint32_t> subject_ids;
    std::string calibration_key_file;

    /// No credentials: any client of the server could publish what this host reads.
    [[nodiscard]] bool anonymous() const { return user.empty() && creds_file.empty() && nkey_seed_file.empty(); }
};

/// A write to a server that has not drained the socket for this long fails, and the client
/// drops the connection and reconnects (a server that stopped reading: docs/cluster.md).
inline constexpr std::int64_t kNatsWriteDeadlineMs = 2000;

/// New client options with the URL, a client name, the credentials and TLS of `config`, and
/// the write deadline kNatsWriteDeadlineMs (the caller adds its reconnect policy and destroys them). False + *error for
/// a bad setting (an unreadable credentials file, a seed file without its public key).
bool make_nats_options(const ClusterConfig& config, __natsOptions** out, std::string* error);

/// "cluster: <what>: <status text>" when s is not NATS_OK.
bool nats_ok(int status, const char* what, std::string* error);

/// The status text and, when the client recorded one on this thread, what the server or the
/// client said about it ("No server available for connection", "Authorization Violation"),
/// without the library's "(file.c:line): " prefix.
std::string nats_error_text(int status);

}  // namespace mocap::cluster
