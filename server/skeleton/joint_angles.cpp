#include "skeleton/joint_angles.hpp"

#include <cassert>
#include <numbers>

namespace mocap::skeleton {

namespace {

/// One joint's sequence: the axis and left-side sign of each anatomical angle, and the
/// order in which they are applied (indices into {flexion, abduction, rotation}).
struct JointConvention {
    std::array<Axis, 3> axis;         // flexion, abduction, rotation
    std::array<double, 3> left_sign;  // flexion, abduction, rotation
    std::array<int, 3> order;         // e.g. {0, 1, 2}: flexion, then abduction, then rotation
    double neutral_left_x_rad;        // q_neutral = Rx(angle) on the left, Rx(-angle) on the right
};

JointConvention convention(JointKind kind) {
    constexpr double kHalfPi = std::numbers::pi / 2;
    switch (kind) {
        case JointKind::kHip:
            return {{Axis::kY, Axis::kX, Axis::kZ}, {-1, 1, -1}, {0, 1, 2}, 0.0};
        case JointKind::kKnee:
            return {{Axis::kY, Axis::kX, Axis::kZ}, {1, 1, -1}, {0, 1, 2}, 0.0};
        case JointKind::kAnkle:
            return {{Axis::kY, Axis::kX, Axis::kZ}, {-1, -1, -1}, {0, 1, 2}, 0.0};
        case JointKind::kShoulder:
            return {{Axis::kY, Axis::kX, Axis::kZ}, {-1, 1, -1}, {1, 0, 2}, -kHalfPi};
        case JointKind::kElbow:
            return {{Axis::kZ, Axis::kX, Axis::kY}, {-1, 1, 1}, {0, 1, 2}, 0.0};
    }
    return {{Axis::kY, Axis::kX, Axis::kZ}, {1, 1, 1}, {0, 1, 2}, 0.0};
}

double side_sign(Axis a, Side side) {
    return (side == Side::kRight && a != Axis::kY) ? -1.0 : 1.0;
}

Quat neutral(const JointConvention& c, Side side) {
    const double a = side == Side::kLeft ? c.neutral_left_x_rad : -c.neutral_left_x_rad;
    return axis_rotation(Axis::kX, a);
}

RotationOrder order_of(const JointConvention& c) {
    return RotationOrder{{c.axis[static_cast<std::size_t>(c.order[0])], c.axis[static_cast<std::size_t>(c.order[1])],
                          c.axis[static_cast<std::size_t>(c.order[2])]}};
}

}  // namespace

std::vector<JointSpec> default_joint_specs(const BodyModel& model) {
    struct Def {
        const char* name;
        JointKind kind;
        Side side;
        std::string_view parent;
        std::string_view child;
    };
    static const Def defs[] = {
        {"left_hip", JointKind::kHip, Side::kLeft, seg::kPelvis, seg::kLeftThigh},
        {"right_hip", JointKind::kHip, Side::kRight, seg::kPelvis, seg::kRightThigh},
        {"left_knee", JointKind::kKnee, Side::kLeft, seg::kLeftThigh, seg::kLeftCalf},
        {"right_knee", JointKind::kKnee, Side::kRight, seg::kRightThigh, seg::kRightCalf},
        {"left_ankle", JointKind::kAnkle, Side::kLeft, seg::kLeftCalf, seg::kLeftFoot},
        {"right_ankle", JointKind::kAnkle, Side::kRight, seg::kRightCalf, seg::kRightFoot},
        {"left_shoulder", JointKind::kShoulder, Side::kLeft, seg::kTrunk, seg::kLeftUpperArm},
        {"right_shoulder", JointKind::kShoulder, Side::kRight, seg::kTrunk, seg::kRightUpperArm},
        {"left_elbow", JointKind::kElbow, Side::kLeft, seg::kLeftUpperArm, seg::kLeftForearm},
        {"right_elbow", JointKind::kElbow, Side::kRight, seg::kRightUpperArm, seg::kRightForearm},
    };
    std::vector<JointSpec> specs;
    for (const Def& d : defs) {
        const int p = model.index_of(d.parent);
        const int c = model.index_of(d.child);
        if (p < 0 || c < 0) continue;
        specs.push_back(JointSpec{d.name, d.kind, d.side, p, c});
    }
    return specs;
}

Quat relative_rotation(const Quat& q_world_parent, const Quat& q_world_child) {
    return (q_world_parent.conjugate() * q_world_child).normalized();
}

JointAngles joint_angles(JointKind kind, Side side, const Quat& q_world_parent, const Quat& q_world_child) {
    const JointConvention c = convention(kind);
    const Quat q_anat = relative_rotation(q_world_parent, q_world_child) * neutral(c, side).conjugate();
    const std::array<double, 3> e = to_euler(order_of(c), q_anat);
    std::array<double, 3> slot{};  // flexion, abduction, rotation
    for (std::size_t k = 0; k < 3; ++k) {
        const auto s = static_cast<std::size_t>(c.order[k]);
        slot[s] = e[k] * c.left_sign[s] * side_sign(c.axis[s], side);
    }
    return {slot[0], slot[1], slot[2]};
}

Quat child_orientation(JointKind kind, Side side, const Quat& q_world_parent, const JointAngles& angles) {
    const JointConvention c = convention(kind);
    const std::array<double, 3> slot{angles.flexion_rad, angles.abduction_rad, angles.rotation_rad};
    std::array<double, 3> e{};
    for (std::size_t k = 0; k < 3; ++k) {
        const auto s = static_cast<std::size_t>(c.order[k]);
        e[k] = slot[s] * c.left_sign[s] * side_sign(c.axis[s], side);
    }
    return (q_world_parent * from_euler(order_of(c), e) * neutral(c, side)).normalized();
}

void compute_joint_angles(std::span<const JointSpec> specs, std::span<const Quat> q_world_segment,
                          std::span<JointAngles> out) {
    assert(out.size() >= specs.size());
    for (std::size_t i = 0; i < specs.size(); ++i) {
        const JointSpec& s = specs[i];
        const auto p = static_cast<std::size_t>(s.parent_segment);
        const auto c = static_cast<std::size_t>(s.child_segment);
        // A frame with fewer segments than the model: the joint is not measured.
        out[i] = (p < q_world_segment.size() && c < q_world_segment.size())
                     ? joint_angles(s.kind, s.side, q_world_segment[p], q_world_segment[c])
                     : JointAngles{};
    }
}

}  // namespace mocap::skeleton
