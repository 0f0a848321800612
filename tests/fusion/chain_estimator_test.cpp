// Tests of the chain stage on synthetic two-segment motion with a known relative heading:
// each sensor's 6D frame is its true orientation turned about the vertical by a heading of
// its own that drifts, so the true δ (child 6D frame -> parent 6D frame) is known exactly.
#include "fusion/chain_estimator.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <numbers>
#include <vector>

namespace mocap::fusion {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

Quat rz(double a) {
    return Quat(std::cos(0.5 * a), 0.0, 0.0, std::sin(0.5 * a));
}
Quat axis_angle(const Vec3& axis, double a) {
    return Quat(Eigen::AngleAxisd(a, axis.normalized()));
}

/// A rotation taking unit vector from onto unit vector to.
Quat align(const Vec3& from, const Vec3& to) {
    return Quat::FromTwoVectors(from, to);
}

struct TwoSegmentMotion {
    Vec3 axis_parent, axis_child;                                         // hinge (or 2dof) axes, sensor frames
    std::function<Quat(double)> q_parent;                                 // true q_earth_parent_sensor(t)
    std::function<Quat(double, const Quat&)> q_child;                     // true q_earth_child_sensor(t, parent)
    std::function<double(double)> h_parent = [](double) { return 0.0; };  // 6D heading offsets
    std::function<double(double)> h_child = [](double) { return 0.0; };
    double rate_hz = 100.0;
};

/// The true δ at t: the child's 6D frame turned by δ is the parent's.
double true_delta(const TwoSegmentMotion& m, double t) {
    return math::wrap_pi(m.h_parent(t) - m.h_child(t));
}

/// Body rate carrying q0 to q1 over dt, in the sensor frame.
Vec3 rate(const Quat& q0, const Quat& q1, double dt) {
    return math::rotvec_from_quat(q0.conjugate() * q1) / dt;
}

struct RunResult {
    std::vector<double> t, delta, truth;
    std::vector<HeadingSource> source;
    JointStatus status;
};

/// Feeds the motion for duration_s; mag_fn(t, in) may fill the magnetometer fields.
RunResult run(const TwoSegmentMotion& m, const JointDef& def, const ChainParams& params, double duration_s,
              const std::function<void(double, SegmentInput&, SegmentInput&)>& mag_fn = nullptr) {
    const JointDef defs[1] = {def};
    ChainEstimator est(2, defs, params);
    RunResult r;
    const double dt = 1.0 / m.rate_hz;
    Quat prev_p = m.q_parent(0.0), prev_c = m.q_child(0.0, prev_p);
    std::vector<SegmentInput> in(2);
    std::vector<SegmentOutput> out(2);
    for (int k = 0; k * dt <= duration_s; ++k) {
        const double t = k * dt;
        const Quat qp = m.q_parent(t), qc = m.q_child(t, qp);
        in[0].fresh = in[1].fresh = true;
        in[0].q6 = rz(m.h_parent(t)) * qp;
        in[1].q6 = rz(m.h_child(t)) * qc;
        in[0].gyro_rad_s = k > 0 ? rate(prev_p, qp, dt) : Vec3::Zero();
        in[1].gyro_rad_s = k > 0 ? rate(prev_c, qc, dt) : Vec3::Zero();
        if (mag_fn) mag_fn(t, in[0], in[1]);
        est.update(static_cast<std::int64_t>(std::llround(t * 1e6)), in, out);
        r.t.push_back(t);
        r.delta.push_back(est.status(0).delta_rad);
        r.truth.push_back(true_delta(m, t));
        r.source.push_back(out[1].source);
        // The output's relative orientation is what the skeleton sees: its error is exactly
        // the error of δ (conj(q_p) ⊗ Rz(e) ⊗ q_p is a rotation by e).
        const Quat rel_out = out[0].q_earth_sensor.conjugate() * out[1].q_earth_sensor;
        const Quat rel_true = qp.conjugate() * qc;
        if (est.status(0).initialised) {
            EXPECT_NEAR(math::angle_rad(rel_out * rel_true.conjugate()),
                        std::abs(math::wrap_pi(r.delta.back() - r.truth.back())), 1e-6)
                << "output inconsistent with δ at t=" << t;
        }
        prev_p = qp;
        prev_c = qc;
    }
    r.status = est.status(0);
    return r;
}

/// Largest |δ − truth| over t in [from_s, to_s].
double max_error_deg(const RunResult& r, double from_s, double to_s = 1e9) {
    double e = 0.0;
    for (std::size_t i = 0; i < r.t.size(); ++i) {
        if (r.t[i] >= from_s && r.t[i] <= to_s) e = std::max(e, std::abs(math::wrap_pi(r.delta[i] - r.truth[i])));
    }
    return e / kDeg;
}

// A hinge whose axis is horizontal most of the time: the axis pair sees δ in every sample,
// and the filter follows both frames' drift (0.5 °/s apart), the frames 120° apart.
TEST(ChainEstimatorHinge, FollowsADriftingHeadingFromTheAxis) {
    TwoSegmentMotion m;
    m.axis_parent = Vec3(0.3, 0.9, 0.2).normalized();
    m.axis_child = Vec3(-0.5, 0.1, 0.8).normalized();
    const Quat mount = align(m.axis_child, m.axis_parent);
    // The parent sways about horizontal axes and turns about the vertical.
    m.q_parent = [](double t) {
        return rz(0.6 * std::sin(0.3 * t)) * axis_angle(Vec3(1, 0, 0), 0.4 * std::sin(0.7 * t)) *
               axis_angle(Vec3(0, 1, 0), 0.3 * std::sin(0.5 * t + 1.0));
    };
    m.q_child = [&](double t, const Quat& qp) {
        return qp * mount * axis_angle(m.axis_child, 1.2 * std::sin(1.1 * t));
    };
    m.h_parent = [](double t) { return 0.4 + 0.002 * kDeg * t * t; };
    m.h_child = [](double t) { return -1.7 + 0.5 * kDeg * t; };
    JointDef def;
    def.parent = 0;
    def.child = 1;
    def.type = JointType::kHinge;
    def.axes_known = true;
    def.axis_parent = m.axis_parent;
    def.axis_child = m.axis_child;
    ChainParams p;
    p.mode = HeadingMode::kJoints;
    const RunResult r = run(m, def, p, 120.0);
    // Noiseless: what is left is the lag behind the drift while the rate is learned (1.2° in
    // the first 15 s, 0.3° after 20 s when measured).
    EXPECT_LT(max_error_deg(r, 5.0), 2.0);
    EXPECT_LT(max_error_deg(r, 20.0), 0.5);
    EXPECT_EQ(r.source.back(), HeadingSource::kJoints);
    EXPECT_EQ(r.status.refused, 0u);
}

// A vertical hinge axis (a door, a turntable): the axis says nothing about δ. While the parent
// only turns about the vertical, nothing does and δ is held on the gyro: it keeps its last
// value and the source says so. Once the parent tilts, the shared angular velocity
// perpendicular to the axis shows δ again.
TEST(ChainEstimatorHinge, VerticalAxisHoldsThenTheSharedRateSeesIt) {
    TwoSegmentMotion m;
    m.axis_parent = Vec3(0, 0, 1);
    m.axis_child = Vec3(0, 0, 1);
    m.q_parent = [](double t) {
        const double tilt = t < 60.0 ? 0.0 : 0.5 * std::sin(0.9 * (t - 60.0));
        return rz(0.2 * t) * axis_angle(Vec3(1, 0, 0), tilt);
    };
    m.q_child = [&](double t, const Quat& qp) { return qp * axis_angle(Vec3(0, 0, 1), 0.8 * std::sin(0.6 * t)); };
    m.h_parent = [](double) { return 0.0; };
    m.h_child = [](double) { return 0.7; };
    JointDef def;
    def.parent = 0;
    def.child = 1;
    def.axes_known = true;
    def.axis_parent = m.axis_parent;
    def.axis_child = m.axis_child;
    ChainParams p;
    p.mode = HeadingMode::kJoints;
    // Started from the magnetometer's view of δ... in joints mode there is none: nothing
    // initialises it until the tilt begins.
    const RunResult r = run(m, def, p, 90.0);
    EXPECT_EQ(r.source[static_cast<std::size_t>(30 * 100)], HeadingSource::kNone);
    EXPECT_LT(max_error_deg(r, 70.0), 1.0);
    EXPECT_EQ(r.source.back(), HeadingSource::kJoints);
}

// A joint that stops moving with the parent still, axis horizontal: δ stays observable from
// the axis alone, so the estimate holds the truth through the pause; then the axis turns
// vertical and stays still: nothing observes δ, the estimate keeps its value (it does not
// wander) and the source becomes the gyro after hold_s.
TEST(ChainEstimatorHinge, AJointThatDoesNotMoveKeepsItsHeading) {
    TwoSegmentMotion m;
    m.axis_parent = Vec3(1, 0, 0);
    m.axis_child = Vec3(0, 1, 0);
    const Quat mount = align(m.axis_child, m.axis_parent);
    m.q_parent = [](double t) {
        if (t < 20.0) return rz(0.5 * std::sin(0.4 * t)) * axis_angle(Vec3(0, 1, 0), 0.3 * std::sin(t));
        if (t < 60.0) return rz(0.5 * std::sin(0.4 * 20.0)) * axis_angle(Vec3(0, 1, 0), 0.3 * std::sin(20.0));
        // turned so the hinge axis points up, then still
        return axis_angle(Vec3(0, 1, 0), -std::numbers::pi / 2);
    };
    m.q_child = [&](double t, const Quat& qp) {
        return qp * mount * axis_angle(m.axis_child, t < 20.0 ? 0.7 * std::sin(0.8 * t) : 0.3);
    };
    m.h_child = [](double) { return 2.0; };
    JointDef def;
    def.parent = 0;
    def.child = 1;
    def.axes_known = true;
    def.axis_parent = m.axis_parent;
    def.axis_child = m.axis_child;
    ChainParams p;
    p.mode = HeadingMode::kJoints;
    const RunResult r = run(m, def, p, 90.0);
    EXPECT_LT(max_error_deg(r, 5.0, 59.9), 0.5);
    EXPECT_LT(max_error_deg(r, 60.0), 0.5);  // held at the truth: nothing moves it
    EXPECT_EQ(r.source.back(), HeadingSource::kGyro);
}

/// A 2-DoF joint (axis 1 fixed in the parent, axis 2 in the child, perpendicular) swinging
/// about both while the parent sways and turns; the child's 6D frame drifts 0.2 °/s.
TwoSegmentMotion two_dof_motion() {
    TwoSegmentMotion m;
    m.axis_parent = Vec3(0, 1, 0);
    m.axis_child = Vec3(1, 0, 0);
    m.q_parent = [](double t) {
        return rz(0.4 * std::sin(0.25 * t)) * axis_angle(Vec3(1, 0, 0), 0.5 * std::sin(0.6 * t)) *
               axis_angle(Vec3(0, 1, 0), 0.4 * std::sin(0.45 * t + 0.5));
    };
    // child = parent ⊗ R(j1, α) ⊗ R(j2, β): the second axis is the child's x.
    m.q_child = [j1 = m.axis_parent, j2 = m.axis_child](double t, const Quat& qp) {
        return qp * axis_angle(j1, 0.9 * std::sin(0.7 * t)) * axis_angle(j2, 0.6 * std::sin(0.5 * t));
    };
    m.h_parent = [](double) { return 0.3; };
    m.h_child = [](double t) { return -0.9 + 0.2 * kDeg * t; };
    return m;
}

JointDef two_dof_def(const TwoSegmentMotion& m) {
    JointDef def;
    def.parent = 0;
    def.child = 1;
    def.type = JointType::kTwoDof;
    def.axes_known = true;
    def.axis_parent = m.axis_parent;
    def.axis_child = m.axis_child;
    def.cos_axis_angle = 0.0;
    return def;
}

// Started from a magnetometer difference 25° off, the two scalar constraints pull δ to the truth.
TEST(ChainEstimatorTwoDof, ConvergesFromAMagnetometerStart) {
    const TwoSegmentMotion m = two_dof_motion();
    const JointDef def = two_dof_def(m);
    ChainParams p;
    p.mode = HeadingMode::kAuto;
    const auto mag = [&](double t, SegmentInput& a, SegmentInput& b) {
        for (SegmentInput* x : {&a, &b}) {
            x->mag_available = true;
            x->mag_trusted = x->field_usable = t < 1.0;  // one look at the field, then it is rejected
            x->field_norm_ut = 50.0;
            x->field_dip_rad = 1.0;
        }
        // d is the filter's heading correction: the field's heading error is 25° for the child.
        a.mag_heading_rad = -m.h_parent(t);
        b.mag_heading_rad = -m.h_child(t) + 25.0 * kDeg;
        a.field_heading_rad = a.mag_heading_rad;
        b.field_heading_rad = b.mag_heading_rad;
    };
    const RunResult r = run(m, def, p, 120.0, mag);
    EXPECT_LT(max_error_deg(r, 60.0), 1.0);
    EXPECT_EQ(r.source.back(), HeadingSource::kJoints);
}

// A 2-DoF joint whose given flexion axis is 30° off the real one (an elbow whose upper arm was
// turned about its length in the calibration pose): the constraints alone (joints) bias δ; in
// auto, trusted fields that agree hold δ, and the joint takes over only once a field it had
// trusted is rejected (a field never trusted yet holds δ on the gyros: a filter's start).
TEST(ChainEstimatorTwoDof, AgreeingFieldsHoldAJointWhoseModelAxisIsOff) {
    const TwoSegmentMotion m = two_dof_motion();
    JointDef def = two_dof_def(m);
    def.axis_parent = axis_angle(Vec3(1, 0, 0), 30.0 * kDeg) * m.axis_parent;  // the model's, 30° off
    // The fields are clean (each d exact) and agree; untrusted for the first 3 s (the filters'
    // start), then trusted.
    const auto mag = [&](double t, SegmentInput& a, SegmentInput& b) {
        for (SegmentInput* x : {&a, &b}) {
            x->mag_available = true;
            x->mag_trusted = x->field_usable = t >= 3.0;
            x->field_norm_ut = 50.0;
            x->field_dip_rad = 1.0;
        }
        a.mag_heading_rad = a.field_heading_rad = -m.h_parent(t);
        b.mag_heading_rad = b.field_heading_rad = -m.h_child(t);
    };
    ChainParams p;
    p.mode = HeadingMode::kAuto;
    const RunResult a = run(m, def, p, 90.0, mag);
    EXPECT_LT(max_error_deg(a, 3.0), 3.0);
    EXPECT_EQ(a.source.back(), HeadingSource::kMagnetometer);
    EXPECT_EQ(a.status.joint_updates, 0u);
    // The same joint without the fields: the model's axis biases δ (what auto avoided).
    p.mode = HeadingMode::kJoints;
    const RunResult j = run(m, def, p, 90.0, mag);
    EXPECT_GT(max_error_deg(j, 30.0), 5.0);
}

// Auto mode: the magnetometer difference is taken while it agrees with the joint and refused
// while a disturbance turns one field by 40°.
TEST(ChainEstimatorAuto, TakesAgreeingFieldsAndRefusesADisturbedOne) {
    TwoSegmentMotion m;
    m.axis_parent = Vec3(1, 0, 0);
    m.axis_child = Vec3(1, 0, 0);
    m.q_parent = [](double t) { return rz(0.3 * t) * axis_angle(Vec3(0, 1, 0), 0.2 * std::sin(t)); };
    m.q_child = [&](double t, const Quat& qp) { return qp * axis_angle(m.axis_child, 0.8 * std::sin(0.9 * t)); };
    m.h_child = [](double) { return 1.0; };
    JointDef def;
    def.parent = 0;
    def.child = 1;
    def.axes_known = true;
    def.axis_parent = m.axis_parent;
    def.axis_child = m.axis_child;
    ChainParams p;
    p.mode = HeadingMode::kAuto;
    const auto mag = [&](double t, SegmentInput& a, SegmentInput& b) {
        for (SegmentInput* x : {&a, &b}) {
            x->mag_available = true;
            x->mag_trusted = x->field_usable = true;
            x->field_norm_ut = 50.0;
            x->field_dip_rad = 1.0;
        }
        a.mag_heading_rad = a.field_heading_rad = -m.h_parent(t);
        b.mag_heading_rad = b.field_heading_rad = -m.h_child(t) + ((t > 30.0 && t < 60.0) ? 40.0 * kDeg : 0.0);
    };
    const RunResult r = run(m, def, p, 90.0, mag);
    EXPECT_LT(max_error_deg(r, 5.0), 1.0);
    EXPECT_GT(r.status.mag_updates, 1000u);
    EXPECT_GT(r.status.mag_disagreements, 1000u);
}

// A joint without axes and without a magnetometer (a ball joint, or a hinge before its axes
// are learned): while it does not move, both segments turn as one body, and their rates show δ
// (the base of a hand-held arm moved alone). Once the joint moves, the rates differ and are not
// taken: δ, a property of the two 6D frames, stays where the still period put it.
/// A ball joint between segments 0 and 1 whose centre is not learned.
JointDef ball_def() {
    JointDef def;
    def.parent = 0;
    def.child = 1;
    def.type = JointType::kBall;
    def.estimate_centre = false;
    return def;
}

/// A parent swaying about both horizontal axes and turning about the vertical.
Quat swaying_parent(double t) {
    return rz(0.5 * std::sin(0.3 * t)) * axis_angle(Vec3(1, 0, 0), 0.6 * std::sin(0.8 * t)) *
           axis_angle(Vec3(0, 1, 0), 0.5 * std::sin(0.55 * t + 1.0));
}

TEST(ChainEstimatorBall, AStillJointShowsItsHeadingAndAMovingOneIsNotTakenForStill) {
    TwoSegmentMotion m;
    m.q_parent = swaying_parent;
    const Quat mount = axis_angle(Vec3(0.2, 0.4, 1.0), 1.9);
    m.q_child = [mount](double t, const Quat& qp) {
        const double bend = t < 20.0 ? 0.0 : 1.0 * std::sin(2.0 * (t - 20.0));
        const double twist = t < 20.0 ? 0.0 : 0.7 * std::sin(1.3 * (t - 20.0));
        return qp * axis_angle(Vec3(0, 1, 0), bend) * axis_angle(Vec3(0, 0, 1), twist) * mount;
    };
    m.h_parent = [](double) { return 0.4; };
    m.h_child = [](double) { return -1.6; };
    const JointDef def = ball_def();
    ChainParams p;
    p.mode = HeadingMode::kJoints;
    const RunResult r = run(m, def, p, 90.0);
    EXPECT_LT(max_error_deg(r, 5.0, 20.0), 1.0);
    EXPECT_LT(max_error_deg(r, 20.0), 1.5);
    EXPECT_EQ(r.source[static_cast<std::size_t>(15 * 100)], HeadingSource::kJoints);
    EXPECT_EQ(r.source.back(), HeadingSource::kGyro);
}

/// A ball joint bending under a swaying parent while the child's 6D frame drifts at
/// drift_deg_s (its gyro's unlearned vertical bias) and, from jump_at_s on, is turned by
/// jump_rad more (its filter started its attitude again).
TwoSegmentMotion drifting_ball(double drift_deg_s, double jump_at_s = 1e9, double jump_rad = 0.0) {
    TwoSegmentMotion m;
    m.q_parent = swaying_parent;
    const Quat mount = axis_angle(Vec3(0.2, 0.4, 1.0), 1.9);
    m.q_child = [mount](double t, const Quat& qp) { return qp * axis_angle(Vec3(0, 1, 0), std::sin(2.0 * t)) * mount; };
    m.h_parent = [](double) { return 0.4; };
    m.h_child = [=](double t) { return -1.6 + drift_deg_s * kDeg * t + (t < jump_at_s ? 0.0 : jump_rad); };
    return m;
}

/// Both segments see a clean field (norm and dip kept, trusted by their filters): each
/// field's own heading is exactly its frame's.
void clean_fields(const TwoSegmentMotion& m, double t, SegmentInput& a, SegmentInput& b) {
    for (SegmentInput* x : {&a, &b}) {
        x->mag_available = x->mag_trusted = x->field_usable = true;
        x->field_norm_ut = 50.0;
        x->field_dip_rad = 1.0;
    }
    a.mag_heading_rad = a.field_heading_rad = -m.h_parent(t);
    b.mag_heading_rad = b.field_heading_rad = -m.h_child(t);
}

// A child whose gyro keeps an unlearned vertical bias of 1 °/s: its 6D frame drifts, and its
// filter's heading correction d follows the field only at 1 / tau (10 s here), 10° behind it
// for good; the field's own heading does not lag. The parent's filter refuses its field for its
// own heading for a while (its heading guard), though the field keeps its norm and dip. A ball
// joint (no constraint of its own) in auto: δ from the fields' own headings, with the drift
// rate learned, stays within a degree where the corrections would leave it 10° off.
TEST(ChainEstimatorAuto, TakesTheFieldsOwnHeadingsNotTheFiltersLaggingCorrections) {
    const TwoSegmentMotion m = drifting_ball(1.0);
    ChainParams p;
    p.mode = HeadingMode::kAuto;
    const auto mag = [&](double t, SegmentInput& a, SegmentInput& b) {
        clean_fields(m, t, a, b);
        a.mag_trusted = t < 30.0 || t > 60.0;
        b.mag_heading_rad = b.field_heading_rad - 10.0 * kDeg;  // the correction's lag
    };
    const RunResult r = run(m, ball_def(), p, 90.0, mag);
    EXPECT_LT(max_error_deg(r, 40.0), 1.0);  // the rate learned (one difference per 30 s counts)
    EXPECT_GT(r.status.mag_updates, 5000u);
    EXPECT_NEAR(r.status.rate_rad_s / kDeg, -1.0, 0.05);
}

// After a short T-pose the filters have not learned their gyro biases at rest, and two
// segments' frames drift apart fast from the start (a simulated body's shank and foot: 3.5 °/s).
// Agreeing fields must hold δ while its rate is learned: δ's lag is δ's own error, not the
// field's. Counting that lag as the field's noise (normalised by the field's variance alone)
// weighed the field down and left δ 9.5° behind after 20 s; a rate uncertainty of 1 °/s and
// clip of 3 °/s left it 23° behind.
TEST(ChainEstimatorAuto, FramesDriftingApartFastFromTheStartAreHeldByAgreeingFields) {
    const TwoSegmentMotion m = drifting_ball(3.5);
    ChainParams p;
    p.mode = HeadingMode::kAuto;
    const RunResult r =
        run(m, ball_def(), p, 120.0, [&](double t, SegmentInput& a, SegmentInput& b) { clean_fields(m, t, a, b); });
    EXPECT_LT(max_error_deg(r, 20.0), 5.0);
    EXPECT_LT(max_error_deg(r, 60.0), 1.0);
    EXPECT_NEAR(r.status.rate_rad_s / kDeg, -3.5, 0.1);
}

// After a gap the child's filter starts its attitude again (SegmentInput::frame_epoch changes):
// its 6D frame is turned by whatever it turned unseen (here 70°), so the δ learned in the old
// frame is wrong by as much. A moving ball joint has no constraint to relearn it; δ starts again
// from the joint's relative orientation at the last step, which a short gap changes little.
// Without the restart: 70° off for good.
TEST(ChainEstimatorBall, ASegmentWhoseFrameStartsAgainKeepsTheJointsRelativeHeading) {
    TwoSegmentMotion m;
    m.q_parent = swaying_parent;
    const Quat mount = axis_angle(Vec3(0.2, 0.4, 1.0), 1.9);
    m.q_child = [mount](double t, const Quat& qp) {
        const double bend = t < 20.0 ? 0.0 : 1.0 * std::sin(2.0 * (t - 20.0));
        return qp * axis_angle(Vec3(0, 1, 0), bend) * mount;
    };
    m.h_parent = [](double) { return 0.4; };
    m.h_child = [](double t) { return t < 40.0 ? -1.6 : -1.6 + 70.0 * kDeg; };
    const JointDef def = ball_def();
    ChainParams p;
    p.mode = HeadingMode::kJoints;
    const RunResult r =
        run(m, def, p, 60.0, [](double t, SegmentInput&, SegmentInput& c) { c.frame_epoch = t < 40.0 ? 3 : 4; });
    EXPECT_LT(max_error_deg(r, 5.0, 39.99), 1.5);
    EXPECT_LT(max_error_deg(r, 40.0), 2.0);
    EXPECT_EQ(r.status.restarts, 1u);
}

// The same restart while the two frames drift apart at 1 °/s (the child's gyro keeps an
// unlearned vertical bias, learned by δ's rate from agreeing fields until t = 50 s, when the
// child's filter restarts and the fields are lost): the filters keep their biases across a
// restart, so the frames go on drifting apart at that rate, and δ's rate is kept with it.
// Forgetting the rate would leave δ 1° further off for every second after the restart.
TEST(ChainEstimatorBall, AFrameRestartKeepsTheRateTheFramesDriftApartAt) {
    const TwoSegmentMotion m = drifting_ball(1.0, 50.0, 70.0 * kDeg);
    ChainParams p;
    p.mode = HeadingMode::kAuto;
    const auto mag = [&](double t, SegmentInput& a, SegmentInput& b) {
        clean_fields(m, t, a, b);
        for (SegmentInput* x : {&a, &b})
            x->mag_trusted = x->field_usable = t < 50.0;
        b.frame_epoch = t < 50.0 ? 3 : 4;
    };
    const RunResult r = run(m, ball_def(), p, 80.0, mag);
    EXPECT_LT(max_error_deg(r, 40.0, 49.99), 1.0);
    EXPECT_LT(max_error_deg(r, 50.0), 3.0);  // 30 s on: forgetting the rate left it 25° off
    EXPECT_EQ(r.status.restarts, 1u);
}

TEST(ChainEstimatorCheck, RefusesBadChains) {
    JointDef a;
    a.parent = 0;
    a.child = 1;
    JointDef b;
    b.parent = 1;
    b.child = 0;
    const JointDef cycle[2] = {a, b};
    EXPECT_NE(ChainEstimator::check(2, cycle), "");
    const JointDef twice[2] = {a, a};
    EXPECT_NE(ChainEstimator::check(2, twice), "");
    JointDef out_of_range = a;
    out_of_range.child = 5;
    EXPECT_NE(ChainEstimator::check(2, std::span<const JointDef>(&out_of_range, 1)), "");
    EXPECT_EQ(ChainEstimator::check(2, std::span<const JointDef>(&a, 1)), "");
    EXPECT_NE(ChainEstimator::check(0, {}), "");
}

}  // namespace
}  // namespace mocap::fusion
