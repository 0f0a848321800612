#include "skeleton/body_chain.hpp"

#include <cmath>
#include <numbers>
#include <string_view>

namespace mocap::skeleton {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

Quat rot_z(double a) {
    return Quat(std::cos(0.5 * a), 0.0, 0.0, std::sin(0.5 * a));
}

/// Type and segment-frame axes of the joint above `child`, by the canonical names.
BodyJoint joint_above(const BodyModel& model, int child) {
    BodyJoint j;
    j.def.parent = model.segments[static_cast<std::size_t>(child)].parent;
    j.def.child = child;
    j.def.type = fusion::JointType::kBall;
    const std::string_view name = model.segments[static_cast<std::size_t>(child)].name;
    const auto is = [&](std::string_view a, std::string_view b) { return name == a || name == b; };
    if (is(seg::kLeftCalf, seg::kRightCalf)) {
        j.def.type = fusion::JointType::kHinge;
        j.axis_parent_segment = j.axis_child_segment = Vec3::UnitY();
    } else if (is(seg::kLeftForearm, seg::kRightForearm)) {
        j.def.type = fusion::JointType::kTwoDof;
        j.axis_parent_segment = Vec3::UnitZ();
        j.axis_child_segment = Vec3::UnitY();
    } else if (is(seg::kLeftHand, seg::kRightHand)) {
        j.def.type = fusion::JointType::kTwoDof;
        j.axis_parent_segment = Vec3::UnitX();
        j.axis_child_segment = Vec3::UnitZ();
    } else if (is(seg::kLeftFoot, seg::kRightFoot)) {
        j.def.type = fusion::JointType::kTwoDof;
        j.axis_parent_segment = Vec3::UnitY();
        j.axis_child_segment = Vec3::UnitX();
    }
    j.def.cos_axis_angle = j.axis_parent_segment.dot(j.axis_child_segment);
    return j;
}

std::vector<fusion::JointDef> defs_of(const std::vector<BodyJoint>& joints, bool estimate_axes) {
    std::vector<fusion::JointDef> defs;
    for (const BodyJoint& j : joints) {
        defs.push_back(j.def);
        if (estimate_axes && j.def.type == fusion::JointType::kHinge) defs.back().estimate_axes = true;
    }
    return defs;
}

/// The signed angle about the unit vector v from a to b, both projected on the plane normal
/// to v; nullopt when either projection is short (nearly along v).
std::optional<double> angle_about(const Vec3& v, const Vec3& a, const Vec3& b) {
    const Vec3 pa = a - a.dot(v) * v, pb = b - b.dot(v) * v;
    if (pa.norm() < 0.5 || pb.norm() < 0.5) return std::nullopt;
    return std::atan2(v.dot(pa.cross(pb)), pa.dot(pb));
}

}  // namespace

std::vector<BodyJoint> body_joints(const BodyModel& model) {
    std::vector<BodyJoint> joints;
    for (std::size_t i = 1; i < model.size(); ++i)
        joints.push_back(joint_above(model, static_cast<int>(i)));
    return joints;
}

std::uint8_t heading_flags(fusion::HeadingSource source) {
    switch (source) {
        case fusion::HeadingSource::kMagnetometer:
            return kSegmentHeadingMag;
        case fusion::HeadingSource::kJoints:
            return kSegmentHeadingJoints;
        case fusion::HeadingSource::kGyro:
            return kSegmentHeadingGyro;
        case fusion::HeadingSource::kNone:
            break;
    }
    return 0;
}

BodyChain::BodyChain(const BodyModel& model, const FusionOptions& options)
    : model_(model),
      joints_(body_joints(model)),
      estimator_(model.size(), defs_of(joints_, options.estimate_axes), options.chain),
      in_(model.size()),
      out_(model.size()) {}

void BodyChain::on_calibration(const Calibration& calibration, bool anchor) {
    for (std::size_t j = 0; j < joints_.size(); ++j) {
        const BodyJoint& b = joints_[j];
        const auto p = static_cast<std::size_t>(b.def.parent), c = static_cast<std::size_t>(b.def.child);
        if (!calibration.calibrated[p] || !calibration.calibrated[c]) continue;
        // A calibration made elsewhere (another host, a file) says nothing of this chain's δ; a
        // joint that already has one (its fields agreed, or it had axes) keeps it rather than
        // restart from the constraints alone.
        const bool keep = anchor || estimator_.status(j).initialised;
        // The centre as the model puts it, each sensor at its segment's middle (as the
        // simulator places them; a real mounting elsewhere is corrected once the motion shows it).
        const auto& sp = model_.segments[p];
        const auto& sc = model_.segments[c];
        estimator_.set_centre(j, math::rotate(calibration.q_sensor_segment[p], Vec3(sc.offset_m - 0.5 * sp.end_m)),
                              math::rotate(calibration.q_sensor_segment[c], Vec3(-0.5 * sc.end_m)));
        if (b.def.type != fusion::JointType::kBall) {
            estimator_.set_axes(j, math::rotate(calibration.q_sensor_segment[p], b.axis_parent_segment),
                                math::rotate(calibration.q_sensor_segment[c], b.axis_child_segment));
        }
        // The mountings were taken from what the chain showed: start δ there, so the
        // constraints refine it rather than pick one of a 2-DoF joint's two roots anew.
        if (keep) estimator_.anchor(j, 10.0 * kDeg);
    }
}

void BodyChain::apply(const SubjectFrame& frame, std::span<Quat> q_earth_sensor, std::span<std::uint8_t> flags) {
    const std::size_t n = std::min<std::size_t>(frame.segment_count, in_.size());
    for (std::size_t i = 0; i < in_.size(); ++i) {
        fusion::SegmentInput& x = in_[i];
        if (i >= n) {
            x.fresh = false;
            continue;
        }
        const SegmentPose& s = frame.segments[i];
        x.fresh = (s.flags & (kSegmentStale | kSegmentNeverSeen)) == 0;
        x.mag_available = s.mag != SegmentMag::kNone;
        x.mag_trusted = s.mag == SegmentMag::kTrusted;
        x.mag_heading_rad = s.mag_heading_rad;
        x.frame_epoch = s.frame_epoch;
        x.field_norm_ut = s.field_norm_ut;
        x.field_heading_rad = s.field_heading_rad;
        x.field_usable = s.field_usable;
        x.field_dip_rad = s.field_dip_rad;
        x.gyro_rad_s = Vec3(s.rate_rad_s[0], s.rate_rad_s[1], s.rate_rad_s[2]);
        x.accel_m_s2 = Vec3(s.accel_m_s2[0], s.accel_m_s2[1], s.accel_m_s2[2]);
        x.q6 = x.mag_available ? (rot_z(-x.mag_heading_rad) * q_earth_sensor[i]).normalized() : q_earth_sensor[i];
    }
    estimator_.update(frame.sample_us, in_, out_);
    for (std::size_t i = 0; i < n; ++i) {
        q_earth_sensor[i] = out_[i].q_earth_sensor;
        flags[i] = heading_flags(out_[i].source);
    }
}

bool BodyChain::refine_calibration(const BodyModel& model, Calibration& calibration, double min_turn_deg) {
    if (calibration.pose == CalibrationPose::kCustom) return false;  // its vertical is not known here
    const std::array<Quat, kMaxSegments> pose = pose_orientations(model, calibration.pose);
    bool changed = false;
    for (std::size_t j = 0; j < joints_.size(); ++j) {
        const fusion::JointStatus st = estimator_.status(j);
        if (!st.axes_estimated) continue;
        const BodyJoint& b = joints_[j];
        const auto p = static_cast<std::size_t>(b.def.parent), c = static_cast<std::size_t>(b.def.child);
        if (!calibration.calibrated[p] || !calibration.calibrated[c]) continue;
        // The learned axes in the segment frames the mountings give; both flipped is the same
        // hinge, so take the sign that agrees with the model in the parent.
        Vec3 up = math::rotate(calibration.q_sensor_segment[p].conjugate(), st.axis_parent);
        Vec3 uc = math::rotate(calibration.q_sensor_segment[c].conjugate(), st.axis_child);
        if (up.dot(b.axis_parent_segment) < 0.0) {
            up = -up;
            uc = -uc;
        }
        const auto turn = [&](std::size_t k, const Vec3& model_axis, const Vec3& learned) {
            // The calibration's heading error is a turn about the vertical of the pose.
            const Vec3 v = math::rotate(pose[k].conjugate(), Vec3::UnitZ());
            const std::optional<double> e = angle_about(v, model_axis, learned);
            if (!e || std::abs(*e) < min_turn_deg * kDeg) return;
            calibration.q_sensor_segment[k] =
                (calibration.q_sensor_segment[k] * Quat(Eigen::AngleAxisd(*e, v))).normalized();
            changed = true;
        };
        turn(p, b.axis_parent_segment, up);
        turn(c, b.axis_child_segment, uc);
    }
    return changed;
}

}  // namespace mocap::skeleton
