#include "math/quaternion.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace mocap::math {

Quat canonical(const Quat& q) {
    return q.w() < 0.0 ? Quat(-q.w(), -q.x(), -q.y(), -q.z()) : q;
}

Quat quat_exp(const Vec3& v) {
    const double n = v.norm();
    // Below ~1e-8 sin(n)/n == 1 to double precision; avoids 0/0.
    const double s = n < 1e-8 ? 1.0 - n * n / 6.0 : std::sin(n) / n;
    return Quat(std::cos(n), s * v.x(), s * v.y(), s * v.z());
}

Vec3 quat_log(const Quat& q) {
    const Vec3 v = q.vec();
    const double vn = v.norm();
    if (vn < 1e-12) return Vec3::Zero();
    // atan2 is accurate near both 0 and π, unlike acos(w).
    const double theta = std::atan2(vn, q.w());
    return v * (theta / vn);
}

Quat quat_from_rotvec(const Vec3& rotvec_rad) {
    return quat_exp(0.5 * rotvec_rad);
}

Vec3 rotvec_from_quat(const Quat& q) {
    return 2.0 * quat_log(canonical(q));
}

Quat slerp(const Quat& q0, const Quat& q1, double t) {
    Quat b = q1;
    double d = q0.dot(q1);
    if (d < 0.0) {  // shortest arc
        b.coeffs() = -b.coeffs();
        d = -d;
    }
    if (d > 0.9995) {  // nearly parallel: normalised lerp avoids dividing by sin(~0)
        Quat r;
        r.coeffs() = (1.0 - t) * q0.coeffs() + t * b.coeffs();
        return r.normalized();
    }
    const double theta = std::acos(std::clamp(d, -1.0, 1.0));
    const double s = std::sin(theta);
    Quat r;
    r.coeffs() = (std::sin((1.0 - t) * theta) / s) * q0.coeffs() + (std::sin(t * theta) / s) * b.coeffs();
    return r.normalized();
}

Mat3 to_rotation_matrix(const Quat& q) {
    return q.normalized().toRotationMatrix();
}

Quat from_rotation_matrix(const Mat3& r) {
    // Eigen uses Shepperd's method (largest-diagonal branch), numerically stable.
    return canonical(Quat(r).normalized());
}

EulerZyx to_euler_zyx(const Quat& qin) {
    const Quat q = qin.normalized();
    const double w = q.w(), x = q.x(), y = q.y(), z = q.z();
    EulerZyx e;
    e.roll_rad = std::atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y));
    e.pitch_rad = std::asin(std::clamp(2.0 * (w * y - z * x), -1.0, 1.0));
    e.yaw_rad = std::atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z));
    return e;
}

Quat from_euler_zyx(const EulerZyx& e) {
    const Quat qz(Eigen::AngleAxisd(e.yaw_rad, Vec3::UnitZ()));
    const Quat qy(Eigen::AngleAxisd(e.pitch_rad, Vec3::UnitY()));
    const Quat qx(Eigen::AngleAxisd(e.roll_rad, Vec3::UnitX()));
    return qz * qy * qx;
}

double angle_rad(const Quat& q) {
    return 2.0 * std::atan2(q.vec().norm(), std::abs(q.w()));
}

double error_total_rad(const Quat& q_err) {
    return 2.0 * std::acos(std::clamp(std::abs(q_err.w()) / q_err.norm(), 0.0, 1.0));
}

double error_heading_rad(const Quat& q_err) {
    // 2·atan(|z/w|) written with atan2 so w = 0 gives π, not a division by zero.
    return 2.0 * std::atan2(std::abs(q_err.z()), std::abs(q_err.w()));
}

double error_inclination_rad(const Quat& q_err) {
    const double n2 = q_err.squaredNorm();
    const double c = std::sqrt((q_err.w() * q_err.w() + q_err.z() * q_err.z()) / n2);
    return 2.0 * std::acos(std::clamp(c, 0.0, 1.0));
}

double wrap_pi(double a_rad) {
    // Most callers pass an angle already in range or one turn off: no fmod for those.
    if (a_rad > -std::numbers::pi && a_rad <= std::numbers::pi) return a_rad;
    constexpr double two_pi = 2.0 * std::numbers::pi;
    double r = std::fmod(a_rad + std::numbers::pi, two_pi);
    if (r <= 0.0) r += two_pi;
    return r - std::numbers::pi;
}

Quat q_enu_ned() {
    constexpr double h = std::numbers::sqrt2 / 2.0;
    return Quat(0.0, h, h, 0.0);
}

Mat3 skew(const Vec3& v) {
    Mat3 m;
    m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
    return m;
}

}  // namespace mocap::math
