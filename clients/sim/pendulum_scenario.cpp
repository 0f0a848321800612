// pendulum_scenario.cpp — why: the motion is integrated from the equations of motion rather
// than prescribed, so the accelerations the sensors read (centripetal, tangential, the
// coupling between the bars) are those of a real pendulum; the pushes are smooth torques, so
// the trajectory stays twice differentiable and the accelerometer has no steps.
#include "sim/pendulum_scenario.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "sim/sim_rng.hpp"

namespace mocap::sim {
namespace {

using Mat3 = math::Mat3;
using Vec2 = Eigen::Vector2d;
using Mat2 = Eigen::Matrix2d;

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;
constexpr double kGravity = 9.81;
constexpr double kWanderRad = 7.0 * kDeg;  // β(θ) = kWanderRad · sin θ
constexpr int kSubsteps = 8;               // RK4 steps per sample
constexpr double kStillS = 3.0;
constexpr double kDamping[2] = {0.003, 0.0004};  // N·m·s: E/e in M/(2c) ~ 30 s (M11 ~ 0.19, M22 ~ 0.02 kg·m²)

struct Bar {
    double length_m, mass_kg;
    Mat3 inertia_kg_m2;  // about the centre of mass, segment frame
};

std::array<Bar, 2> bars() {
    std::array<Bar, 2> out{};
    const auto bodies = pendulum_bodies();
    for (std::size_t i = 0; i < 2; ++i) {
        const PendulumBody& b = bodies[i];
        const double m = b.mass_kg, l = b.length_m, w = b.width_m, d = b.thickness_m;
        out[i] = {l, m, Eigen::Vector3d(m * (w * w + d * d), m * (l * l + d * d), m * (l * l + w * w)).asDiagonal()};
        out[i].inertia_kg_m2 /= 12.0;
    }
    return out;
}

/// Everything of one configuration (q, q̇) the equations and the sensors need, world frame.
struct Kin {
    Mat3 r1, r2;              // segment → world
    Vec3 w1, w2;              // angular velocities
    Vec3 arm1, arm_j1, arm2;  // pivot → c1, pivot → lower joint, lower joint → c2
    Vec3 u_w;                 // lower joint's instantaneous axis (unnormalised), world
    Vec3 du_w;                // its derivative with respect to θ2, world
};

struct Model {
    std::array<Bar, 2> bar = bars();
    Mat3 hang;          // seg1 → world at θ1 = 0: x down, z along the pivot axis
    Vec3 pivot_axis_w;  // h
    Vec3 pivot_m = pendulum_pivot_m();

    Kin kin(const Vec2& q, const Vec2& qd) const {
        Kin k;
        const double b = kWanderRad * std::sin(q[1]), db = kWanderRad * std::cos(q[1]), ddb = -b;
        k.r1 = Eigen::AngleAxisd(q[0], pivot_axis_w).toRotationMatrix() * hang;
        const Mat3 w = Eigen::AngleAxisd(b, Vec3::UnitX()).toRotationMatrix() *
                       Eigen::AngleAxisd(q[1], Vec3::UnitZ()).toRotationMatrix();
        k.r2 = k.r1 * w;
        const Vec3 u(db, -std::sin(b), std::cos(b));  // β' x + Rx(β) z
        const Vec3 du = ddb * Vec3::UnitX() + db * Vec3(0.0, -std::cos(b), -std::sin(b));
        k.u_w = k.r1 * u;
        k.du_w = k.r1 * du;
        k.w1 = qd[0] * pivot_axis_w;
        k.w2 = k.w1 + qd[1] * k.u_w;
        k.arm1 = k.r1 * Vec3(0.5 * bar[0].length_m, 0.0, 0.0);
        k.arm_j1 = k.r1 * Vec3(bar[0].length_m, 0.0, 0.0);
        k.arm2 = k.r2 * Vec3(0.5 * bar[1].length_m, 0.0, 0.0);
        return k;
    }

    /// The velocity Jacobians of one configuration: v_c = Σ ja[j] q̇_j, ω = Σ jw[j] q̇_j; the
    /// inertias in the world frame.
    struct Jacobians {
        std::array<Vec3, 2> ja1, ja2, jw1, jw2;
        Mat3 i1, i2;
        [[nodiscard]] Mat2 mass(const std::array<Bar, 2>& b) const {
            Mat2 m;
            for (std::size_t r = 0; r < 2; ++r) {
                for (std::size_t c = 0; c < 2; ++c)
                    m(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c)) =
                        b[0].mass_kg * ja1[r].dot(ja1[c]) + b[1].mass_kg * ja2[r].dot(ja2[c]) +
                        jw1[r].dot(i1 * jw1[c]) + jw2[r].dot(i2 * jw2[c]);
            }
            return m;
        }
    };

    Jacobians jacobians(const Kin& k) const {
        const Vec3& h = pivot_axis_w;
        Jacobians j;
        j.ja1 = {h.cross(k.arm1), Vec3::Zero()};
        j.ja2 = {h.cross(k.arm_j1 + k.arm2), k.u_w.cross(k.arm2)};
        j.jw1 = {h, Vec3::Zero()};
        j.jw2 = {h, k.u_w};
        j.i1 = k.r1 * bar[0].inertia_kg_m2 * k.r1.transpose();
        j.i2 = k.r2 * bar[1].inertia_kg_m2 * k.r2.transpose();
        return j;
    }

    /// q̈ under the generalized forces tau (Kane: Σ Jᵀ (m (a − g)) + Jωᵀ (I α + ω × I ω) = tau,
    /// with a = J q̈ + bias), and the centres' linear accelerations.
    Vec2 accel(const Vec2& q, const Vec2& qd, const Vec2& tau, Vec3* a1 = nullptr, Vec3* a2 = nullptr) const {
        const Kin k = kin(q, qd);
        const Jacobians j = jacobians(k);
        const Vec3 alpha2_bias = k.w1.cross(qd[1] * k.u_w) + qd[1] * qd[1] * k.du_w;  // α1 has none
        const Vec3 a1_bias = k.w1.cross(k.w1.cross(k.arm1));
        const Vec3 a2_bias =
            k.w1.cross(k.w1.cross(k.arm_j1)) + alpha2_bias.cross(k.arm2) + k.w2.cross(k.w2.cross(k.arm2));
        const Vec3 g(0.0, 0.0, -kGravity);
        Vec2 rhs = tau;
        for (std::size_t r = 0; r < 2; ++r) {
            rhs[static_cast<Eigen::Index>(r)] -=
                bar[0].mass_kg * j.ja1[r].dot(a1_bias - g) + bar[1].mass_kg * j.ja2[r].dot(a2_bias - g) +
                j.jw1[r].dot(k.w1.cross(j.i1 * k.w1)) + j.jw2[r].dot(j.i2 * alpha2_bias + k.w2.cross(j.i2 * k.w2));
        }
        Vec2 qdd = j.mass(bar).ldlt().solve(rhs);
        if (a1 != nullptr) *a1 = j.ja1[0] * qdd[0] + a1_bias;
        if (a2 != nullptr) *a2 = j.ja2[0] * qdd[0] + j.ja2[1] * qdd[1] + a2_bias;
        return qdd;
    }

    Mat2 mass_matrix(const Vec2& q) const { return jacobians(kin(q, Vec2::Zero())).mass(bar); }

    /// Kinetic + potential energy, J (potential from the pivot's height).
    double energy_j(const Vec2& q, const Vec2& qd) const {
        const Kin k = kin(q, qd);
        const Vec3 v1 = k.w1.cross(k.arm1);
        const Vec3 v2 = k.w1.cross(k.arm_j1) + k.w2.cross(k.arm2);
        const Mat3 i1 = k.r1 * bar[0].inertia_kg_m2 * k.r1.transpose();
        const Mat3 i2 = k.r2 * bar[1].inertia_kg_m2 * k.r2.transpose();
        return 0.5 * (bar[0].mass_kg * v1.squaredNorm() + bar[1].mass_kg * v2.squaredNorm() + k.w1.dot(i1 * k.w1) +
                      k.w2.dot(i2 * k.w2)) +
               kGravity * (bar[0].mass_kg * k.arm1.z() + bar[1].mass_kg * (k.arm_j1 + k.arm2).z());
    }
};

/// A push: a torque pulse on θ1 (pump = false) or a torque along a joint's velocity (pump).
struct Push {
    double t0_s = 0.0, duration_s = 0.0;
    int joint = 0;
    bool pump = false;
    double gain = 0.0;  ///< N·m (pulse) or N·m·s (pump)
};

double sin2_window(double t, double t0, double d) {
    if (t <= t0 || t >= t0 + d) return 0.0;
    const double s = std::sin(kPi * (t - t0) / d);
    return s * s;
}

Vec2 torque(const std::vector<Push>& pushes, double t, const Vec2& qd, bool free_swing) {
    if (free_swing) return Vec2::Zero();
    Vec2 tau(-kDamping[0] * qd[0], -kDamping[1] * qd[1]);
    for (const Push& p : pushes) {
        const double w = sin2_window(t, p.t0_s, p.duration_s);
        if (w > 0.0) tau[p.joint] += w * p.gain * (p.pump ? qd[p.joint] : 1.0);
    }
    return tau;
}

}  // namespace

std::array<PendulumBody, 2> pendulum_bodies() {
    // Aluminium bars, 40 × 20 mm.
    return {{{0.35, 0.75, 0.04, 0.02}, {0.30, 0.65, 0.04, 0.02}}};
}

Vec3 pendulum_pivot_m() {
    return {0.0, 0.0, 1.6};
}

ChainRecording make_pendulum_scenario(const PendulumOptions& o, const MagneticEnv& env) {
    Model model;
    SimRng rng(o.seed, 21);
    const double pivot_heading = rng.uniform(-kPi, kPi);
    model.pivot_axis_w = Vec3(std::cos(pivot_heading), std::sin(pivot_heading), 0.0);
    // seg1 → world at rest: x down, z along the pivot axis, y = z × x.
    model.hang.col(0) = -Vec3::UnitZ();
    model.hang.col(2) = model.pivot_axis_w;
    model.hang.col(1) = model.hang.col(2).cross(model.hang.col(0));
    const std::array<Quat, 2> mount = {random_rotation(o.seed, 600), random_rotation(o.seed, 601)};

    const double dt = 1.0 / o.rate_hz;
    const auto n = static_cast<std::size_t>(std::llround(o.duration_s * o.rate_hz)) + 1;
    std::vector<Push> pushes;
    double next_push_s = kStillS;
    Vec2 q = Vec2::Zero(), qd = Vec2::Zero();
    if (o.free_swing) {
        q = Vec2(70.0 * kDeg, -40.0 * kDeg);
        next_push_s = o.duration_s + 1.0;
    }
    const double e_rest = model.energy_j(Vec2::Zero(), Vec2::Zero());

    std::array<SensorTrack, 2> tracks;
    struct AxisSum {
        Vec3 parent = Vec3::Zero(), child = Vec3::Zero();
    } axis_sum;
    std::vector<std::pair<Vec3, double>> axes_seen;  // (axis in seg1's frame, weight)
    auto record = [&](const Vec2& qk, const Vec2& qdk, double t) {
        const Kin k = model.kin(qk, qdk);
        Vec3 a[2];
        model.accel(qk, qdk, torque(pushes, t, qdk, o.free_swing), &a[0], &a[1]);
        const Mat3* r[2] = {&k.r1, &k.r2};
        const Vec3 c[2] = {model.pivot_m + k.arm1, model.pivot_m + k.arm_j1 + k.arm2};
        for (std::size_t i = 0; i < 2; ++i) {
            tracks[i].q_earth_sensor.push_back(Quat(*r[i]) * mount[i]);
            tracks[i].position_m.push_back(c[i]);
            tracks[i].lin_acc_earth_m_s2.push_back(a[i]);
        }
        const Vec3 u_seg1 = k.r1.transpose() * k.u_w;
        const Vec3 u_seg2 = k.r2.transpose() * k.u_w;
        const double weight = std::abs(qdk[1]);
        axis_sum.parent += weight * u_seg1.normalized();
        axis_sum.child += weight * u_seg2.normalized();
        axes_seen.emplace_back(u_seg1.normalized(), weight);
    };
    {
        const Kin k0 = model.kin(q, qd);
        tracks[0].q_before = Quat(k0.r1) * mount[0];
        tracks[1].q_before = Quat(k0.r2) * mount[1];
    }
    record(q, qd, 0.0);
    const double h = dt / kSubsteps;
    for (std::size_t s = 1; s < n; ++s) {
        const double t_start = static_cast<double>(s - 1) * dt;
        if (t_start >= next_push_s) {
            Push p;
            p.t0_s = t_start;
            if (pushes.empty()) {
                p.duration_s = 0.5;
                p.joint = 0;
                p.gain = rng.sign() * rng.uniform(1.2, 1.8);  // N·m on the upper bar from rest
            } else {
                // Pump toward the energy of a swing of the upper bar of A, E* = V(A, 0) − V(0, 0):
                // 45–85° through the pivot, less through the lower joint (whose bar would
                // otherwise turn over).
                p.joint = rng.uniform() < 0.6 ? 0 : 1;
                const double amp = (p.joint == 0 ? rng.uniform(45.0, 85.0) : rng.uniform(30.0, 55.0)) * kDeg;
                const double target = model.energy_j(Vec2(amp, 0.0), Vec2::Zero()) - e_rest;
                const double swing = std::max(1e-3, model.energy_j(q, qd) - e_rest);
                p.duration_s = rng.uniform(2.0, 4.0);
                p.pump = true;
                // E grows by exp(2 K ∫w / M_jj) with ∫w = d/2 for a pump K along θ̇_j.
                const double m_jj = model.mass_matrix(q)(p.joint, p.joint);
                p.gain = std::clamp(std::log(target / swing), 0.0, 3.0) * m_jj / p.duration_s;
            }
            pushes.push_back(p);
            next_push_s = t_start + rng.uniform(8.0, 20.0);
        }
        for (int i = 0; i < kSubsteps; ++i) {
            const double t = t_start + i * h;
            auto f = [&](double tt, const Vec2& qq, const Vec2& vv) {
                return model.accel(qq, vv, torque(pushes, tt, vv, o.free_swing));
            };
            const Vec2 k1v = f(t, q, qd), k1q = qd;
            const Vec2 k2q = qd + 0.5 * h * k1v, k2v = f(t + 0.5 * h, q + 0.5 * h * k1q, k2q);
            const Vec2 k3q = qd + 0.5 * h * k2v, k3v = f(t + 0.5 * h, q + 0.5 * h * k2q, k3q);
            const Vec2 k4q = qd + h * k3v, k4v = f(t + h, q + h * k3q, k4q);
            q += (h / 6.0) * (k1q + 2.0 * k2q + 2.0 * k3q + k4q);
            qd += (h / 6.0) * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
        }
        record(q, qd, static_cast<double>(s) * dt);
    }

    ChainRecording rec;
    rec.scenario = "pendulum";
    rec.seed = o.seed;
    rec.rate_hz = o.rate_hz;
    rec.duration_s = o.duration_s;
    rec.magnetic_env = env.spec().name;
    const auto bodies = pendulum_bodies();
    for (std::size_t i = 0; i < 2; ++i) {
        ChainSensor sensor;
        sensor.name = "seg" + std::to_string(i + 1);
        sensor.length_m = bodies[i].length_m;
        sensor.q_segment_sensor = mount[i];
        sense_track(tracks[i], o.rate_hz, env, o.noise_scale, o.seed, 200 + i, sensor);
        rec.sensors.push_back(std::move(sensor));
    }
    const Vec3 mean_parent = axis_sum.parent.norm() > 0.0 ? Vec3(axis_sum.parent.normalized()) : Vec3(Vec3::UnitZ());
    const Vec3 mean_child = axis_sum.child.norm() > 0.0 ? Vec3(axis_sum.child.normalized()) : Vec3(Vec3::UnitZ());
    ChainJoint j;
    j.parent = "seg1";
    j.child = "seg2";
    j.type = "hinge";
    j.axis_parent = math::rotate(math::conj(mount[0]), mean_parent);
    j.axis_child = math::rotate(math::conj(mount[1]), mean_child);
    j.r_parent_m = math::rotate(math::conj(mount[0]), Vec3(0.5 * bodies[0].length_m, 0.0, 0.0));
    j.r_child_m = math::rotate(math::conj(mount[1]), Vec3(-0.5 * bodies[1].length_m, 0.0, 0.0));
    double wander = 0.0;
    for (const auto& [axis, weight] : axes_seen) {
        if (weight > 0.1) wander = std::max(wander, std::acos(std::clamp(axis.dot(mean_parent), -1.0, 1.0)));
    }
    j.axis_wander_deg = wander / kDeg;
    j.note = "not an exact hinge: the axis of seg2 relative to seg1 turns with the joint angle (docs/simulator.md)";
    rec.joints.push_back(j);
    return rec;
}

}  // namespace mocap::sim
