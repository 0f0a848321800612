// chain_recording.hpp — a recording of several sensors on a chain of rigid segments with its
// truth (`mocap-sim csv --scenario chain|pendulum`), the sensor model that turns true
// trajectories into readings, and the files it is written as (docs/simulator.md, "Chain files"):
//
//   DIR/NAME.toml   the CHAIN.toml of `mocap-filter --chain`: one [[segment]] per sensor
//                   (name, csv relative to the TOML's folder) and one [[joint]] per joint
//                   (parent, child, type hinge|2dof|ball, axis_parent and axis_child: unit
//                   vectors in the parent's and the child's SENSOR frame; for 2dof the axis
//                   fixed in each). The axes are the true ones; delete them to test axis
//                   estimation.
//   DIR/SEG.csv     one per segment, the `mocap-filter --in` layout with the reference
//                   (recording_csv.hpp): t,gx,gy,gz,ax,ay,az,mx,my,mz,qw,qx,qy,qz,movement.
//   DIR/truth.toml  what a test of a chain method may want besides: each sensor's mounting
//                   (q_segment_sensor), length, gyro bias, and each joint's centre seen from
//                   both sensors (r_parent_m, r_child_m, sensor frames).
//
// Sensor model (the conventions of scenario.hpp and stream_node.hpp): row k's gyro is the
// constant body rate that carries truth k−1 to truth k (ideal_reading), so integrating it
// reproduces the truth on noiseless data; the accelerometer is the specific force
// f = R(q)ᵀ (a + [0, 0, 9.81]) (the single-sensor scenarios' gravity) of the sensor's true
// linear acceleration a (the second
// derivative of its position); the magnetometer reads R(q)ᵀ B(p) of the environment at the
// sensor's position. Noise and a constant gyro bias per sensor are the `realistic` scenario's
// MEMS figures (stream_node_noise), scaled by noise_scale (0: ideal sensors, no bias).
//
// Thread-safety: plain values and pure functions. Cost: linear in rows × sensors.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/imu_sample.hpp"
#include "math/quaternion.hpp"
#include "sim/magnetic_env.hpp"

namespace mocap::sim {

using math::Quat;
using math::Vec3;

/// One sample of one sensor and the truth behind it.
struct ChainRow {
    ImuSample sample;                ///< what the sensor reports (t_us, gyro, accel, mag)
    Quat q_earth_sensor;             ///< true orientation, ENU
    bool moving = false;             ///< the sensor moved over (t_{k-1}, t_k] (movement column)
    Vec3 gyro_true_rad_s;            ///< true body rate over (t_{k-1}, t_k], no bias, no noise
    Vec3 lin_acc_earth_m_s2;         ///< true linear acceleration at t_k, earth frame
    Vec3 mag_earth_ut;               ///< true field at the sensor, earth frame
    Vec3 position_m = Vec3::Zero();  ///< the sensor's position, ENU
};

struct ChainSensor {
    std::string name;                          ///< segment name: seg1, seg2, ...
    double length_m = 0.0;                     ///< segment length (proximal to distal joint)
    Quat q_segment_sensor = Quat::Identity();  ///< mounting; segment x runs along the segment
    Vec3 gyro_bias_rad_s = Vec3::Zero();       ///< constant bias in every gyro reading
    std::vector<ChainRow> rows;
};

struct ChainJoint {
    std::string parent;
    std::string child;
    std::string type;                  ///< "hinge" | "2dof" | "ball"
    Vec3 axis_parent = Vec3::UnitZ();  ///< unit, parent's sensor frame
    Vec3 axis_child = Vec3::UnitZ();   ///< unit, child's sensor frame
    Vec3 r_parent_m = Vec3::Zero();    ///< joint centre from the parent's sensor, its frame
    Vec3 r_child_m = Vec3::Zero();     ///< joint centre from the child's sensor, its frame
    double axis_wander_deg = 0.0;      ///< a near-hinge's largest axis excursion from its mean
    std::string note;                  ///< a truth.toml comment (e.g. how a hinge is not exact)
};

struct ChainRecording {
    std::string scenario;  ///< "chain" | "pendulum"
    std::uint64_t seed = 0;
    double rate_hz = 0.0;
    double duration_s = 0.0;
    std::string magnetic_env;
    std::vector<ChainSensor> sensors;
    std::vector<ChainJoint> joints;
};

/// The truth of one sensor at the sample instants k = 0..n−1 and the instant before the
/// first (for row 0's gyro).
struct SensorTrack {
    Quat q_before = Quat::Identity();
    std::vector<Quat> q_earth_sensor;
    std::vector<Vec3> position_m;
    std::vector<Vec3> lin_acc_earth_m_s2;
};

/// Fills sensor.rows (and its gyro bias) from the track: readings at rate_hz in the field of
/// env, noise and bias drawn from (seed, stream) and scaled by noise_scale.
void sense_track(const SensorTrack& track, double rate_hz, const MagneticEnv& env, double noise_scale,
                 std::uint64_t seed, std::uint64_t stream, ChainSensor& sensor);

/// Writes toml_path, one CSV per sensor and truth.toml next to it (reference quaternions in
/// NED with ned). The folder must exist. false with *error on a failed write.
bool write_chain_files(const ChainRecording& recording, const std::filesystem::path& toml_path, bool ned,
                       std::string* error);

/// A uniformly distributed rotation (the sensors' mountings).
Quat random_rotation(std::uint64_t seed, std::uint64_t stream);

}  // namespace mocap::sim
