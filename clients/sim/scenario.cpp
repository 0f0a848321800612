#include "sim/scenario.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include "sim/sim_rng.hpp"

namespace mocap::sim {

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDegToRad = kPi / 180.0;
constexpr double kGaussToUt = 100.0;

// Independent random streams of one seed (SimRng's `stream`).
enum Stream : std::uint64_t { kMotion = 1, kNoise = 2, kBias = 3, kDisturbance = 4, kStart = 5, kBursts = 6 };

/// Earth field of the given strength and dip (inclination below the horizon), pointing to
/// magnetic north (+y in ENU) so that magnetic and true north coincide.
Vec3 field_enu_ut(double norm_ut, double dip_rad) {
    return {0.0, norm_ut * std::cos(dip_rad), -norm_ut * std::sin(dip_rad)};
}

// ---------------------------------------------------------------- fourati / continuous / bursts

constexpr double kTablePieceS = 15.0;  // Table I: four pieces of 15 s
constexpr int kTableSubsteps = 8;      // RK4 steps per sample interval for the truth

bool follows_table_one(ScenarioKind kind) {
    return kind == ScenarioKind::fourati || kind == ScenarioKind::continuous || kind == ScenarioKind::bursts;
}

/// Table I's piece (1..4) for the sample interval (t - dt, t]: the piece of its midpoint, so
/// an interval that ends on a boundary belongs to the piece it lies in.
int table_piece(double t_mid_s) {
    return std::clamp(static_cast<int>(std::floor(t_mid_s / kTablePieceS)), 0, 3) + 1;
}

Quat quat_derivative(const Quat& q, const Vec3& w) {
    const Quat dq = q * Quat(0.0, w.x(), w.y(), w.z());
    return Quat(0.5 * dq.w(), 0.5 * dq.x(), 0.5 * dq.y(), 0.5 * dq.z());
}

Quat axpy(const Quat& q, double h, const Quat& k) {
    return Quat(q.coeffs() + h * k.coeffs());
}

/// The truth over one sample interval: q̇ = ½ q ⊗ [0, ω(t)] with ω of one Table I piece,
/// classical RK4 in kTableSubsteps steps (error far below 1e-9 rad per interval at these
/// rates and frequencies), normalised at the end.
Quat integrate_table_one(const Quat& q0, int piece, double t0_s, double dt_s) {
    const double h = dt_s / kTableSubsteps;
    Quat q = q0;
    for (int i = 0; i < kTableSubsteps; ++i) {
        const double t = t0_s + i * h;
        const Vec3 w0 = fourati_table_rate_rad_s(piece, t);
        const Vec3 wm = fourati_table_rate_rad_s(piece, t + 0.5 * h);
        const Vec3 w1 = fourati_table_rate_rad_s(piece, t + h);
        const Quat k1 = quat_derivative(q, w0);
        const Quat k2 = quat_derivative(axpy(q, 0.5 * h, k1), wm);
        const Quat k3 = quat_derivative(axpy(q, 0.5 * h, k2), wm);
        const Quat k4 = quat_derivative(axpy(q, h, k3), w1);
        q = Quat(q.coeffs() + (h / 6.0) * (k1.coeffs() + 2.0 * k2.coeffs() + 2.0 * k3.coeffs() + k4.coeffs()));
    }
    return q.normalized();
}

// ---------------------------------------------------------------- realistic / magnetic

constexpr double kRampS = 0.6;        // raised-cosine fade in/out of each movement
constexpr double kRestoreGain = 0.6;  // 1/s, pulls the sensor's z axis back toward up
constexpr double kDisturbanceHeadingRad = 39.0 * kDegToRad;
constexpr double kDisturbanceRampS = 1.5;

struct Sinusoid {
    double amp_rad_s = 0.0;
    double freq_hz = 0.0;
    double phase_rad = 0.0;
};

struct Movement {
    double t0_s = 0.0;
    double t1_s = 0.0;
    std::array<std::array<Sinusoid, 3>, 3> axes{};  // [axis][component]
};

struct Burst {
    double t0_s = 0.0;
    double duration_s = 0.0;
    double amp_m_s2 = 0.0;
    Vec3 dir = Vec3::UnitX();
};

struct MotionPlan {
    std::vector<Movement> movements;
    std::vector<Burst> bursts;
};

Vec3 random_unit(SimRng& rng) {
    // Normal components give a uniformly distributed direction.
    for (;;) {
        const Vec3 v(rng.normal(), rng.normal(), rng.normal());
        if (v.norm() > 1e-6) return v.normalized();
    }
}

/// Rest at the start (5–7 s), then movements of 8–16 s separated by rests of 2–4 s, a
/// final rest of at least 2 s. Each movement has 3 sinusoids per axis (0.15–1.2 Hz,
/// 0.2–0.8 rad/s: a limb's swing, peaks ~2 rad/s) and bursts of linear acceleration
/// (0.3–0.8 s, 2–6 m/s², one full sine so the velocity returns to zero) every 1.5–4 s.
MotionPlan plan_motion(SimRng& rng, double duration_s) {
    MotionPlan plan;
    double t = rng.uniform(5.0, 7.0);
    for (;;) {
        const double end_limit = duration_s - 2.0;
        const double len = std::min(rng.uniform(8.0, 16.0), end_limit - t);
        if (len < 4.0) break;
        Movement m;
        m.t0_s = t;
        m.t1_s = t + len;
        for (auto& axis : m.axes) {
            for (auto& s : axis) {
                s.amp_rad_s = rng.uniform(0.2, 0.8);
                s.freq_hz = rng.uniform(0.15, 1.2);
                s.phase_rad = rng.uniform(0.0, 2.0 * kPi);
            }
        }
        double tb = m.t0_s + kRampS + rng.uniform(0.5, 2.0);
        for (;;) {
            Burst b;
            b.duration_s = rng.uniform(0.3, 0.8);
            b.amp_m_s2 = rng.uniform(2.0, 6.0);
            b.dir = random_unit(rng);
            b.t0_s = tb;
            if (tb + b.duration_s > m.t1_s - kRampS) break;
            plan.bursts.push_back(b);
            tb += b.duration_s + rng.uniform(1.5, 4.0);
        }
        plan.movements.push_back(m);
        t = m.t1_s + rng.uniform(2.0, 4.0);
    }
    return plan;
}

/// 0 outside [t0, t1], 1 inside, raised-cosine ramps of ramp_s at both ends.
double smooth_window(double t, double t0, double t1, double ramp_s) {
    if (t <= t0 || t >= t1) return 0.0;
    const double u = std::min(t - t0, t1 - t);
    if (u >= ramp_s) return 1.0;
    return 0.5 - 0.5 * std::cos(kPi * u / ramp_s);
}

Vec3 plan_rate_rad_s(const MotionPlan& plan, double t_s, const Quat& q_earth_sensor) {
    for (const Movement& m : plan.movements) {
        const double e = smooth_window(t_s, m.t0_s, m.t1_s, kRampS);
        if (e <= 0.0) continue;
        Vec3 w = Vec3::Zero();
        for (int i = 0; i < 3; ++i) {
            for (const Sinusoid& s : m.axes[static_cast<std::size_t>(i)]) {
                w[i] += s.amp_rad_s * std::sin(2.0 * kPi * s.freq_hz * t_s + s.phase_rad);
            }
        }
        // A limb returns toward its neutral pose: with u_b = earth up seen in the sensor
        // frame, ω = k (z × u_b) turns the sensor's z axis toward up without bounding
        // heading. It keeps long recordings away from permanent gimbal-lock poses.
        const Vec3 up_sensor = math::rotate(math::conj(q_earth_sensor), Vec3::UnitZ());
        w += kRestoreGain * Vec3::UnitZ().cross(up_sensor);
        return e * w;
    }
    return Vec3::Zero();
}

/// Moving at sample t if the sample's interval (t - dt, t] overlaps a movement, so that
/// every row whose gyro reading carries motion is flagged.
bool plan_moving(const MotionPlan& plan, double t_s, double dt_s) {
    return std::any_of(plan.movements.begin(), plan.movements.end(),
                       [&](const Movement& m) { return t_s > m.t0_s && t_s - dt_s < m.t1_s; });
}

Vec3 plan_lin_acc_m_s2(const MotionPlan& plan, double t_s) {
    Vec3 a = Vec3::Zero();
    for (const Burst& b : plan.bursts) {
        const double u = (t_s - b.t0_s) / b.duration_s;
        if (u > 0.0 && u < 1.0) a += b.amp_m_s2 * std::sin(2.0 * kPi * u) * b.dir;
    }
    return a;
}

/// Field added near a steel object: at full strength the horizontal field turns by 39°
/// (direction drawn from the seed) and grows by 10%, and the vertical field weakens by
/// 4 µT (norm 50 -> ~48.0 µT, dip 60° -> ~55.0°), over a window of 16 s (1.5 s ramps)
/// centred in the recording.
struct Disturbance {
    Vec3 delta_ut = Vec3::Zero();
    double t0_s = 0.0;
    double t1_s = 0.0;
    [[nodiscard]] Vec3 at(double t_s) const { return smooth_window(t_s, t0_s, t1_s, kDisturbanceRampS) * delta_ut; }
};

Disturbance make_disturbance(SimRng& rng, const ScenarioSpec& spec) {
    const Vec3& m0 = spec.mag_field_ut;
    const Vec3 h(m0.x(), m0.y(), 0.0);
    const double turn = rng.sign() * kDisturbanceHeadingRad;
    const Vec3 h_disturbed = 1.1 * (Eigen::AngleAxisd(turn, Vec3::UnitZ()) * h);
    Disturbance d;
    d.delta_ut = (h_disturbed - h) + Vec3(0.0, 0.0, 4.0);
    d.t0_s = 0.5 * spec.duration_s - 8.0;
    d.t1_s = 0.5 * spec.duration_s + 8.0;
    return d;
}

/// A burst of linear acceleration in the earth frame with a plateau and raised-cosine ramps:
/// it does not average out over the burst, as a push or a carried sensor's start does not.
struct PlateauBurst {
    double t0_s = 0.0;
    double t1_s = 0.0;
    Vec3 acc_m_s2 = Vec3::Zero();  ///< plateau value
};

/// spec.lin_acc_bursts bursts, one in each equal slice of the recording, at least 1 s from the
/// slice's ends (so consecutive bursts are 2 s apart at least and the first waits for 1 s).
std::vector<PlateauBurst> plan_plateau_bursts(SimRng& rng, const ScenarioSpec& spec) {
    std::vector<PlateauBurst> bursts;
    if (spec.lin_acc_bursts <= 0) return bursts;
    const double slice = spec.duration_s / spec.lin_acc_bursts;
    for (int i = 0; i < spec.lin_acc_bursts; ++i) {
        PlateauBurst b;
        const double lo = i * slice + 1.0;
        const double hi = std::max(lo, (i + 1) * slice - 1.0 - spec.lin_acc_burst_s);
        b.t0_s = rng.uniform(lo, hi);
        b.t1_s = b.t0_s + spec.lin_acc_burst_s;
        const double amp = rng.uniform(spec.lin_acc_burst_min_m_s2, spec.lin_acc_burst_max_m_s2);
        b.acc_m_s2 = amp * random_unit(rng);
        bursts.push_back(b);
    }
    return bursts;
}

Vec3 plateau_lin_acc_m_s2(const std::vector<PlateauBurst>& bursts, double ramp_s, double t_s) {
    Vec3 a = Vec3::Zero();
    for (const PlateauBurst& b : bursts)
        a += smooth_window(t_s, b.t0_s, b.t1_s, ramp_s) * b.acc_m_s2;
    return a;
}

Vec3 noise_vec(SimRng& rng, double sigma) {
    const Vec3 n(rng.normal(), rng.normal(), rng.normal());
    return sigma * n;
}

}  // namespace

Vec3 fourati_table_rate_rad_s(int piece, double t_s) {
    const double t = t_s;
    switch (piece) {
        case 1:
        case 3:
            return {-2.5 * std::sin(1.5 * t), 1.5 * std::cos(0.9 * t), -1.5 * std::sin(1.2 * t)};
        case 2:
            return {-1.5 * std::sin(1.5 * t), 1.3 * std::cos(1.3 * t), -2.0 * std::sin(2.0 * t)};
        default:
            // As printed: −1.5 sin(−1.5 t), the opposite sign of piece 2's x rate.
            return {-1.5 * std::sin(-1.5 * t), 1.3 * std::cos(1.3 * t), -2.0 * std::sin(2.0 * t)};
    }
}

std::optional<ScenarioKind> parse_scenario_kind(std::string_view name) {
    if (name == "fourati") return ScenarioKind::fourati;
    if (name == "realistic") return ScenarioKind::realistic;
    if (name == "magnetic") return ScenarioKind::magnetic;
    if (name == "continuous") return ScenarioKind::continuous;
    if (name == "bursts") return ScenarioKind::bursts;
    return std::nullopt;
}

std::string_view scenario_name(ScenarioKind kind) {
    switch (kind) {
        case ScenarioKind::fourati:
            return "fourati";
        case ScenarioKind::realistic:
            return "realistic";
        case ScenarioKind::magnetic:
            return "magnetic";
        case ScenarioKind::continuous:
            return "continuous";
        case ScenarioKind::bursts:
            return "bursts";
    }
    return "unknown";
}

ScenarioSpec scenario_spec(ScenarioKind kind) {
    ScenarioSpec s;
    if (kind == ScenarioKind::fourati) {
        // Table II of the paper: σ = 0.4 in its units (rad/s, m/s², G); 0.5 G at 60°.
        s.rate_hz = 100.0;
        s.duration_s = 60.0;
        s.gyro_noise_rad_s = 0.4;
        s.accel_noise_m_s2 = 0.4;
        s.mag_noise_ut = 0.4 * kGaussToUt;
        s.gyro_bias_max_rad_s = 0.0;
        s.mag_field_ut = field_enu_ut(0.5 * kGaussToUt, 60.0 * kDegToRad);
        return s;
    }
    // MPU9250-like at 100 Hz: gyro 0.3 °/s rms (0.03 °/s/√Hz incl. vibration), accel
    // 0.03 m/s² rms (300 µg/√Hz), AK8963 mag 0.5 µT rms; bias up to 2 °/s per axis.
    s.rate_hz = 100.0;
    s.duration_s = 90.0;
    s.gyro_noise_rad_s = 0.3 * kDegToRad;
    s.accel_noise_m_s2 = 0.03;
    s.mag_noise_ut = 0.5;
    s.gyro_bias_max_rad_s = 2.0 * kDegToRad;
    s.mag_field_ut = field_enu_ut(50.0, 60.0 * kDegToRad);
    if (kind == ScenarioKind::continuous || kind == ScenarioKind::bursts) {
        // Table I's 60 s with the same sensor; every axis biased by 0.02 rad/s (1.15 °/s).
        s.duration_s = 60.0;
        s.gyro_bias_max_rad_s = 0.02;
        s.gyro_bias_min_fraction = 1.0;
    }
    if (kind == ScenarioKind::bursts) {
        // Eight 1 s pushes of 2–5 m/s² (0.2 s ramps): a fifth to a half of gravity, the size of
        // a limb's swing starting or stopping, each long enough to pass a 3 s low-pass in part.
        s.gyro_bias_mixed_signs = true;
        s.lin_acc_bursts = 8;
        s.lin_acc_burst_s = 1.0;
        s.lin_acc_burst_ramp_s = 0.2;
        s.lin_acc_burst_min_m_s2 = 2.0;
        s.lin_acc_burst_max_m_s2 = 5.0;
    }
    return s;
}

Scenario make_scenario(ScenarioKind kind, std::uint64_t seed, const ScenarioOptions& options) {
    Scenario sc;
    sc.kind = kind;
    sc.seed = seed;
    sc.spec = scenario_spec(kind);
    const ScenarioSpec& spec = sc.spec;
    const bool table_one = follows_table_one(kind);

    SimRng motion_rng(seed, kMotion);
    SimRng noise_rng(seed, kNoise);
    SimRng bias_rng(seed, kBias);
    SimRng disturbance_rng(seed, kDisturbance);
    SimRng start_rng(seed, kStart);
    SimRng bursts_rng(seed, kBursts);

    const MotionPlan plan = table_one ? MotionPlan{} : plan_motion(motion_rng, spec.duration_s);
    Disturbance disturbance;
    if (kind == ScenarioKind::magnetic) disturbance = make_disturbance(disturbance_rng, spec);
    const std::vector<PlateauBurst> plateau_bursts = plan_plateau_bursts(bursts_rng, spec);

    if (options.gyro_bias && spec.gyro_bias_max_rad_s > 0.0) {
        for (int i = 0; i < 3; ++i) {
            sc.gyro_bias_rad_s[i] =
                bias_rng.sign() * bias_rng.uniform(spec.gyro_bias_min_fraction, 1.0) * spec.gyro_bias_max_rad_s;
        }
        const bool all_equal = (sc.gyro_bias_rad_s.array() > 0.0).all() || (sc.gyro_bias_rad_s.array() < 0.0).all();
        if (spec.gyro_bias_mixed_signs && all_equal) {
            const int axis = std::min(static_cast<int>(bias_rng.uniform() * 3.0), 2);
            sc.gyro_bias_rad_s[axis] = -sc.gyro_bias_rad_s[axis];
        }
    }

    // Table I: the paper's q(0) = identity in NED, i.e. the sensor axes on north/east/down;
    // in ENU that is q_enu_ned. Otherwise: any heading, a tilt of up to 28° (±0.35 rad about east
    // and north).
    Quat q = math::q_enu_ned();
    if (!table_one) {
        const double yaw = start_rng.uniform(-kPi, kPi);
        const Vec3 tilt(start_rng.uniform(-0.35, 0.35), start_rng.uniform(-0.35, 0.35), 0.0);
        q = (Quat(Eigen::AngleAxisd(yaw, Vec3::UnitZ())) * math::quat_from_rotvec(tilt)).normalized();
    }

    const double dt = 1.0 / spec.rate_hz;
    const auto n = static_cast<std::size_t>(std::llround(spec.duration_s * spec.rate_hz)) + 1;
    sc.rows.reserve(n);
    for (std::size_t k = 0; k < n; ++k) {
        const double t = static_cast<double>(k) * dt;
        // The rate over (t - dt, t]: Table I's truth is integrated and the reading is the
        // constant rate that carries the previous truth to it; the human-like motion is
        // evaluated at the midpoint (state from the interval start).
        const double t_mid = t - 0.5 * dt;
        Vec3 w = Vec3::Zero();
        if (table_one) {
            if (k == 0) {
                w = fourati_table_rate_rad_s(1, 0.0);
            } else {
                const Quat q_next = integrate_table_one(q, table_piece(t_mid), t - dt, dt);
                w = math::rotvec_from_quat(math::conj(q) * q_next) / dt;
                q = q_next;
            }
        } else {
            w = plan_rate_rad_s(plan, t_mid, q);
            if (k > 0) q = (q * math::quat_from_rotvec(w * dt)).normalized();
        }

        ScenarioRow row;
        row.q_earth_sensor = math::canonical(q);
        row.moving = table_one || plan_moving(plan, t, dt);
        row.gyro_true_rad_s = w;
        row.lin_acc_earth_m_s2 =
            table_one ? plateau_lin_acc_m_s2(plateau_bursts, spec.lin_acc_burst_ramp_s, t) : plan_lin_acc_m_s2(plan, t);
        row.mag_earth_ut = spec.mag_field_ut + disturbance.at(t);

        const Quat q_sensor_earth = math::conj(q);
        const double ns = options.noise_scale;
        const Vec3 gyro = w + sc.gyro_bias_rad_s + noise_vec(noise_rng, ns * spec.gyro_noise_rad_s);
        const Vec3 accel = math::rotate(q_sensor_earth, row.lin_acc_earth_m_s2 + spec.gravity_up_m_s2) +
                           noise_vec(noise_rng, ns * spec.accel_noise_m_s2);
        const Vec3 mag = math::rotate(q_sensor_earth, row.mag_earth_ut) +
                         noise_vec(noise_rng, ns * options.mag_noise_scale * spec.mag_noise_ut);

        row.sample.t_us = std::llround(t * 1e6);
        row.sample.gyro_rad_s = math::to_array(gyro);
        row.sample.accel_m_s2 = math::to_array(accel);
        row.sample.mag_ut = math::to_array(mag);
        sc.rows.push_back(row);
    }
    return sc;
}

}  // namespace mocap::sim
