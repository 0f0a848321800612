#include "fusion/chain_estimator.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "fusion/joint_constraints.hpp"

namespace mocap::fusion {

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

Quat rz(double a_rad) {
    return Quat(std::cos(0.5 * a_rad), 0.0, 0.0, std::sin(0.5 * a_rad));
}

/// A joint without axes (a ball joint, or one whose axes are not known yet): no per-sample
/// axis constraint; the joint centre and a still joint's rates are all it has.
bool axes_free(const JointDef& d) {
    return d.type == JointType::kBall || !d.axes_known;
}

}  // namespace

std::string_view to_string(JointType t) {
    switch (t) {
        case JointType::kHinge:
            return "hinge";
        case JointType::kTwoDof:
            return "2dof";
        case JointType::kBall:
            return "ball";
    }
    return "?";
}

std::string_view to_string(HeadingMode m) {
    switch (m) {
        case HeadingMode::kMagnetometer:
            return "magnetometer";
        case HeadingMode::kJoints:
            return "joints";
        case HeadingMode::kAuto:
            return "auto";
    }
    return "?";
}

std::optional<HeadingMode> parse_heading_mode(std::string_view name) {
    if (name == "magnetometer") return HeadingMode::kMagnetometer;
    if (name == "joints") return HeadingMode::kJoints;
    if (name == "auto") return HeadingMode::kAuto;
    return std::nullopt;
}

std::string_view to_string(HeadingSource s) {
    switch (s) {
        case HeadingSource::kNone:
            return "none";
        case HeadingSource::kMagnetometer:
            return "magnetometer";
        case HeadingSource::kJoints:
            return "joints";
        case HeadingSource::kGyro:
            return "gyro";
    }
    return "?";
}

std::string ChainEstimator::check(std::size_t segment_count, std::span<const JointDef> joints) {
    if (segment_count == 0 || segment_count > kMaxSegments) {
        return "a chain has 1.." + std::to_string(kMaxSegments) + " segments";
    }
    std::array<int, kMaxSegments> parent{};
    parent.fill(-1);
    for (std::size_t j = 0; j < joints.size(); ++j) {
        const JointDef& d = joints[j];
        const auto in_range = [&](int s) { return s >= 0 && static_cast<std::size_t>(s) < segment_count; };
        const std::string where = "joint " + std::to_string(j) + ": ";
        if (!in_range(d.parent) || !in_range(d.child)) return where + "segment index out of range";
        if (d.parent == d.child) return where + "a segment cannot be its own parent";
        if (parent[static_cast<std::size_t>(d.child)] >= 0) return where + "the child already has a parent joint";
        if (d.axes_known && (!d.axis_parent.allFinite() || !d.axis_child.allFinite() || d.axis_parent.norm() < 1e-6 ||
                             d.axis_child.norm() < 1e-6)) {
            return where + "axes must be finite and non-zero";
        }
        parent[static_cast<std::size_t>(d.child)] = d.parent;
    }
    for (std::size_t s = 0; s < segment_count; ++s) {  // walking up from any segment must end
        int at = static_cast<int>(s);
        for (std::size_t steps = 0; at >= 0; ++steps) {
            if (steps > segment_count) return "the joints form a cycle";
            at = parent[static_cast<std::size_t>(at)];
        }
    }
    return {};
}

ChainEstimator::ChainEstimator(std::size_t segment_count, std::span<const JointDef> joints, const ChainParams& params)
    : params_(params), segment_count_(segment_count) {
    joint_of_child_.fill(-1);
    joints_.reserve(joints.size());
    for (const JointDef& d : joints) {
        Joint& j = joints_.emplace_back();
        j.def = d;
        j.filter = HeadingFilter(params_.filter);
        if (d.axes_known) {
            j.def.axis_parent.normalize();
            j.def.axis_child.normalize();
        }
        // Only a joint the centre constraint may serve (no axes) learns its centre: the
        // estimate costs more than all the other constraints together.
        if (!d.centre_known && d.estimate_centre && axes_free(d)) {
            JointPositionParams cp = params_.centre;
            if (d.type == JointType::kHinge) cp.free_directions = 1;  // any point of the axis is a centre
            j.centre = std::make_unique<JointPositionEstimator>(cp);
        }
        if (d.type == JointType::kHinge && (d.estimate_axes || !d.axes_known)) {
            j.axis = std::make_unique<HingeAxisEstimator>(params_.axis);
        }
        joint_of_child_[static_cast<std::size_t>(d.child)] = static_cast<int>(joints_.size()) - 1;
    }
    // Parents before children: repeatedly take the segments whose parent is placed.
    std::array<bool, kMaxSegments> placed{};
    std::size_t n = 0;
    while (n < segment_count_) {
        for (std::size_t s = 0; s < segment_count_; ++s) {
            if (placed[s]) continue;
            const int j = joint_of_child_[s];
            if (j < 0 || placed[static_cast<std::size_t>(joints_[static_cast<std::size_t>(j)].def.parent)]) {
                placed[s] = true;
                order_[n++] = static_cast<int>(s);
            }
        }
    }
    reset();
}

void ChainEstimator::forget_delta(Joint& j) {
    j.filter.reset();
    forget_tracking(j);
}

void ChainEstimator::forget_tracking(Joint& j) {
    j.search = TrigQuad{};
    j.last_joint_us = j.last_mag_us = j.refused_since_us = j.still_since_us = -1;
    j.past = {};
}

void ChainEstimator::restart_delta(Joint& j, const SegmentInput& p, const SegmentInput& c) {
    ++j.stats.restarts;
    if (!j.filter.initialised()) {
        forget_delta(j);
        return;
    }
    // Rz(δ) ≈ q6_p · (q_p⁻¹ q_c)_last · q6_c⁻¹; its twist about the vertical is δ. The rate at
    // which the two frames drift apart is the difference of the gyros' unlearned biases, which
    // the filters keep across their restart: it stays.
    const auto pi = static_cast<std::size_t>(j.def.parent), ci = static_cast<std::size_t>(j.def.child);
    const Quat m = p.q6 * last_out_[pi].conjugate() * last_out_[ci] * c.q6.conjugate();
    forget_tracking(j);
    j.filter.restart(math::wrap_pi(2.0 * std::atan2(m.z(), m.w())), params_.restart_sigma_deg * kDeg);
}

void ChainEstimator::reset() {
    for (Joint& j : joints_) {
        forget_delta(j);
        j.noise_ratio.fill(1.0);
        j.stats = JointStatus{};
        if (j.axis) j.axis->reset();
        if (j.centre) {
            j.centre->reset();
            j.def.centre_known = false;
        }
        if (j.axes_estimated) j.def.axes_known = false;  // learned in the run that is forgotten
        j.axes_estimated = false;
    }
    psi_.fill(0.0);
    field_seen_.fill(false);
    epoch_.fill(-1);
    last_out_.fill(Quat::Identity());
    last_us_ = -1;
}

void ChainEstimator::set_axes(std::size_t joint, const Vec3& axis_parent, const Vec3& axis_child) {
    Joint& j = joints_[joint];
    j.def.axis_parent = axis_parent.normalized();
    j.def.axis_child = axis_child.normalized();
    j.def.axes_known = true;
    j.axes_estimated = false;
    // Other axes make another δ: the constraints start it again.
    j.filter.reset();
    ++j.stats.restarts;
}

void ChainEstimator::set_centre(std::size_t joint, const Vec3& r_parent, const Vec3& r_child) {
    Joint& j = joints_[joint];
    j.def.r_parent = r_parent;
    j.def.r_child = r_child;
    j.def.centre_known = true;
}

void ChainEstimator::anchor(std::size_t joint, double sigma_rad) {
    if (last_us_ < 0) return;  // nothing composed yet: no heading to keep
    Joint& j = joints_[joint];
    j.filter.init(
        math::wrap_pi(psi_[static_cast<std::size_t>(j.def.child)] - psi_[static_cast<std::size_t>(j.def.parent)]),
        sigma_rad);
    j.refused_since_us = -1;
}

void ChainEstimator::learn_axes(Joint& j, std::int64_t t_us, const SegmentInput& p, const SegmentInput& c) {
    // Axes given (a calibration, a chain file) stay unless the motion was asked to replace them.
    if (!j.axis || (j.def.axes_known && !j.def.estimate_axes && !j.axes_estimated)) return;
    const bool solved = j.axis->add(t_us, p.gyro_rad_s, c.gyro_rad_s, p.q6, c.q6, !solved_this_step_);
    solved_this_step_ = solved_this_step_ || solved;
    if (!solved || !j.axis->ready()) return;
    const Vec3& ap = j.axis->axis_parent();
    Vec3 ac = j.axis->axis_child();
    // Early in the motion the estimator's own sign rule can pick the wrong sign (a simulated
    // knee's first axes, 1 s into a walk after a 2 s T-pose: δ 188° off, the knee 50° off in
    // flexion for 2 s); a δ the fields or the old axes know well decides it.
    if (j.filter.initialised() && j.filter.sigma_rad() < params_.axis_sign_sigma_deg * kDeg &&
        pair_contradicts(math::rotate(p.q6, ap), math::rotate(c.q6, ac), j.filter.delta_rad(),
                         params_.min_axis_horizontal)) {
        ac = -ac;
    }
    // A change below ~1° is the estimate's own noise: keep the axes (and δ) as they are.
    constexpr double kSame = 0.9998;
    if (j.def.axes_known && ap.dot(j.def.axis_parent) > kSame && ac.dot(j.def.axis_child) > kSame) return;
    const bool was_known = j.def.axes_known;
    j.def.axis_parent = ap;
    j.def.axis_child = ac;
    j.def.axes_known = true;
    j.axes_estimated = true;
    if (!was_known) return;  // δ (from the magnetometer, or none) is kept as the start
    j.filter.reset();
    ++j.stats.restarts;
}

bool ChainEstimator::fields_agree(const SegmentInput& p, const SegmentInput& c) const {
    if (p.field_norm_ut <= 0.0 || c.field_norm_ut <= 0.0) return false;
    const double rel = std::abs(p.field_norm_ut - c.field_norm_ut) / std::max(p.field_norm_ut, c.field_norm_ut);
    return rel <= params_.field_norm_agree &&
           std::abs(p.field_dip_rad - c.field_dip_rad) <= params_.field_dip_agree_deg * kDeg;
}

bool ChainEstimator::centre_pair(Joint& j, std::int64_t t_us, const SegmentInput& p, const SegmentInput& c, Vec3& a,
                                 Vec3& b) {
    Joint::Past& older = j.past[0];
    Joint::Past& prev = j.past[1];
    bool ok = false;
    const bool have_accel = p.accel_m_s2.squaredNorm() > 0.0 && c.accel_m_s2.squaredNorm() > 0.0;
    if (have_accel && older.t_us >= 0 && prev.t_us > older.t_us && t_us > prev.t_us) {
        const double span_s = static_cast<double>(t_us - older.t_us) * 1e-6;
        const Vec3 dw_p = (p.gyro_rad_s - older.p.gyro_rad_s) / span_s;
        const Vec3 dw_c = (c.gyro_rad_s - older.c.gyro_rad_s) / span_s;
        const SegmentInput& pp = prev.p;
        const SegmentInput& pc = prev.c;
        if (j.centre && j.def.centre_known) j.centre->compare_with(j.def.r_parent, j.def.r_child);
        const bool worked = j.centre && j.centre->add(prev.t_us, pp.gyro_rad_s, dw_p, pp.accel_m_s2, pc.gyro_rad_s,
                                                      dw_c, pc.accel_m_s2, !solved_this_step_);
        solved_this_step_ = solved_this_step_ || worked;
        // A learned centre replaces a given one (the body model's guess) only where it
        // explains the motion clearly better: a sensor mounted off the segment's middle.
        if (worked && j.centre->take_solution() && j.centre->ready() &&
            (!j.def.centre_known || j.centre->solution_cost() < 0.7 * j.centre->reference_cost())) {
            j.def.r_parent = j.centre->r_parent();
            j.def.r_child = j.centre->r_child();
            j.def.centre_known = true;
        }
        if (j.def.centre_known) {
            a = math::rotate(pp.q6, pp.accel_m_s2 + gamma_matrix(pp.gyro_rad_s, dw_p) * j.def.r_parent);
            b = math::rotate(pc.q6, pc.accel_m_s2 + gamma_matrix(pc.gyro_rad_s, dw_c) * j.def.r_child);
            ok = true;
        }
    }
    older = prev;
    prev = {have_accel ? t_us : -1, p, c};
    return ok;
}

bool ChainEstimator::constrain(Joint& j, std::int64_t t_us, double dt_s, const SegmentInput& p, const SegmentInput& c) {
    const JointDef& d = j.def;
    // One independent measurement per correlation time (heading_filter.hpp).
    const double scale = dt_s > 0.0 ? std::max(1.0, params_.correlation_s / dt_s) : 1.0;
    HeadingFilter& f = j.filter;
    bool taken = false;
    const auto lost_us = static_cast<std::int64_t>(params_.lost_s * 1e6);
    const auto take = [&](const HeadingMeasurement& m, Stream stream, double init_floor_rad = 5.0 * kDeg) {
        if (!m.ok) return;
        // The first informative sample starts the estimate (its variance is the sample's own,
        // with a floor, as it is the only one so far); so does a constraint after the gate has
        // refused every one for lost_s: the estimate, not the joint, is wrong then (a start
        // from a disturbed field, axes that changed).
        const bool lost = j.refused_since_us >= 0 && t_us - j.refused_since_us >= lost_us;
        if (!f.initialised() || (lost && d.type == JointType::kHinge)) {
            if (lost) ++j.stats.restarts;
            f.init(f.delta_rad() + m.residual_rad, std::max(std::sqrt(m.var_rad2), init_floor_rad));
            j.refused_since_us = -1;
            taken = true;
            return;
        }
        const double ratio = learn_noise(j, stream, m.residual_rad, m.var_rad2);
        if (f.update(f.delta_rad() + m.residual_rad, m.var_rad2 * ratio * scale, params_.gate_sigma)) {
            j.refused_since_us = -1;
            taken = true;
        } else {
            ++j.stats.refused;
            if (j.refused_since_us < 0) j.refused_since_us = t_us;
        }
    };
    // A joint without axes (a ball joint): the joint centre is one point of both segments, so
    // its specific force is one earth vector seen from both 6D frames (one step late: it needs
    // ω̇). It depends on the centre's place and on ω̇ at the sample rate, so it is the weakest
    // constraint: used only where neither axes nor agreeing fields (auto) see δ. A single
    // sample of it is noisy, so a start from it is given at least 20°.
    const bool mag_recent = j.last_mag_us >= 0 && static_cast<double>(t_us - j.last_mag_us) * 1e-6 < params_.hold_s;
    const bool no_axes = axes_free(d);
    if (!no_axes) j.past[1].t_us = -1;  // not followed: a later centre pair starts afresh
    // A joint without axes that does not move: both segments turn as one body, so their
    // angular velocities are one earth vector (a vector pair). Taken where the two rates have
    // agreed in their vertical parts and their horizontal lengths (which δ does not change)
    // for still_s without a break: a moving joint's rates agree so only for moments.
    if (no_axes) {
        const Vec3 u = math::rotate(p.q6, p.gyro_rad_s);
        const Vec3 v = math::rotate(c.q6, c.gyro_rad_s);
        const double hu = std::hypot(u.x(), u.y()), hv = std::hypot(v.x(), v.y());
        const double tol = params_.still_rate_rad_s + params_.sigma_rate_rel * 0.5 * (u.norm() + v.norm());
        if (std::abs(u.z() - v.z()) >= tol || std::abs(hu - hv) >= tol) {
            j.still_since_us = -1;
        } else if (j.still_since_us < 0) {
            j.still_since_us = t_us;
        } else if (!mag_recent && static_cast<double>(t_us - j.still_since_us) * 1e-6 >= params_.still_s) {
            take(pair_measurement(u, v, f.delta_rad(), tol, params_.min_rate_horizontal_rad_s), kStillPair);
        }
    }
    if (Vec3 fa, fb; no_axes && centre_pair(j, t_us, p, c, fa, fb) && !mag_recent) {
        const double h = 0.5 * (std::hypot(fa.x(), fa.y()) + std::hypot(fb.x(), fb.y()));
        take(pair_measurement(fa, fb, f.delta_rad(), params_.sigma_acc_m_s2 + params_.sigma_acc_rel * h,
                              params_.min_acc_horizontal_m_s2),
             kAccPair, 20.0 * kDeg);
    }
    if (no_axes) return taken;
    const Vec3 a = math::rotate(p.q6, d.axis_parent);
    const Vec3 b = math::rotate(c.q6, d.axis_child);
    const Vec3 u = math::rotate(p.q6, p.gyro_rad_s);
    const Vec3 v = math::rotate(c.q6, c.gyro_rad_s);
    if (d.type == JointType::kHinge) {
        take(pair_measurement(a, b, f.delta_rad(), params_.sigma_axis, params_.min_axis_horizontal), kAxisPair);
        // The angular velocity perpendicular to the axis is the same vector for both segments.
        const Vec3 up = u - u.dot(a) * a;
        const Vec3 vp = v - v.dot(b) * b;
        const double sigma = params_.sigma_rate_rad_s + params_.sigma_rate_rel * 0.5 * (up.norm() + vp.norm());
        take(pair_measurement(up, vp, f.delta_rad(), sigma, params_.min_rate_horizontal_rad_s), kRatePair);
    } else {  // 2dof: two scalar constraints
        const TrigLinear g_axis = two_dof_axis_constraint(a, b, d.cos_axis_angle);
        const TrigLinear g_rate = two_dof_rate_constraint(a, b, u, v);
        const double sigma_rate =
            params_.sigma_two_dof_rate_rad_s + params_.sigma_rate_rel * 0.5 * (u.norm() + v.norm());
        // Each sample has two roots in δ; their sum over the last search_s has one, once the
        // motion is rich enough: that starts (and restarts) δ without a magnetometer.
        j.search.shift(f.initialised() ? f.rate_rad_s() * dt_s : 0.0);
        j.search.scale(step_.search_decay);
        const double sa = params_.sigma_two_dof_axis, sr = sigma_rate;
        j.search.add(g_axis, 1.0 / (sa * sa * scale));
        j.search.add(g_rate, 1.0 / (sr * sr * scale));
        const bool lost = j.refused_since_us >= 0 && t_us - j.refused_since_us >= lost_us;
        if (!f.initialised() || lost) {
            const TrigQuad::Minimum m = j.search.minimum();
            // Chi-square units: the runner-up clearly worse, the minimum sharp within ~10°.
            const double sigma = m.curvature > 0.0 ? std::sqrt(2.0 / m.curvature) : 1e9;
            if (m.runner_up - m.value > params_.search_margin && sigma < 10.0 * kDeg) {
                if (lost) ++j.stats.restarts;
                f.init(m.delta_rad, std::max(sigma, 2.0 * kDeg));
                j.refused_since_us = -1;
                taken = true;
            }
            return taken;
        }
        take(scalar_measurement(g_axis, f.delta_rad(), sa, 0.05), kTwoDofAxis);
        take(scalar_measurement(g_rate, f.delta_rad(), sr, params_.min_rate_horizontal_rad_s * 0.2), kTwoDofRate);
    }
    return taken;
}

void ChainEstimator::update_joint(Joint& j, std::int64_t t_us, double dt_s, const SegmentInput& p,
                                  const SegmentInput& c, bool fields_seen) {
    HeadingFilter& f = j.filter;
    f.predict(dt_s);
    if (!p.fresh || !c.fresh) return;
    if (params_.mode == HeadingMode::kMagnetometer) return;
    learn_axes(j, t_us, p, c);
    const bool fields_alike =
        params_.mode == HeadingMode::kAuto && p.mag_available && c.mag_available && fields_agree(p, c);
    const bool fields_ok = fields_alike && p.field_usable && c.field_usable;
    // A 2-DoF joint's axes from the body model are only as good as the calibration pose held
    // them (a T-pose with the upper arm turned 30° about its length turns the elbow's flexion
    // axis by as much, and biases δ by about that): auto takes agreeing fields over them and
    // uses the joint where the fields fail. Hinges (the knee's axis is well defined) and axes
    // learned from the motion are used throughout. Fields alike in norm and dip that a filter
    // has not trusted yet (its start) hold δ on the gyros rather than hand it to the joint; a
    // field rejected after it was trusted is a disturbance, and the joint holds δ then.
    // The same for a joint without axes (a ball joint, a joint whose axes are not known yet):
    // its constraints (a joint centre's specific force, the rates of a still joint) are weaker
    // than fields that agree.
    const bool model_two_dof = j.def.type == JointType::kTwoDof && !j.axes_estimated;
    const bool field_first = (model_two_dof || axes_free(j.def)) && fields_alike && (fields_ok || !fields_seen);
    const bool joint_recent =
        !field_first && j.last_joint_us >= 0 && static_cast<double>(t_us - j.last_joint_us) * 1e-6 < params_.hold_s;
    if (!field_first && constrain(j, t_us, dt_s, p, c)) {
        j.last_joint_us = t_us;
        ++j.stats.joint_updates;
    }
    if (!fields_ok) return;
    const double z = math::wrap_pi(c.field_heading_rad - p.field_heading_rad);
    if (!f.initialised()) {
        f.init(z, 20.0 * kDeg);
        j.last_mag_us = t_us;
        return;
    }
    const double agree = std::max(params_.mag_agree_deg * kDeg, 3.0 * f.sigma_rad());
    if (joint_recent && std::abs(math::wrap_pi(z - f.delta_rad())) > agree) {
        ++j.stats.mag_disagreements;
        return;
    }
    // A field's error depends on where the segments are, so it stays while they stay: one
    // independent difference per mag_correlation_s.
    const double scale = dt_s > 0.0 ? std::max(1.0, params_.mag_correlation_s / dt_s) : 1.0;
    const double sm = params_.sigma_mag_deg * kDeg;
    const double ratio = learn_noise(j, kMag, math::wrap_pi(z - f.delta_rad()), sm * sm);
    if (f.update(z, sm * sm * ratio * scale, params_.gate_sigma)) {
        j.last_mag_us = t_us;
        ++j.stats.mag_updates;
    } else {
        ++j.stats.refused;
    }
}

// What a stream's errors really are: its innovations against the estimate, relative to the
// variance the filter expects of them (the stream's model variance plus δ's own), averaged
// over noise_tau_s of sample time. A joint that is only nearly a hinge (an axis that wanders),
// a field that varies from place to place, an axis slightly off: each shows as a larger ratio,
// and that stream then counts for less against the others of the same joint; a stream better
// than its model (an exact hinge, a clean field) counts for more. Bounded to
// [min_noise_ratio, 100]: a stream that agrees with the estimate because it made it never
// becomes infinitely sure. δ's own variance belongs in the denominator: while δ is uncertain
// (at the start, frames drifting apart faster than the rate has been learned) large
// innovations are δ's error, not the stream's, and counting them as the stream's would weigh
// the stream down just when δ needs it (docs/fusion.md, "Learning each stream's noise").
double ChainEstimator::learn_noise(Joint& j, Stream stream, double innovation_rad, double model_var) const {
    double& r = j.noise_ratio[stream];
    const double p = j.filter.sigma_rad() * j.filter.sigma_rad();
    const double x = std::min(innovation_rad * innovation_rad / (model_var + p), 100.0);
    r += step_.noise_gain * (x - r);
    return std::max(params_.min_noise_ratio, r);
}

HeadingSource ChainEstimator::source_of(const Joint& j, std::int64_t t_us) const {
    const auto recent = [&](std::int64_t at) {
        return at >= 0 && static_cast<double>(t_us - at) * 1e-6 < params_.hold_s;
    };
    if (recent(j.last_joint_us)) return HeadingSource::kJoints;
    if (recent(j.last_mag_us)) return HeadingSource::kMagnetometer;
    return j.filter.initialised() ? HeadingSource::kGyro : HeadingSource::kNone;
}

void ChainEstimator::update(std::int64_t t_us, std::span<const SegmentInput> in, std::span<SegmentOutput> out) {
    const double dt_s = last_us_ >= 0 && t_us > last_us_ ? static_cast<double>(t_us - last_us_) * 1e-6 : 0.0;
    last_us_ = t_us;
    solved_this_step_ = false;
    if (dt_s != step_.dt_s) {  // the coefficients of one step, recomputed only when the rate changes
        step_.dt_s = dt_s;
        step_.search_decay = dt_s > 0.0 ? std::exp(-dt_s / params_.search_s) : 1.0;
        step_.noise_gain = dt_s > 0.0 ? 1.0 - std::exp(-dt_s / params_.noise_tau_s) : 0.0;
    }
    // A segment whose filter restarted its attitude (after a gap) has a new 6D heading frame:
    // the relative headings to it, and their drift, are unknown again.
    std::array<bool, kMaxSegments> restarted{};
    for (std::size_t s = 0; s < segment_count_; ++s) {
        if (!in[s].fresh) continue;
        if (in[s].mag_trusted) field_seen_[s] = true;
        restarted[s] = epoch_[s] >= 0 && epoch_[s] != in[s].frame_epoch;
        epoch_[s] = in[s].frame_epoch;
    }
    std::array<JointHeading, kMaxSegments> headings{};
    for (std::size_t i = 0; i < joints_.size(); ++i) {
        Joint& j = joints_[i];
        const auto p = static_cast<std::size_t>(j.def.parent), c = static_cast<std::size_t>(j.def.child);
        if (restarted[p] || restarted[c]) restart_delta(j, in[p], in[c]);
        update_joint(j, t_us, dt_s, in[p], in[c], field_seen_[p] && field_seen_[c]);
        headings[i] = {j.filter.initialised(), j.filter.delta_rad(), source_of(j, t_us)};
    }
    compose(in, std::span<const JointHeading>(headings.data(), joints_.size()), out);
}

void ChainEstimator::compose(std::span<const SegmentInput> in, std::span<const JointHeading> headings,
                             std::span<SegmentOutput> out) {
    const bool per_segment = params_.mode == HeadingMode::kMagnetometer;
    for (std::size_t k = 0; k < segment_count_; ++k) {
        const auto s = static_cast<std::size_t>(order_[k]);
        const SegmentInput& x = in[s];
        const int ji = joint_of_child_[s];
        HeadingSource source = HeadingSource::kNone;
        if (per_segment || ji < 0) {
            // The root (or every segment, per segment): its own magnetometer heading, which the
            // filter holds on its gyro while it rejects the field.
            if (x.mag_available) psi_[s] = x.mag_heading_rad;
            source = x.mag_available && x.mag_trusted ? HeadingSource::kMagnetometer : HeadingSource::kGyro;
        } else {
            const JointHeading& h = headings[static_cast<std::size_t>(ji)];
            const auto parent = static_cast<std::size_t>(joints_[static_cast<std::size_t>(ji)].def.parent);
            if (h.known) {
                psi_[s] = psi_[parent] + h.delta_rad;
            } else if (x.mag_available && params_.mode == HeadingMode::kAuto) {
                psi_[s] = x.mag_heading_rad;  // nothing from the joint yet: the segment's own field
            } else {
                psi_[s] = psi_[parent];
            }
            source = h.source;
        }
        out[s].q_earth_sensor = (rz(psi_[s]) * x.q6).normalized();
        last_out_[s] = out[s].q_earth_sensor;
        out[s].source = source;
    }
}

JointStatus ChainEstimator::status(std::size_t j) const {
    const Joint& x = joints_[j];
    JointStatus s = x.stats;
    s.delta_rad = x.filter.delta_rad();
    s.sigma_rad = x.filter.sigma_rad();
    s.rate_rad_s = x.filter.rate_rad_s();
    s.initialised = x.filter.initialised();
    s.source = source_of(x, last_us_);
    s.axes_known = x.def.axes_known;
    s.axes_estimated = x.axes_estimated;
    s.axis_parent = x.def.axis_parent;
    s.axis_child = x.def.axis_child;
    s.centre_known = x.def.centre_known;
    s.r_parent = x.def.r_parent;
    s.r_child = x.def.r_child;
    return s;
}

}  // namespace mocap::fusion
