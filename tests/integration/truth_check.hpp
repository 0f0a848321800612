// truth_check.hpp — calibrated poses against mocap-sim's own truth file (`stream --truth-poses`):
// the orientation check of the calibration tests (daemon_test.cpp, calibration_kv_test.cpp).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <tuple>
#include <vector>

#include "math/quaternion.hpp"
#include "mocap/v1/mocap.pb.h"

namespace mocap::itest {

/// What the frames of one subject say against the truth.
struct TruthErrors {
    std::size_t calibrated_frames = 0;  ///< frames whose first segment is calibrated
    std::size_t motion_frames = 0;      ///< of those, at or after the motion's start
    std::size_t malformed = 0;          ///< calibrated frames without segment_count segments
    std::size_t stale = 0;              ///< stale segments in motion frames
    std::vector<double> err_deg;        ///< one per segment of each motion frame, sorted
    [[nodiscard]] double median() const { return err_deg.empty() ? 0.0 : err_deg[err_deg.size() / 2]; }
    [[nodiscard]] double p95() const { return err_deg.empty() ? 0.0 : err_deg[err_deg.size() * 95 / 100]; }
};

/// One value of the truth file: a segment of a subject at a SYNC counter.
struct TruthKey {
    std::uint32_t subject;
    std::uint32_t counter;
    std::string segment;
    bool operator<(const TruthKey& o) const {
        return std::tie(subject, counter, segment) < std::tie(o.subject, o.counter, o.segment);
    }
};
/// Every segment's true orientation (q_world_segment) in the truth CSV at `path`.
std::map<TruthKey, math::Quat> read_truth(const std::string& path);

/// The frame's q_world_segment of segment i, normalised.
math::Quat segment_q(const v1::SkeletonFrame& f, int i);

/// The SYNC counter of a frame (the low 32 bits of its sync), which the truth file keys on.
std::uint32_t counter_of(const v1::SkeletonFrame& f);

/// Orientation errors of the calibrated frames of `subject` from SYNC counter `motion_start`
/// on. With heading "earth" and a given facing of 0 the output equals the truth turned by the
/// subject's own facing ψ during calibration, q_out ⊗ Rz(ψ) = q_true, and ψ is the truth's
/// first pelvis heading. segment_names: the Hello's, in frame order.
TruthErrors truth_errors(const std::vector<v1::SkeletonFrame>& frames, const std::vector<std::string>& segment_names,
                         const std::string& truth_csv_path, std::uint32_t subject, std::uint32_t motion_start);

}  // namespace mocap::itest
