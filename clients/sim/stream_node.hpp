// stream_node.hpp — one simulated sensor node of `mocap-sim stream`: from its segment's true
// motion to the CAN frames an MPU9250 node would send for one SYNC.
//
// Model (ENU earth frame, docs/design.md, "Quaternions and frames"):
//   q_earth_sensor = q_earth_segment ⊗ q_segment_sensor, with a fixed mounting rotation drawn
//   per node from the seed: a random axis and an angle up to 30° (the root segment's node
//   turns only about its own x axis, so its x axis still points forward for the daemon's
//   `facing = "sensor"` calibration).
//   gyro  ω_k = 2·log(conj(q_{k-1}) ⊗ q_k) / dt in the sensor frame: the constant body rate
//         that carries the previous truth to this one (as scenario.hpp), + a constant per-node
//         bias (up to 2 °/s per axis) + white noise;
//   accel f = R(q)ᵀ (a_lin + [0, 0, g]), a_lin the earth-frame linear acceleration of the
//         sensor (the caller's finite difference), + white noise;
//   mag   m = R(q)ᵀ m_earth + h, m_earth the field at the sensor (the caller's: a magnetic
//         environment, magnetic_env.hpp; by default 50 µT at 60° dip, north and down), h a
//         hard-iron offset fixed in the sensor frame (set_hard_iron_ut: a magnet carried by
//         the segment; zero by default), + white noise;
//   noise σ: the "realistic" scenario's MEMS figures (scenario_spec).
// Quantisation through the wire library (mw_*_from_*), ranges ±16 g / ±2000 °/s, so the
// daemon decodes exactly what a real node would send. Attitude mode sends q_earth_sensor
// with 0.5° of rotation noise as one ATT frame.
//
// Thread-safety: one instance per thread. Cost: a few hundred ns per sample, no allocation.
#pragma once

#include <cstdint>

#include "math/quaternion.hpp"
#include "mocap_wire/mw_can.h"
#include "sim/sim_rng.hpp"

namespace mocap::sim {

using math::Quat;
using math::Vec3;

/// Earth field used by the simulator: 50 µT, dip 60° (ENU: north and down).
Vec3 stream_mag_earth_ut();

struct NodeSensorNoise {
    double gyro_rad_s = 0.0;
    double accel_m_s2 = 0.0;
    double mag_ut = 0.0;
    double attitude_rad = 0.0;
    double gyro_bias_max_rad_s = 0.0;
};

/// The realistic MEMS figures (scale 1) or silence (scale 0).
NodeSensorNoise stream_node_noise(double scale);

/// What one sample should read, before noise and quantisation.
struct SensorReading {
    Vec3 gyro_rad_s;
    Vec3 accel_m_s2;
    Vec3 mag_ut;
};

/// The ideal reading of a sensor whose orientation went from q_prev to q over dt_s, with
/// earth-frame linear acceleration lin_acc_earth, in the earth-frame field mag_earth_ut.
SensorReading ideal_reading(const Quat& q_prev, const Quat& q, double dt_s, const Vec3& lin_acc_earth_m_s2,
                            const Vec3& mag_earth_ut = stream_mag_earth_ut());

class SimulatedNode {
public:
    /// node_id 1..63; root: mount rotation only about the sensor x axis.
    SimulatedNode(std::uint8_t node_id, bool root, std::uint64_t seed, std::uint64_t stream,
                  const NodeSensorNoise& noise);

    [[nodiscard]] std::uint8_t node_id() const { return node_id_; }
    [[nodiscard]] const Quat& q_segment_sensor() const { return q_segment_sensor_; }
    [[nodiscard]] const Vec3& gyro_bias_rad_s() const { return gyro_bias_rad_s_; }
    /// A constant field added to every magnetometer reading, sensor frame, µT.
    void set_hard_iron_ut(const Vec3& offset_ut) { hard_iron_ut_ = offset_ut; }
    [[nodiscard]] const Vec3& hard_iron_ut() const { return hard_iron_ut_; }

    /// The three raw frames (ACCEL, GYRO, MAG) for SYNC `counter`, in the earth-frame field
    /// mag_earth_ut at the sensor. Returns 3.
    int raw_frames(const Quat& q_earth_segment_prev, const Quat& q_earth_segment, double dt_s,
                   const Vec3& lin_acc_earth_m_s2, std::uint32_t counter, mw_can_frame out[3],
                   const Vec3& mag_earth_ut = stream_mag_earth_ut());
    /// The ATT frame for SYNC `counter`. Returns 1.
    int attitude_frame(const Quat& q_earth_segment, std::uint32_t counter, mw_can_frame out[1]);

private:
    Vec3 noise(double sigma);

    std::uint8_t node_id_;
    Quat q_segment_sensor_;
    Vec3 gyro_bias_rad_s_ = Vec3::Zero();
    Vec3 hard_iron_ut_ = Vec3::Zero();
    NodeSensorNoise noise_;
    SimRng rng_;
};

}  // namespace mocap::sim
