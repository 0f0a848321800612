// serve_config.hpp — everything the daemon gives the pose service: settings, the
// skeleton/subject description announced in Hello, and the control/stats callbacks.
//
// Units are in the names. The daemon fills these from its TOML config; the defaults
// here are the documented defaults (config/mocapd.toml repeats them).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/connection_slots.hpp"

#include "core/metrics_registry.hpp"

namespace mocap::serve {

class ControlAttemptLimiter;

struct ServeConfig {
    std::string bind_address = "0.0.0.0";           ///< IPv4/IPv6 literal to listen on
    std::uint16_t port = 7001;                      ///< 0 = any free port (tests); see PoseServer::port()
    std::size_t io_threads = 1;                     ///< serve threads; each owns a share of the clients
    std::size_t max_clients = 256;                  ///< slots; a client refused gets Goodbye(SERVER_FULL)
    PeerLimits limits{};                            ///< [limits] pose_per_address, loopback, stall_evict_s
    std::size_t queue_frames = 64;                  ///< per-client frame queue; the oldest frame is
                                                    ///< dropped (and announced) when it is full
    std::uint32_t subscribe_timeout_ms = 5000;      ///< an unsubscribed client must send a valid
                                                    ///< message at least this often
    std::uint32_t max_client_message_bytes = 4096;  ///< longer ClientMessages close the link
    double max_client_messages_per_s = 20.0;        ///< sustained request rate per client
    std::uint32_t client_message_burst = 40;        ///< requests allowed at once before the rate applies
    /// The same per peer address, over all its connections, so that reconnecting gains
    /// nothing (address_budget.hpp).
    double max_address_messages_per_s = 500.0;
    std::uint32_t address_message_burst = 1000;
    /// Subject ids one Subscribe may name (an empty list means every subject, so a client
    /// never needs more ids than there are subjects); more: Goodbye(MALFORMED), counted in
    /// serve.subscribe_too_many_subjects. Bounds what one request costs the serve thread.
    std::uint32_t max_subscribe_subjects = 64;
    /// Client requests one serve thread handles per turn; frames handed over meanwhile are
    /// delivered before the next turn (request_budget.hpp), so requests can delay a frame
    /// by at most two turns.
    std::size_t requests_per_turn = 32;
    /// SO_SNDBUF per client (0 = kernel default, which grows to MiBs: tens of seconds of
    /// one subject's frames held in the kernel for a stalled client before its queue
    /// drops anything). Bounded, a lagging client's data stays fresh.
    std::uint32_t send_buffer_bytes = 128 * 1024;
    std::uint32_t close_grace_ms = 1000;        ///< time a closing client gets to read its Goodbye
    std::size_t publish_backlog_frames = 4096;  ///< frames waiting for one serve thread;
                                                ///< beyond it frames are dropped (counted)
    std::string control_token;                  ///< empty = every control request is refused
    bool control_loopback_only = true;          ///< refuse control from non-loopback peers
    /// Failed-attempt limits shared with HTTP (the daemon makes one); null = the server
    /// makes its own with the default limits (control_access.hpp).
    std::shared_ptr<ControlAttemptLimiter> control_attempts;
    std::uint32_t frame_rate_hz = 100;      ///< announced in Hello
    std::string world_frame = "ENU";        ///< announced in Hello ("ENU" or "NED")
    std::string server_version = "mocapd";  ///< announced in Hello
    /// Wall clock (CLOCK_REALTIME µs) for encoded_us and Stats; empty = system_clock.
    std::function<std::int64_t()> wall_clock_us;
};

struct SegmentInfo {
    std::string name;
    int parent = -1;                   ///< index of the parent segment; -1 = root
    std::array<double, 3> offset_m{};  ///< joint position in the parent's frame
    std::uint32_t node_id = 0;         ///< CAN node id of the segment's sensor
};

struct SubjectInfo {
    std::uint32_t id = 0;
    std::string name;
};

/// What Hello tells every client: segment order of frames, joint-angle names, subjects.
struct ServeDescription {
    std::vector<SegmentInfo> segments;
    std::vector<std::string> joint_angle_names;
    std::vector<SubjectInfo> subjects;
};

enum class CalibrationPose { kT, kN };

struct ControlResult {
    bool ok = false;
    std::string error;  ///< shown to the client when !ok
    std::string take;   ///< start/stop of a take: its name (ControlReply.take_name)
    static ControlResult success() { return {true, {}, {}}; }
    static ControlResult failure(std::string why) { return {false, std::move(why), {}}; }
};

/// Actions the daemon performs for control requests, and its stats. Each is called on
/// a serve thread after the token was checked; it must return quickly (start the work
/// elsewhere and report "accepted" rather than block: it delays that thread's clients).
/// An empty function answers "not supported". Must be safe to call from any thread.
struct ControlHandlers {
    std::function<ControlResult(std::uint32_t subject_id, CalibrationPose pose)> calibrate;
    std::function<ControlResult(const std::string& path)> start_recording;  ///< "" = default
    std::function<ControlResult()> stop_recording;
    /// Takes (serve/take_recorder.hpp): name "" = generated from the start time.
    std::function<ControlResult(const std::string& name, const std::string& notes)> start_take;
    std::function<ControlResult()> stop_take;
    std::function<ControlResult()> reload;
    /// Every metric for StatsRequest: the daemon's registry (core/metrics_registry.hpp),
    /// which holds the pose service's own counters too. Empty = the server's own counters.
    std::function<MetricsSnapshot()> stats;
};

}  // namespace mocap::serve
