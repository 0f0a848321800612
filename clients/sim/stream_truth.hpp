// stream_truth.hpp — the true joint angles `mocap-sim stream --truth` writes, in exactly the
// format of `mocap-client angles` and `mocapd --replay --angles-out` (serve/angles_csv.hpp):
//
//   subject,sync,t_s,left_hip.flexion_deg,left_hip.abduction_deg,left_hip.rotation_deg,...
//
// The angles come from the true q_earth_segment of every segment of the body through the
// daemon's own code: skeleton::default_joint_specs (the joints PoseSolver uses) and
// compute_joint_angles, named "<joint>.<axis>" in the order the daemon announces them
// (Hello.skeleton.joint_angle_names), so a live session compares to the truth column by
// column.
//
// `sync` is what mocapd calls that instant on a sink's first connection (SyncExtender): the
// daemon's FrameReassembler starts the first stream at 2^32 + the sink's 32-bit SYNC counter
// and adds 2^32 at every wrap, so rows join the daemon's output on sync. (After a reconnect
// the daemon continues its own count; the low 32 bits are always the sink's counter.)
//
// Thread-safety: one TruthAngles per thread. Cost: append_row is O(joints), no allocation once
// `out` has grown to a row's size.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "skeleton/body_model.hpp"
#include "skeleton/joint_angles.hpp"

namespace mocap::sim {

/// The daemon's extended SYNC value of each counter of one uninterrupted sink stream.
class SyncExtender {
public:
    std::uint64_t extend(std::uint32_t counter) {
        if (have_ && counter < last_) ++wraps_;
        have_ = true;
        last_ = counter;
        return ((wraps_ + 1u) << 32u) + counter;
    }

private:
    bool have_ = false;
    std::uint32_t last_ = 0;
    std::uint64_t wraps_ = 0;
};

class TruthAngles {
public:
    explicit TruthAngles(const skeleton::BodyModel& model);

    /// "<joint>.<axis>" for every joint and axis (flexion, abduction, rotation).
    [[nodiscard]] const std::vector<std::string>& names() const { return names_; }
    /// The CSV header line, with its newline.
    [[nodiscard]] std::string header() const;
    /// Appends one row: the angles of q_earth_segment (every segment of the model, in order).
    void append_row(std::uint32_t subject, std::uint64_t sync, std::int64_t t_us,
                    std::span<const skeleton::Quat> q_earth_segment, std::string& out);

private:
    std::vector<skeleton::JointSpec> joints_;
    std::vector<std::string> names_;
    std::vector<skeleton::JointAngles> angles_;
    std::vector<double> values_rad_;
};

}  // namespace mocap::sim
