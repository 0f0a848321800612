// body_chain.hpp — the chain stage for a body model (docs/fusion.md): which joints hold which
// relative headings, and for one subject the ChainEstimator (fusion/chain_estimator.hpp) that
// turns the filters' 6D orientations and magnetometer headings into heading-consistent
// q_earth_sensor before the calibration is applied (pose_solver.hpp).
//
// Joints of the default body (by the canonical segment names, body_model.hpp), axes in the
// segment frames of the T-pose (x forward, y left, z up):
//   knee                 hinge  flexion axis y in thigh and calf
//   elbow                2dof   flexion axis z fixed in the upper arm (palms down), the
//                               forearm's long axis y fixed in the forearm (pronation)
//   wrist                2dof   flexion axis x fixed in the forearm, deviation axis z in the hand
//   ankle                2dof   dorsiflexion axis y fixed in the calf, inversion axis x in the foot
//   spine, neck, shoulder, hip, and every joint of another body: ball (no per-sample
//   constraint; the magnetometer where fields agree, else the gyro holds it)
// The axes in the sensor frames follow from the calibration's mounting rotations:
// j_sensor = q_sensor_segment ⊗ j_segment. Before a calibration the joints have no axes.
//
// Axes from the motion (FusionOptions::estimate_axes, `[fusion] axis = "estimate"`): the hinges
// learn their axes in the sensor frames from the gyroscopes (hinge_axis_estimator.hpp). A
// calibration taken where the field was disturbed has mounting rotations off by the field's
// heading error about the vertical of the calibration pose; the learned axis shows that error,
// and refine_calibration() turns both segments' mountings about that vertical to agree with
// it, so the joint angles, not only the headings, come out right. The caller saves the refined
// calibration, so a subject calibrates once.
//
// Not thread-safe: one per subject, on the assembler thread. Cost per frame: the chain step
// (O(joints)), no allocation after construction.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "core/frame.hpp"
#include "fusion/chain_estimator.hpp"
#include "skeleton/body_model.hpp"
#include "skeleton/calibration.hpp"

namespace mocap::skeleton {

struct FusionOptions {
    fusion::ChainParams chain{};  ///< chain.mode is the heading source ([fusion] heading)
    bool estimate_axes = false;   ///< [fusion] axis = "estimate": hinges learn their axes
};

/// A joint of the body as the chain stage sees it: axes in the segment frames (T-pose).
struct BodyJoint {
    fusion::JointDef def;  ///< parent, child, type (axes unset: sensor frames come later)
    Vec3 axis_parent_segment = Vec3::UnitY();
    Vec3 axis_child_segment = Vec3::UnitY();
};

/// The joints of the model (see the file comment), one per non-root segment.
std::vector<BodyJoint> body_joints(const BodyModel& model);

/// The HeadingSource as SegmentFlags (kSegmentHeading*, 0 for none).
std::uint8_t heading_flags(fusion::HeadingSource source);

class BodyChain {
public:
    BodyChain(const BodyModel& model, const FusionOptions& options);

    /// A calibration was installed: the joints' axes in the sensor frames from its mountings
    /// (segments it did not calibrate keep theirs unknown). anchor: the calibration was taken
    /// from this chain's own output a moment ago, so each joint's δ starts from the relative
    /// heading shown then (ChainEstimator::anchor); false for one loaded or made elsewhere, where
    /// only the joints that already had a δ keep it.
    void on_calibration(const Calibration& calibration, bool anchor);

    /// One frame: replaces q_earth_sensor[i] (the filters' own, filled by the caller) with the
    /// chain's and writes each segment's heading flags. Segments flagged stale or never seen
    /// take no part in the constraints.
    void apply(const SubjectFrame& frame, std::span<Quat> q_earth_sensor, std::span<std::uint8_t> flags);

    /// A learned hinge axis that disagrees with the calibration's mountings by more than
    /// min_turn_deg: turns those mountings (see the file comment). True when `calibration`
    /// was changed (the caller installs and saves it).
    bool refine_calibration(const BodyModel& model, Calibration& calibration, double min_turn_deg = 2.0);

    [[nodiscard]] const fusion::ChainEstimator& estimator() const { return estimator_; }
    [[nodiscard]] const std::vector<BodyJoint>& joints() const { return joints_; }

private:
    BodyModel model_;
    std::vector<BodyJoint> joints_;
    fusion::ChainEstimator estimator_;
    std::vector<fusion::SegmentInput> in_;
    std::vector<fusion::SegmentOutput> out_;
};

}  // namespace mocap::skeleton
