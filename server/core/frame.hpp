// frame.hpp — the values that travel through the pipeline: one segment's sample in,
// one subject's assembled pose frame out.
//
// Ownership: plain values, copied into fixed-capacity rings (no heap: docs/style.md, "Hot path never allocates").
// Times: every *_us field is microseconds. sample_us is the sample instant on the sink's
// clock; the stage stamps are the daemon host's wall clock (CLOCK_REALTIME, µs since the
// epoch) so that a client on the same host (or a PTP/NTP-synchronised one) can measure
// sink-send -> client-receive. Nothing here reads a clock: the daemon stamps them.
#pragma once

#include <array>
#include <cstdint>

#include "core/imu_sample.hpp"

namespace mocap {

/// Largest number of segments one subject may have (the default body has 15).
inline constexpr std::size_t kMaxSegments = 32;

/// Per-stage timestamps, wall clock µs; 0 = stage not reached.
struct StageTimes {
    std::int64_t sink_send_us = 0;  ///< sink's send time of the packet that carried the sample
    std::int64_t received_us = 0;   ///< daemon: packet decoded / CAN frame read
    std::int64_t filtered_us = 0;   ///< daemon: filter update finished (latest segment)
    std::int64_t assembled_us = 0;  ///< daemon: subject frame complete or deadline hit
    std::int64_t encoded_us = 0;    ///< daemon: frame encoded for clients
    std::int64_t dequeued_us = 0;   ///< daemon: worker took the sample off its queue (latest)
};

/// A sample on its way from ingest to the segment's filter worker.
struct SegmentSample {
    std::uint32_t subject_id = 0;
    std::uint16_t segment_index = 0;                        ///< index into the subject's skeleton
    std::uint8_t node_id = 0;                               ///< CAN node id it came from
    bool has_node_quat = false;                             ///< node ran its own filter: node_q is the estimate
    std::uint64_t sync = 0;                                 ///< SYNC counter, extended past wrap (monotonic)
    ImuSample imu{};                                        ///< raw sample (t_us = sample instant)
    std::array<double, 4> node_q_wxyz{1.0, 0.0, 0.0, 0.0};  ///< q_earth_sensor from the node
    StageTimes times{};
};

/// Flags of one segment in an assembled frame.
enum SegmentFlags : std::uint8_t {
    kSegmentStale = 1u << 0,       ///< no sample for this SYNC instant: last good pose held
    kSegmentNeverSeen = 1u << 1,   ///< no sample since start: identity pose
    kSegmentCalibrated = 1u << 2,  ///< sensor-to-segment calibration applied
    kSegmentFromNode = 1u << 3,    ///< orientation computed on the node, not in the daemon
    // Where the segment's heading came from (at most one is set; none before a heading is
    // known or when the daemon does not say): its own magnetometer, the joints of the body
    // (fusion/chain_estimator.hpp), or the gyroscope alone (held: nothing observed it lately).
    kSegmentHeadingMag = 1u << 4,
    kSegmentHeadingJoints = 1u << 5,
    kSegmentHeadingGyro = 1u << 6,
};

/// What the segment's filter says about its magnetometer heading (SegmentPose::mag).
enum class SegmentMag : std::uint8_t {
    kNone = 0,      ///< no magnetometer heading (no field, or a filter that does not split it)
    kRejected = 1,  ///< the filter holds its heading on the gyro: the field is rejected
    kTrusted = 2,   ///< the filter uses the field now
};

/// One segment's filtered orientation (before skeleton calibration), and what the chain stage
/// needs to replace the filter's magnetometer heading (filter/orientation_filter.hpp,
/// HeadingSplit): q_earth_sensor = Rz(mag_heading_rad) ⊗ q6.
struct SegmentPose {
    std::array<double, 4> q_earth_sensor_wxyz{1.0, 0.0, 0.0, 0.0};
    std::int64_t sample_us = 0;
    std::uint8_t flags = kSegmentNeverSeen;
    SegmentMag mag = SegmentMag::kNone;
    std::uint8_t frame_epoch = 0;       ///< changes when the filter's 6D heading frame starts again
                                        ///< (its attitude restarted after a gap), modulo 256
    float mag_heading_rad = 0.0f;       ///< the filter's heading correction about the vertical
    float field_norm_ut = 0.0f;         ///< the field the filter sees (0: unknown)
    float field_heading_rad = 0.0f;     ///< the field's own heading in the 6D frame (HeadingSplit)
    bool field_usable = false;          ///< the field keeps its norm and dip (HeadingSplit)
    float field_dip_rad = 0.0f;         ///< its dip, positive down
    std::array<float, 3> rate_rad_s{};  ///< bias-corrected rate, sensor frame
    std::array<float, 3> accel_m_s2{};  ///< specific force, sensor frame (for the joint centres' constraint)
};

/// One subject at one SYNC instant, all segments, as the assembler emits it.
struct SubjectFrame {
    std::uint32_t subject_id = 0;
    std::uint64_t sync = 0;
    std::int64_t sample_us = 0;  ///< sample instant (sink clock)
    StageTimes times{};
    std::uint16_t segment_count = 0;
    std::array<SegmentPose, kMaxSegments> segments{};
};

}  // namespace mocap
