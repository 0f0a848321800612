// chain_scenario.cpp — why: every degree of freedom is an explicit function of time (a glide
// between postures plus a faded swing, with C∞ transitions), so poses can be evaluated at any
// instant and the accelerometer gets the exact second derivative of the positions instead of
// a sampled approximation; pauses are exactly still, so `movement` is exactly 0 there.
#include "sim/chain_scenario.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include "sim/sim_rng.hpp"

namespace mocap::sim {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;
constexpr std::size_t kSegments = 5;
constexpr double kAccelStepS = 2e-4;  // central difference for the linear acceleration

// Degrees of freedom: the hand (base yaw, pitch, roll; grip x, y, z) and the joints.
enum Channel : std::size_t {
    kYaw,
    kPitch,
    kRoll,
    kX,
    kY,
    kZ,
    kHinge1,
    kHinge2,
    kHinge3,
    kTwoDofA,
    kTwoDofB,
    kChannels
};
// What moves together: the base, each hinge, the 2-DoF joint.
constexpr std::size_t kGroups = 5;
constexpr std::array<std::pair<std::size_t, std::size_t>, kGroups> kGroupChannels = {
    {{kYaw, kHinge1}, {kHinge1, kHinge2}, {kHinge2, kHinge3}, {kHinge3, kTwoDofA}, {kTwoDofA, kChannels}}};

struct Limit {
    double posture = 0.0;  ///< |posture| bound
    double swing = 0.0;    ///< each of the three sinusoids' amplitude bound
};
// Angles in rad, grip in m; posture + 3 swings bounds each degree of freedom (header).
constexpr std::array<Limit, kChannels> kLimits = {{
    {50 * kDeg, 12 * kDeg},  // yaw
    {12 * kDeg, 5 * kDeg},   // pitch (tilts the arm's length: it stays at table height)
    {60 * kDeg, 10 * kDeg},  // roll: the base is held in the hand, turned about the arm's
                             // length, so no hinge axis stays vertical for long
    {0.10, 0.06},            // x
    {0.10, 0.06},            // y
    {0.06, 0.04},            // z
    {40 * kDeg, 16 * kDeg},  // hinge 1
    {40 * kDeg, 16 * kDeg},  // hinge 2
    {25 * kDeg, 10 * kDeg},  // hinge 3 (bends the arm up and down)
    {35 * kDeg, 15 * kDeg},  // 2-DoF, about seg4's z
    {25 * kDeg, 12 * kDeg},  // 2-DoF, about seg5's y
}};

struct Wave {
    double amp = 0.0;
    double freq_hz = 0.0;
    double phase_rad = 0.0;
};

struct Episode {
    double t0_s = 0.0, t1_s = 0.0, ramp_s = 1.0;
    std::array<bool, kChannels> active{};
    std::array<std::array<Wave, 3>, kChannels> waves{};
    std::array<double, kChannels> from{}, to{};
};

struct Arm {
    std::array<double, kSegments> length_m{};
    std::array<Quat, kSegments> q_segment_sensor{};
    std::vector<Episode> episodes;
};

/// C∞ step: 0 for u <= 0, 1 for u >= 1.
double transition(double u) {
    if (u <= 0.0) return 0.0;
    if (u >= 1.0) return 1.0;
    const double a = std::exp(-1.0 / u), b = std::exp(-1.0 / (1.0 - u));
    return a / (a + b);
}

Quat rot(const Vec3& axis, double angle_rad) {
    return Quat(Eigen::AngleAxisd(angle_rad, axis));
}

std::vector<Episode> plan_episodes(SimRng& rng, double duration_s) {
    std::vector<Episode> out;
    // The hand holds the base in some posture from the start (a recording begins at rest,
    // not with every joint at zero).
    std::array<double, kChannels> posture{};
    for (std::size_t c = 0; c < kChannels; ++c)
        posture[c] = rng.uniform(-1.0, 1.0) * kLimits[c].posture;
    // Each group alone once, in a seeded order (Fisher–Yates), then mixtures.
    std::array<std::size_t, kGroups> order = {0, 1, 2, 3, 4};
    for (std::size_t i = kGroups - 1; i > 0; --i)
        std::swap(order[i], order[static_cast<std::size_t>(rng.uniform() * static_cast<double>(i + 1))]);
    double t = rng.uniform(3.0, 5.0);
    for (std::size_t e = 0;; ++e) {
        const double len = std::min(rng.uniform(6.0, 14.0), duration_s - 2.0 - t);
        if (len < 4.0) break;
        std::array<bool, kGroups> groups{};
        if (e < kGroups) {
            groups[order[e]] = true;
        } else if (e == kGroups) {
            groups.fill(true);
        } else {
            const double kind = rng.uniform();
            if (kind < 0.4) {
                groups.fill(true);
            } else if (kind < 0.65) {
                groups[std::min<std::size_t>(kGroups - 1, static_cast<std::size_t>(rng.uniform() * kGroups))] = true;
            } else {
                for (std::size_t g = 0; g < kGroups; ++g)
                    groups[g] = rng.uniform() < (g == 0 ? 0.8 : 0.5);  // the hand rarely rests
                if (std::none_of(groups.begin(), groups.end(), [](bool g) { return g; })) groups[0] = true;
            }
        }
        Episode ep;
        ep.t0_s = t;
        ep.t1_s = t + len;
        ep.ramp_s = std::min(1.5, len / 3.0);
        const double speed = rng.uniform(0.6, 1.8);
        ep.from = posture;
        ep.to = posture;
        for (std::size_t g = 0; g < kGroups; ++g) {
            if (!groups[g]) continue;
            for (std::size_t c = kGroupChannels[g].first; c < kGroupChannels[g].second; ++c) {
                ep.active[c] = true;
                ep.to[c] = rng.uniform(-1.0, 1.0) * kLimits[c].posture;
                for (Wave& w : ep.waves[c]) {
                    w.amp = rng.uniform(0.2, 1.0) * kLimits[c].swing;
                    // The hand shifts the grip faster than it turns the joints.
                    const bool shift = c == kX || c == kY || c == kZ;
                    w.freq_hz = speed * (shift ? rng.uniform(0.25, 0.9) : rng.uniform(0.1, 0.6));
                    w.phase_rad = rng.uniform(0.0, 2.0 * kPi);
                }
            }
        }
        posture = ep.to;
        out.push_back(ep);
        t = ep.t1_s + rng.uniform(2.0, 5.0);
    }
    return out;
}

std::array<double, kChannels> channels_at(const std::vector<Episode>& episodes, double t_s) {
    std::array<double, kChannels> v = episodes.empty() ? std::array<double, kChannels>{} : episodes.front().from;
    for (const Episode& ep : episodes) {
        if (t_s <= ep.t0_s) break;  // still in the posture the previous episode left
        const double glide = transition((t_s - ep.t0_s) / (ep.t1_s - ep.t0_s));
        const double fade = transition((t_s - ep.t0_s) / ep.ramp_s) * transition((ep.t1_s - t_s) / ep.ramp_s);
        for (std::size_t c = 0; c < kChannels; ++c) {
            v[c] = ep.from[c] + (ep.to[c] - ep.from[c]) * glide;
            if (!ep.active[c] || fade <= 0.0) continue;
            for (const Wave& w : ep.waves[c])
                v[c] += fade * w.amp * std::sin(2.0 * kPi * w.freq_hz * (t_s - ep.t0_s) + w.phase_rad);
        }
    }
    return v;
}

/// Segment orientations and proximal-joint positions at t.
void arm_pose(const Arm& arm, double t_s, std::array<Quat, kSegments>& q, std::array<Vec3, kSegments>& proximal) {
    const auto v = channels_at(arm.episodes, t_s);
    q[0] = rot(Vec3::UnitZ(), v[kYaw]) * rot(Vec3::UnitY(), v[kPitch]) * rot(Vec3::UnitX(), v[kRoll]);
    q[1] = q[0] * rot(Vec3::UnitZ(), v[kHinge1]);
    q[2] = q[1] * rot(Vec3::UnitZ(), v[kHinge2]);
    q[3] = q[2] * rot(Vec3::UnitY(), v[kHinge3]);
    q[4] = q[3] * rot(Vec3::UnitZ(), v[kTwoDofA]) * rot(Vec3::UnitY(), v[kTwoDofB]);
    proximal[0] = chain_base_position_m() + Vec3(v[kX], v[kY], v[kZ]);
    for (std::size_t i = 1; i < kSegments; ++i)
        proximal[i] = proximal[i - 1] + math::rotate(q[i - 1], Vec3(arm.length_m[i - 1], 0.0, 0.0));
}

std::array<Vec3, kSegments> sensor_positions_m(const Arm& arm, double t_s) {
    std::array<Quat, kSegments> q;
    std::array<Vec3, kSegments> p;
    arm_pose(arm, t_s, q, p);
    for (std::size_t i = 0; i < kSegments; ++i)
        p[i] += math::rotate(q[i], Vec3(0.5 * arm.length_m[i], 0.0, 0.0));
    return p;
}

}  // namespace

Vec3 chain_base_position_m() {
    return workbench_position_m() + Vec3(-0.6, 0.0, 1.0);
}

ChainRecording make_chain_scenario(const ChainOptions& o, const MagneticEnv& env) {
    Arm arm;
    SimRng shape(o.seed, 11);
    for (double& l : arm.length_m)
        l = shape.uniform(0.2, 0.35);
    for (std::size_t i = 0; i < kSegments; ++i)
        arm.q_segment_sensor[i] = random_rotation(o.seed, 500 + i);
    SimRng plan(o.seed, 12);
    arm.episodes = plan_episodes(plan, o.duration_s);

    const double dt = 1.0 / o.rate_hz;
    const auto n = static_cast<std::size_t>(std::llround(o.duration_s * o.rate_hz)) + 1;
    std::array<SensorTrack, kSegments> tracks;
    for (SensorTrack& tr : tracks) {
        tr.q_earth_sensor.reserve(n);
        tr.position_m.reserve(n);
        tr.lin_acc_earth_m_s2.reserve(n);
    }
    std::array<Quat, kSegments> q;
    std::array<Vec3, kSegments> p;
    arm_pose(arm, -dt, q, p);
    for (std::size_t i = 0; i < kSegments; ++i)
        tracks[i].q_before = q[i] * arm.q_segment_sensor[i];
    for (std::size_t k = 0; k < n; ++k) {
        const double t = static_cast<double>(k) * dt;
        arm_pose(arm, t, q, p);
        const auto before = sensor_positions_m(arm, t - kAccelStepS);
        const auto after = sensor_positions_m(arm, t + kAccelStepS);
        for (std::size_t i = 0; i < kSegments; ++i) {
            const Vec3 pos = p[i] + math::rotate(q[i], Vec3(0.5 * arm.length_m[i], 0.0, 0.0));
            tracks[i].q_earth_sensor.push_back(q[i] * arm.q_segment_sensor[i]);
            tracks[i].position_m.push_back(pos);
            tracks[i].lin_acc_earth_m_s2.push_back((after[i] - 2.0 * pos + before[i]) / (kAccelStepS * kAccelStepS));
        }
    }

    ChainRecording rec;
    rec.scenario = "chain";
    rec.seed = o.seed;
    rec.rate_hz = o.rate_hz;
    rec.duration_s = o.duration_s;
    rec.magnetic_env = env.spec().name;
    for (std::size_t i = 0; i < kSegments; ++i) {
        ChainSensor s;
        s.name = "seg" + std::to_string(i + 1);
        s.length_m = arm.length_m[i];
        s.q_segment_sensor = arm.q_segment_sensor[i];
        sense_track(tracks[i], o.rate_hz, env, o.noise_scale, o.seed, 100 + i, s);
        rec.sensors.push_back(std::move(s));
    }
    // Axes and joint centres in the sensor frames: conj(mounting) applied to segment vectors.
    const Vec3 axis_parent_seg[4] = {Vec3::UnitZ(), Vec3::UnitZ(), Vec3::UnitY(), Vec3::UnitZ()};
    const Vec3 axis_child_seg[4] = {Vec3::UnitZ(), Vec3::UnitZ(), Vec3::UnitY(), Vec3::UnitY()};
    for (std::size_t i = 0; i + 1 < kSegments; ++i) {
        const Quat to_parent = math::conj(arm.q_segment_sensor[i]);
        const Quat to_child = math::conj(arm.q_segment_sensor[i + 1]);
        ChainJoint j;
        j.parent = rec.sensors[i].name;
        j.child = rec.sensors[i + 1].name;
        j.type = i + 2 == kSegments ? "2dof" : "hinge";
        j.axis_parent = math::rotate(to_parent, axis_parent_seg[i]);
        j.axis_child = math::rotate(to_child, axis_child_seg[i]);
        j.r_parent_m = math::rotate(to_parent, Vec3(0.5 * arm.length_m[i], 0.0, 0.0));
        j.r_child_m = math::rotate(to_child, Vec3(-0.5 * arm.length_m[i + 1], 0.0, 0.0));
        rec.joints.push_back(j);
    }
    return rec;
}

}  // namespace mocap::sim
