#include "filter/attitude_solver.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace mocap::filter {

math::Vec3 field_direction_enu(double dip_rad) {
    return {0.0, std::cos(dip_rad), -std::sin(dip_rad)};
}

double measured_dip_rad(const math::Vec3& accel, const math::Vec3& mag) {
    const double na = accel.norm(), nm = mag.norm();
    if (!(na > 0.0) || !(nm > 0.0)) return std::numeric_limits<double>::quiet_NaN();
    return std::asin(std::clamp(-accel.dot(mag) / (na * nm), -1.0, 1.0));
}

bool own_dip_field_direction(const math::Vec3& accel, const math::Vec3& mag, math::Vec3& h_ref_enu) {
    const double nn = accel.squaredNorm() * mag.squaredNorm();
    if (!(nn > 0.0) || !std::isfinite(nn)) return false;
    const double sin_dip = -accel.dot(mag) / std::sqrt(nn);
    const double cos2 = 1.0 - sin_dip * sin_dip;
    if (!(cos2 > 0.0)) return false;
    h_ref_enu = math::Vec3(0.0, std::sqrt(cos2), -sin_dip);
    return true;
}

std::string_view to_string(AttitudeStatus s) {
    switch (s) {
        case AttitudeStatus::ok:
            return "ok";
        case AttitudeStatus::zero_accel:
            return "zero_accel";
        case AttitudeStatus::zero_mag:
            return "zero_mag";
        case AttitudeStatus::parallel_vectors:
            return "parallel_vectors";
        case AttitudeStatus::not_finite:
            return "not_finite";
    }
    return "unknown";
}

namespace {

// Validates and normalises the pair; a non-ok status leaves the outputs unspecified.
AttitudeStatus unit_pair(const math::Vec3& accel, const math::Vec3& mag, const math::Vec3& h_ref, const LmaParams& p,
                         math::Vec3& f_s, math::Vec3& h_s) {
    if (!accel.allFinite() || !mag.allFinite() || !h_ref.allFinite()) return AttitudeStatus::not_finite;
    const double na = accel.norm(), nm = mag.norm();
    if (na < p.min_norm) return AttitudeStatus::zero_accel;
    if (nm < p.min_norm) return AttitudeStatus::zero_mag;
    f_s = accel / na;
    h_s = mag / nm;
    const double s_min = std::sin(p.min_angle_rad);
    if (f_s.cross(h_s).norm() < s_min) return AttitudeStatus::parallel_vectors;
    if (math::Vec3::UnitZ().cross(h_ref).norm() < s_min * h_ref.norm()) return AttitudeStatus::parallel_vectors;
    return AttitudeStatus::ok;
}

// Solves A x = b for the symmetric positive definite 3x3 A = JᵀJ + λI by the adjugate:
// JᵀJ is positive semidefinite and λ > 0, so det(A) >= λ³ > 0. About 40 flops, against
// ~150 ns for a pivoting factorisation.
math::Vec3 solve_spd3(const math::Mat3& a, const math::Vec3& b) {
    const double c00 = a(1, 1) * a(2, 2) - a(1, 2) * a(1, 2);
    const double c01 = a(0, 2) * a(1, 2) - a(0, 1) * a(2, 2);
    const double c02 = a(0, 1) * a(1, 2) - a(0, 2) * a(1, 1);
    const double c11 = a(0, 0) * a(2, 2) - a(0, 2) * a(0, 2);
    const double c12 = a(0, 1) * a(0, 2) - a(0, 0) * a(1, 2);
    const double c22 = a(0, 0) * a(1, 1) - a(0, 1) * a(0, 1);
    const double inv_det = 1.0 / (a(0, 0) * c00 + a(0, 1) * c01 + a(0, 2) * c02);
    return inv_det * math::Vec3(c00 * b.x() + c01 * b.y() + c02 * b.z(), c01 * b.x() + c11 * b.y() + c12 * b.z(),
                                c02 * b.x() + c12 * b.y() + c22 * b.z());
}

}  // namespace

AttitudeSolution solve_lma(const math::Vec3& accel, const math::Vec3& mag, const math::Vec3& h_ref_enu,
                           const math::Quat& q_start, const LmaParams& p) {
    AttitudeSolution r;
    math::Vec3 f_s, h_s;
    r.status = unit_pair(accel, mag, h_ref_enu, p, f_s, h_s);
    if (!r.ok()) return r;
    const math::Vec3 f_n = math::Vec3::UnitZ();
    const math::Vec3 h_n = h_ref_enu.normalized();
    math::Quat q = q_start.normalized();
    if (!q.coeffs().allFinite()) q = math::Quat::Identity();
    for (r.iterations = 0; r.iterations < p.max_iterations;) {
        // Steps 2-3: measured directions carried to the earth frame by the estimate.
        const math::Vec3 f_hat = math::rotate(q, f_s);
        const math::Vec3 h_hat = math::rotate(q, h_s);
        // Steps 4-6 with J = −2 [[ĥ]ₓ ; [f̂]ₓ] and ε = [h_n − ĥ ; f_n − f̂], written out:
        //   JᵀJ = 4 (2 I − ĥĥᵀ − f̂f̂ᵀ),   Jᵀε = 2 (ĥ × h_n + f̂ × f_n).
        const math::Mat3 a =
            (8.0 + p.lambda) * math::Mat3::Identity() - 4.0 * (h_hat * h_hat.transpose() + f_hat * f_hat.transpose());
        const math::Vec3 jte = 2.0 * (h_hat.cross(h_n) + f_hat.cross(f_n));
        const math::Vec3 delta = p.alpha * solve_spd3(a, jte);
        // Step 7 (erratum): earth-side correction.
        q = (math::Quat(1.0, delta.x(), delta.y(), delta.z()) * q).normalized();
        ++r.iterations;
        if (delta.norm() < p.tolerance_rad) break;
    }
    const math::Vec3 e_h = h_n - math::rotate(q, h_s), e_f = f_n - math::rotate(q, f_s);
    r.residual = std::sqrt(e_h.squaredNorm() + e_f.squaredNorm());
    r.q_earth_sensor = math::canonical(q);
    return r;
}

AttitudeSolution solve_triad(const math::Vec3& accel, const math::Vec3& mag, const math::Vec3& h_ref_enu,
                             const LmaParams& p) {
    AttitudeSolution r;
    math::Vec3 f_s, h_s;
    r.status = unit_pair(accel, mag, h_ref_enu, p, f_s, h_s);
    if (!r.ok()) return r;
    math::Mat3 body, ref;
    const math::Vec3 up = math::Vec3::UnitZ();
    const math::Vec3 b2 = f_s.cross(h_s).normalized();
    const math::Vec3 r2 = up.cross(h_ref_enu).normalized();
    body << f_s, b2, f_s.cross(b2);
    ref << up, r2, up.cross(r2);
    // Both triads are orthonormal, so ref · bodyᵀ is a rotation mapping body onto ref.
    r.q_earth_sensor = math::from_rotation_matrix(ref * body.transpose());
    const math::Vec3 e_h = h_ref_enu.normalized() - math::rotate(r.q_earth_sensor, h_s);
    const math::Vec3 e_f = up - math::rotate(r.q_earth_sensor, f_s);
    r.residual = std::sqrt(e_h.squaredNorm() + e_f.squaredNorm());
    return r;
}

}  // namespace mocap::filter
