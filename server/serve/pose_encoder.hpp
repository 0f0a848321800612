// pose_encoder.hpp — turns one subject frame into the bytes every client receives.
//
// A frame is encoded ONCE per field selection into an immutable shared buffer
// (length prefix + mocap.v1.ServerMessage{frame}); every subscribed client writes the
// same buffer (docs/style.md, "Encode once, drop the oldest"). The encoder reuses one message object, so after the
// first frames its repeated fields keep their capacity and encoding allocates only the
// output buffer.
//
// Thread-safety: one PoseEncoder per thread (it owns a scratch message).
// Cost: ~135 ns and 462 bytes for a 15-segment frame with orientations + positions,
// ~160 ns / 888 bytes with every field (tests/serve/serve_bench, Release).
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "core/frame.hpp"
#include "skeleton/skeleton_pose.hpp"

namespace mocap::v1 {
class ServerMessage;
}

namespace mocap::serve {

/// Bits of a subscription's field selection (equal to mocap.v1.Field).
enum FieldBits : std::uint32_t {
    kFieldOrientations = 1u << 0,
    kFieldPositions = 1u << 1,
    kFieldJointAngles = 1u << 2,
    kFieldRaw = 1u << 3,
};
inline constexpr std::uint32_t kFieldAll = 0xFu;
/// Number of distinct field selections (index 1..15 used; 0 is normalised away).
inline constexpr std::size_t kFieldCombinations = 16;

/// Unknown bits dropped; 0 becomes orientations | positions.
constexpr std::uint32_t normalize_fields(std::uint32_t fields) {
    fields &= kFieldAll;
    return fields == 0 ? (kFieldOrientations | kFieldPositions) : fields;
}

using SharedBytes = std::shared_ptr<const std::string>;

/// Length-prefixed serialisation of any ServerMessage into a new shared buffer.
/// Returns nullptr if serialisation fails (never for well-formed messages).
SharedBytes encode_server_message(const v1::ServerMessage& message);

class PoseEncoder {
public:
    PoseEncoder();
    ~PoseEncoder();
    PoseEncoder(const PoseEncoder&) = delete;
    PoseEncoder& operator=(const PoseEncoder&) = delete;

    /// Encodes `frame` + `pose` with the selected `fields` (normalised internally);
    /// stage stamps come from frame.times except encoded_us, given here (wall µs).
    /// Precondition (asserted): pose.segment_count == frame.segment_count when
    /// orientations, positions or joint angles are selected.
    SharedBytes encode_frame(const SubjectFrame& frame, const skeleton::SkeletonPose& pose, std::uint32_t fields,
                             std::int64_t encoded_us);

private:
    std::unique_ptr<v1::ServerMessage> message_;  ///< reused scratch message
};

}  // namespace mocap::serve
