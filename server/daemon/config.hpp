// config.hpp — mocapd's configuration: the TOML file's values, validated.
//
// The loader accepts exactly the keys documented in config/mocapd.toml (an unknown key
// is an error, so typos are caught) and reports the first problem as
// "<file>:<line>: <key>: <what is wrong>". Thread-safety: plain values; the daemon loads
// a new DaemonConfig on SIGHUP and applies the [reload] fields.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "daemon/endpoint.hpp"

namespace mocap::daemon {

struct SocketCanConfig {
    std::string interface;      ///< e.g. "can0", "vcan0"
    std::uint32_t subject = 1;  ///< subject id the bus belongs to
    bool operator==(const SocketCanConfig&) const = default;
};

struct SegmentConfig {
    std::string name;
    std::string parent;                ///< "" = root
    std::array<double, 3> offset_m{};  ///< joint position in the parent's frame, metres
    std::array<double, 3> end_m{};     ///< distal tip in this segment's frame, metres
    std::uint8_t node = 0;             ///< CAN node id (1..63)
    std::string filter;                ///< "" = [filter].name
    bool operator==(const SegmentConfig&) const = default;
};

/// Shortest accepted control token: with the failed-attempt limits (2 guesses a second at
/// most, docs/security.md) 16 random characters cannot be guessed in any useful time.
inline constexpr std::size_t kMinControlTokenLength = 16;

/// Largest [ingest] subject_id_base: base + max_subjects (<= 4096) stays within 32 bits.
inline constexpr std::uint32_t kMaxSubjectIdBase = 4'000'000'000;

struct DaemonConfig {
    // [log]
    std::string log_level = "info";
    double stats_interval_s = 10.0;
    // [ingest]
    Endpoint sink_listen{"0.0.0.0", 7000};
    std::uint32_t max_sinks = 64;
    double sink_idle_timeout_s = 10.0;
    /// A sink's subject id is subject_id_base + its 8-bit sink id, so the hosts of different
    /// zones of one site serve distinct ids (docs/cluster.md, "Subject ids across a site").
    std::uint32_t subject_id_base = 0;
    /// Host -> sink keepalive period (docs/protocol.md §3.5); 0 = send none (stream version 1).
    double keepalive_period_s = 0.25;
    std::vector<SocketCanConfig> socketcan;
    // [pipeline]
    std::uint32_t workers = 0;  ///< 0 = hardware cores
    std::uint32_t ring_capacity = 4096;
    std::uint32_t max_subjects = 64;
    double assembly_deadline_ms = 20.0;
    // [filter]
    std::string filter_name = "mocap";
    std::vector<std::pair<std::string, std::string>> filter_params;
    // [fusion]
    std::string fusion_heading = "auto";  ///< "magnetometer" | "joints" | "auto" (docs/fusion.md)
    bool fusion_estimate_axes = false;    ///< axis = "estimate" (else "model")
    // [skeleton]
    std::string calibration_dir = ".";
    double calibration_s = 1.0;
    std::string auto_calibrate = "t-pose";  ///< "t-pose" | "n-pose" | "off"
    bool heading_align = true;              ///< heading = "align" (else "earth")
    bool facing_from_sensor = true;         ///< facing = "sensor" (else "given")
    double facing_heading_deg = 0.0;
    std::array<double, 3> facing_sensor_axis{1.0, 0.0, 0.0};
    double smoothing_alpha = 1.0;
    double root_height_m = 1.0;           ///< only with custom segments
    std::vector<SegmentConfig> segments;  ///< empty = built-in 15-segment body
    // [serve]
    Endpoint pose_listen{"0.0.0.0", 7001};
    std::uint32_t max_clients = 1024;
    std::uint32_t serve_threads = 1;
    std::uint32_t client_queue_frames = 64;
    double handshake_timeout_s = 5.0;
    std::uint32_t max_message_bytes = 65536;
    double max_client_messages_per_s = 20.0;    ///< sustained requests per client
    std::uint32_t client_message_burst = 40;    ///< requests at once before the rate applies
    double max_address_messages_per_s = 500.0;  ///< the same per peer address, over its connections
    std::uint32_t address_message_burst = 1000;
    std::uint32_t max_subscribe_subjects = 64;  ///< subject ids one Subscribe may name
    // [control]
    std::string control_token;  ///< "" = control off; else at least kMinControlTokenLength characters
    bool control_loopback_only = true;
    // [outputs] (docs/outputs.md)
    Endpoint bvh_listen{"0.0.0.0", 7002};
    bool bvh_live = true;  ///< serve live BVH on bvh_listen
    std::uint32_t bvh_max_clients = 64;
    std::uint32_t bvh_threads = 1;   ///< live BVH serve threads; clients spread over them
    std::uint32_t bvh_subject = 0;   ///< 0 = first subject with a frame
    double bvh_units_per_m = 100.0;  ///< "cm" = 100, "m" = 1, "mm" = 1000
    std::string bvh_rotation_order = "ZXY";
    double bvh_frame_time_s = 0.0;  ///< 0 = measured from the subject's frames
    std::string record_dir = ".";
    double record_flush_interval_s = 1.0;
    bool raw_record = false;       ///< record every raw sample from start
    double raw_rotate_mb = 256.0;  ///< 0 = never by size
    double raw_rotate_s = 3600.0;  ///< 0 = never by time
    std::uint32_t raw_ring_capacity = 16384;
    std::uint32_t export_memory_mb = 256;              ///< take exports held in memory, all peers
    std::uint32_t export_memory_per_address_mb = 128;  ///< take exports held for one peer address
    std::uint32_t offline_export_max_mb = 384;         ///< estimate above which an offline export is refused
    double take_start_min_free_mb = 64.0;              ///< free space a take start needs on record_dir; 0 = no check
    // [http] (docs/viewer.md): viewer page, pose WebSocket, /metrics, /healthz
    bool http_enabled = true;
    Endpoint http_listen{"0.0.0.0", 8080};
    std::uint32_t http_max_clients = 64;            ///< HTTP + WebSocket connections at once
    std::uint32_t http_threads = 1;                 ///< serve threads; connections spread over them
    std::uint32_t http_ws_queue_frames = 16;        ///< per-WebSocket frame queue (oldest dropped)
    std::vector<std::string> http_allowed_origins;  ///< origins besides the served host that may open /ws
    /// Host names besides localhost and this machine's own that a request's Host may carry
    /// (DNS rebinding: origin_check.hpp); IP literals always may.
    std::vector<std::string> http_allowed_hosts;
    // [limits] (docs/security.md, "Connection slots"): connections one peer address may
    // hold per port (0 = no limit), whether that applies to loopback peers, and how long a
    // connection may go without progress before a new one may take its slot.
    std::uint32_t sink_per_address = 8;
    std::uint32_t pose_per_address = 64;
    std::uint32_t bvh_per_address = 16;
    std::uint32_t http_per_address = 16;
    bool limits_on_loopback = false;
    double stall_evict_s = 5.0;
    // [cluster] (docs/outputs.md, "Cluster publisher"): poses to a NATS cluster
    std::string cluster_nats_url;  ///< "" = off; one URL or a comma-separated list
    std::string cluster_site = "venue";
    std::string cluster_host_id;  ///< "" = the host name
    std::string cluster_user;
    std::string cluster_password;
    std::string cluster_creds_file;
    std::string cluster_nkey_seed_file;
    bool cluster_allow_anonymous = false;
    std::string cluster_calibration_key_file;  ///< signs and checks shared calibrations ("" = unsigned)
    std::string cluster_tls_ca_file;
    std::string cluster_tls_cert_file;
    std::string cluster_tls_key_file;
    std::uint32_t cluster_raw_replicas = 1;
    std::uint32_t cluster_queue_frames = 1024;        ///< frames between the pipeline and the publisher
    std::uint32_t cluster_raw_queue_samples = 65536;  ///< raw samples between ingest and the publisher
    // [vmc] (docs/outputs.md, "VMC"): one subject as the VMC protocol (OSC over UDP)
    bool vmc_enabled = false;
    std::vector<std::string> vmc_destinations{"127.0.0.1:39539"};  ///< "host:port"; names resolved at check/start
    std::uint32_t vmc_subject = 0;                                 ///< 0 = first subject with a frame
    std::vector<std::pair<std::string, std::string>> vmc_bones;    ///< segment -> HumanBodyBones; empty = default

    bool operator==(const DaemonConfig&) const = default;
};

/// The text of config/mocapd.toml, compiled in.
std::string_view embedded_default_config();

/// Parses and validates TOML text. On error returns std::nullopt and sets *error to
/// "<source_name>:<line>: <key>: <message>". Never throws.
std::optional<DaemonConfig> parse_config(std::string_view toml_text, std::string_view source_name, std::string* error);

/// Reads a file and parses it (errors as above; an unreadable file names the path). A path
/// that is not a regular file (a directory, a FIFO) and a file with no settings (empty,
/// blanks or comments only) are refused. What the text alone cannot show (filters, ports
/// shared by two listeners, directories) is checked by check_config (daemon/config_check.hpp).
std::optional<DaemonConfig> load_config_file(const std::string& path, std::string* error);

/// [cluster].host_id, or when empty the host name up to its first '.' with any character a NATS
/// subject token cannot hold ('*', '>', whitespace) replaced by '_'; "" if there is no host name.
std::string cluster_host_id(const DaemonConfig& config);

}  // namespace mocap::daemon
