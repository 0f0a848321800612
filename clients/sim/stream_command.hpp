// stream_command.hpp — `mocap-sim stream`: K simulated sink nodes with their sensor nodes,
// streaming to mocapd over TCP; the load generator of the integration tests and benchmarks.
//
//   mocap-sim stream --connect HOST:PORT[,HOST:PORT...] [--subjects K] [--nodes N] [--rate HZ]
//                    [--mode raw|quat] [--duration S] [--motion walk|FILE.bvh] [--loss P]
//                    [--seed N] [--truth FILE.csv] [--truth-poses FILE.csv]
//                    [--dropout NODE:START_S:END_S]... [--jitter-us J] [--calibrate-s S]
//                    [--noise-scale X] [--magnetic-env clean|lab|steel-floor|FILE.toml]
//                    [--magnet SEGMENT[:UT]]... [--sink-rate-stats] [--no-early-close]
//                    [--first-counter C]
//
// Each subject k (1..K) is one sink_node (the real sink core, firmware/sink_node) with sink
// id k and its own TCP connection, and N sensor nodes on the first N segments of the default
// 15-segment body (node ids 1..N). Its HAL: can_transmit hands SYNC to the subject's nodes,
// which compute their sample for that instant (stream_node.hpp) from the subject's motion
// (stream_motion.hpp: T-pose still for --calibrate-s, then walk or BVH) and queue their CAN
// frames for can_receive, released after a per-node delay drawn in [0, --jitter-us];
// --loss P drops each node frame with probability P before the sink sees it; --dropout
// silences a node id in every subject for a time window (repeatable). The uplink is
// stream_uplink.hpp. Subjects differ by a seeded heading and start 10 m apart.
// --connect with several hosts is the sink's ordered host list (sink_node.h, "Host list and
// failover"): a lost connection, or a host silent for 750 ms once it has sent keepalives,
// moves each sink to the next host, wrapping.
//
// Clock: time_us is CLOCK_REALTIME in µs, so the sink timestamps compare directly with the
// daemon's receive times on the same host (latency = daemon clock - sink timestamp).
// Simulated time is the SYNC index / rate (exact), so the motion and the truth do not
// depend on scheduling; a SYNC the loop is late for is skipped by the core (counted).
//
// One thread, one event loop: it sleeps until the earliest sink deadline or frame release
// (clock_nanosleep), polls what is due, and allocates nothing per sample once running.
// Sinks start staggered over one period so that their SYNCs do not all fall together.
// --duration bounds everything (a peer that never accepts is retried with the core's
// back-off until then). SIGINT/SIGTERM stop it early.
//
// Magnetometers (raw mode) read the field of --magnetic-env at their own position
// (magnetic_env.hpp; default clean: the uniform 50 µT at 60° dip everywhere, as before); the
// environment's floor is seeded from --seed. --magnet SEGMENT[:UT] (repeatable) adds a
// constant field of UT µT (default 30), in a seeded direction fixed in the sensor frame, to
// the magnetometer of that segment's node in every subject: a magnet or a phone carried on it.
//
// --truth writes the true joint angles in exactly the format of `mocap-client angles`
// (serve/angles_csv.hpp): subject,sync,t_s,<joint>.<axis>_deg,... one row per subject and
// SYNC, computed from the true segment orientations by the daemon's own joint-angle code
// (skeleton/joint_angles.hpp, default_joint_specs of the default body). `sync` is the value
// mocapd gives that instant for a sink's first connection: 2^32 + the SYNC counter the sink
// sent, plus 2^32 per wrap of the counter (frame_reassembler.hpp), so rows join the daemon's
// output on sync; t_s is the simulator's clock at the SYNC (CLOCK_REALTIME, within a few µs of
// the sink's stamp, which is the daemon's t_s); subject is the sink id (the daemon's subject
// with subject_id_base = 0).
// --truth-poses writes one CSV row per subject, segment and SYNC: t_us (the SYNC's send time),
// subject, segment (name), node, counter, seg_qw..seg_qz = q_earth_segment (what the
// daemon's calibrated output should match), sensor_qw..sensor_qz = q_earth_sensor (what a
// filter's raw output should match). ENU. Rows of dropped-out nodes are written as well.
//
// --no-early-close makes the sinks close a packet only at the next SYNC (sink_node.h), to
// measure what the early close saves.
// --first-counter starts every sink's SYNC counter at C (e.g. near 2^32 to cross the wrap);
// the motion and the truth still start at the first instant.
// --sink-rate-stats prints one JSON line at the end on stdout (see run_stream_command).
// Exit code: 0, or 1 if a subject never connected or a truth file could not be written, 2 for
// bad arguments.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

namespace mocap::sim {

struct StreamCommandOptions {
    std::string connect;
    int subjects = 1;
    int first_sink_id = 1;  ///< sinks get ids first_sink_id .. first_sink_id + subjects - 1
    int nodes = 15;
    int rate_hz = 100;
    std::string mode = "raw";
    double duration_s = 10.0;
    std::string motion = "walk";
    double loss = 0.0;
    std::uint64_t seed = 1;
    std::string truth_path;        ///< --truth: joint angles, mocap-client angles' format
    std::string truth_poses_path;  ///< --truth-poses: every segment's and sensor's orientation
    std::vector<std::string> dropouts;
    double jitter_us = 0.0;
    double calibrate_s = 2.0;
    double noise_scale = 1.0;
    std::string magnetic_env = "clean";
    std::vector<std::string> magnets;
    bool sink_rate_stats = false;
    bool early_close = true;          ///< the sink core's early batch close (--no-early-close: off)
    std::uint32_t first_counter = 0;  ///< SYNC counter of the first instant (--first-counter)
};

/// A parsed --dropout.
struct NodeDropout {
    int node = 0;
    double start_s = 0.0;
    double end_s = 0.0;
};
/// "NODE:START_S:END_S" with START < END; false with *error otherwise.
bool parse_dropout(const std::string& text, NodeDropout* out, std::string* error);

/// A parsed --magnet.
struct SegmentMagnet {
    std::string segment;
    double field_ut = 30.0;
};
/// "SEGMENT[:UT]" with UT in (0, 2000]; false with *error otherwise (the segment name is
/// checked against the body by the caller).
bool parse_magnet(const std::string& text, SegmentMagnet* out, std::string* error);

CLI::App* add_stream_command(CLI::App& app, StreamCommandOptions& options);

/// Runs until --duration. The stats JSON (one line): subjects, nodes, rate_hz, mode,
/// elapsed_s, requested_samples_per_s, samples, samples_per_s, can_frames, packets,
/// packets_dropped, frames_dropped, lost_can_frames, dropout_samples, syncs_skipped,
/// early_closes, cpu_percent (user + system of this process over the elapsed time), and
/// per_subject: [{subject, packets, frames, samples, packets_dropped, frames_dropped,
/// lost_can_frames, dropout_samples, syncs_skipped, early_closes, connects, disconnects,
/// packets_busy, keepalives_in, keepalive_timeouts, host_switches}].
int run_stream_command(const StreamCommandOptions& options);

}  // namespace mocap::sim
