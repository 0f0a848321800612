// stream_node.cpp — why: readings are derived from successive truth orientations (not from
// an analytic rate), so integrating the gyro reproduces the truth exactly on noiseless data
// whatever the motion source is.
#include "sim/stream_node.hpp"

#include <cmath>
#include <numbers>

#include "mocap_wire/mw_scale.h"
#include "sim/scenario.hpp"

namespace mocap::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kMaxMountRad = 30.0 * kDeg;
constexpr mw_accel_range kAccelRange = MW_ACCEL_16G;
constexpr mw_gyro_range kGyroRange = MW_GYRO_2000DPS;

void to_floats(const Vec3& v, float out[3]) {
    for (int i = 0; i < 3; ++i)
        out[i] = static_cast<float>(v[i]);
}

void encode_raw(mw_function kind, std::uint8_t node, const std::int16_t counts[3], std::uint32_t counter,
                mw_can_frame& out) {
    mw_raw raw{};
    raw.kind = kind;
    raw.node_id = node;
    for (int i = 0; i < 3; ++i)
        raw.xyz[i] = counts[i];
    raw.counter_low = static_cast<std::uint16_t>(counter & 0xFFFFu);
    (void)mw_raw_encode(&raw, &out);  // node id and kind are valid by construction
}

}  // namespace

Vec3 stream_mag_earth_ut() {
    const double dip = 60.0 * kDeg;
    return {0.0, 50.0 * std::cos(dip), -50.0 * std::sin(dip)};
}

NodeSensorNoise stream_node_noise(double scale) {
    const ScenarioSpec spec = scenario_spec(ScenarioKind::realistic);
    NodeSensorNoise n;
    n.gyro_rad_s = scale * spec.gyro_noise_rad_s;
    n.accel_m_s2 = scale * spec.accel_noise_m_s2;
    n.mag_ut = scale * spec.mag_noise_ut;
    n.attitude_rad = scale * 0.5 * kDeg;
    n.gyro_bias_max_rad_s = scale * spec.gyro_bias_max_rad_s;
    return n;
}

SensorReading ideal_reading(const Quat& q_prev, const Quat& q, double dt_s, const Vec3& lin_acc_earth_m_s2,
                            const Vec3& mag_earth_ut) {
    SensorReading r;
    r.gyro_rad_s = 2.0 * math::quat_log(math::canonical(math::conj(q_prev) * q)) / dt_s;
    const Quat q_sensor_earth = math::conj(q);
    r.accel_m_s2 = math::rotate(q_sensor_earth, lin_acc_earth_m_s2 + Vec3(0.0, 0.0, MW_STANDARD_GRAVITY_M_S2));
    r.mag_ut = math::rotate(q_sensor_earth, mag_earth_ut);
    return r;
}

SimulatedNode::SimulatedNode(std::uint8_t node_id, bool root, std::uint64_t seed, std::uint64_t stream,
                             const NodeSensorNoise& noise)
    : node_id_(node_id), noise_(noise), rng_(seed, stream) {
    SimRng mount(seed, stream ^ 0x4D4F554E54ull);  // independent of the noise sequence
    const double angle = mount.uniform(-kMaxMountRad, kMaxMountRad);
    Vec3 axis = Vec3::UnitX();
    if (!root) {
        axis = Vec3(mount.normal(), mount.normal(), mount.normal());
        axis = axis.norm() > 1e-9 ? Vec3(axis.normalized()) : Vec3(Vec3::UnitZ());
    }
    q_segment_sensor_ = math::quat_from_rotvec(angle * axis);
    for (int i = 0; i < 3; ++i) {
        gyro_bias_rad_s_[i] = mount.sign() * mount.uniform(0.25, 1.0) * noise_.gyro_bias_max_rad_s;
    }
}

Vec3 SimulatedNode::noise(double sigma) {
    if (sigma <= 0.0) return Vec3::Zero();
    return sigma * Vec3(rng_.normal(), rng_.normal(), rng_.normal());
}

int SimulatedNode::raw_frames(const Quat& q_earth_segment_prev, const Quat& q_earth_segment, double dt_s,
                              const Vec3& lin_acc_earth_m_s2, std::uint32_t counter, mw_can_frame out[3],
                              const Vec3& mag_earth_ut) {
    const SensorReading r = ideal_reading(q_earth_segment_prev * q_segment_sensor_, q_earth_segment * q_segment_sensor_,
                                          dt_s, lin_acc_earth_m_s2, mag_earth_ut);
    float v[3];
    std::int16_t counts[3];
    to_floats(r.accel_m_s2 + noise(noise_.accel_m_s2), v);
    (void)mw_accel_from_m_s2(v, kAccelRange, counts);  // saturation is what a real part does
    encode_raw(MW_FN_ACCEL, node_id_, counts, counter, out[0]);
    to_floats(r.gyro_rad_s + gyro_bias_rad_s_ + noise(noise_.gyro_rad_s), v);
    (void)mw_gyro_from_rad_s(v, kGyroRange, counts);
    encode_raw(MW_FN_GYRO, node_id_, counts, counter, out[1]);
    to_floats(r.mag_ut + hard_iron_ut_ + noise(noise_.mag_ut), v);
    (void)mw_mag_from_ut(v, counts);
    encode_raw(MW_FN_MAG, node_id_, counts, counter, out[2]);
    return 3;
}

int SimulatedNode::attitude_frame(const Quat& q_earth_segment, std::uint32_t counter, mw_can_frame out[1]) {
    const Quat q = q_earth_segment * q_segment_sensor_ * math::quat_from_rotvec(noise(noise_.attitude_rad));
    mw_attitude att{};
    att.node_id = node_id_;
    att.q[0] = static_cast<float>(q.w());
    att.q[1] = static_cast<float>(q.x());
    att.q[2] = static_cast<float>(q.y());
    att.q[3] = static_cast<float>(q.z());
    att.counter_low = static_cast<std::uint16_t>(counter & 0x3FFFu);
    (void)mw_attitude_encode(&att, &out[0]);  // a unit quaternion always encodes
    return 1;
}

}  // namespace mocap::sim
