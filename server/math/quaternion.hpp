// quaternion.hpp — quaternion utilities shared by every filter and the skeleton.
//
// Convention (docs/design.md, "Quaternions and frames"): quaternions are (w, x, y, z), Hamilton product, unit norm.
// `q_a_b` rotates a vector from frame b into frame a: v_a = q_a_b ⊗ v_b ⊗ q_a_b*.
// Eigen::Quaterniond already implements the Hamilton product and stores (x, y, z, w)
// internally; construct it as Quat(w, x, y, z). All functions are pure and cheap
// (no allocation); thread-safe.
#pragma once

#include <Eigen/Geometry>

#include "core/imu_sample.hpp"

namespace mocap::math {

using Quat = Eigen::Quaterniond;
using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Vec4 = Eigen::Vector4d;

inline Vec3 to_vec3(const Vec3d& v) {
    return {v[0], v[1], v[2]};
}
inline Vec3d to_array(const Vec3& v) {
    return {v.x(), v.y(), v.z()};
}

/// (w, x, y, z) as a 4-vector; the layout used by Markley averaging.
inline Vec4 to_wxyz(const Quat& q) {
    return {q.w(), q.x(), q.y(), q.z()};
}
inline Quat from_wxyz(const Vec4& v) {
    return Quat(v[0], v[1], v[2], v[3]);
}

/// Hamilton product a ⊗ b.
inline Quat mul(const Quat& a, const Quat& b) {
    return a * b;
}
/// Conjugate (the inverse for a unit quaternion).
inline Quat conj(const Quat& q) {
    return q.conjugate();
}
/// Rotates v by q: q ⊗ [0, v] ⊗ q*.
inline Vec3 rotate(const Quat& q, const Vec3& v) {
    return q._transformVector(v);
}

/// The representative with w >= 0 (q and -q are the same rotation).
Quat canonical(const Quat& q);

/// Quaternion exponential of a pure quaternion [0, v]: (cos|v|, sin|v| v/|v|).
Quat quat_exp(const Vec3& v);
/// Quaternion logarithm of a unit quaternion: the v with quat_exp(v) = q, |v| in [0, π]
/// (|v| <= π/2 when w >= 0; canonicalise first for the shortest rotation).
Vec3 quat_log(const Quat& q);

/// Rotation vector (axis·angle, rad) -> quaternion: exp(v/2).
Quat quat_from_rotvec(const Vec3& rotvec_rad);
/// Quaternion -> rotation vector of the shortest rotation (angle in [0, π]).
Vec3 rotvec_from_quat(const Quat& q);

/// Spherical linear interpolation along the shortest arc; t in [0, 1].
Quat slerp(const Quat& q0, const Quat& q1, double t);

/// Rotation matrix R with v_a = R v_b for q_a_b, and back (Shepperd's method).
Mat3 to_rotation_matrix(const Quat& q);
Quat from_rotation_matrix(const Mat3& r);

/// ZYX (yaw-pitch-roll, aerospace) Euler angles: q = Rz(yaw) Ry(pitch) Rx(roll).
struct EulerZyx {
    double roll_rad = 0.0;
    double pitch_rad = 0.0;
    double yaw_rad = 0.0;
};
EulerZyx to_euler_zyx(const Quat& q);
Quat from_euler_zyx(const EulerZyx& e);

/// Smallest angle of the rotation q, rad in [0, π].
double angle_rad(const Quat& q);

/// Error metrics of the BROAD benchmark (docs/design.md, "Error metrics") for q_err = q_est ⊗ conj(q_ref),
/// where the earth z axis is vertical (ENU or NED).
double error_total_rad(const Quat& q_err);        ///< 2·acos(|w|)
double error_heading_rad(const Quat& q_err);      ///< 2·atan(|z/w|)
double error_inclination_rad(const Quat& q_err);  ///< 2·acos(√(w²+z²))

/// Wraps an angle to (-π, π].
double wrap_pi(double a_rad);

/// q_enu_ned: rotates NED vectors into ENU (x_e = y_n, y_e = x_n, z_e = -z_n). It is its
/// own inverse, so q_ned_sensor = q_enu_ned ⊗ q_enu_sensor as well.
Quat q_enu_ned();

/// Skew-symmetric matrix [v]x with [v]x w = v × w.
Mat3 skew(const Vec3& v);

}  // namespace mocap::math
