#include "filter/attitude_solver.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>

namespace mocap::filter {

Vec3 field_direction_enu(double dip_rad) { return {0.0, std::cos(dip_rad), -std::sin(dip_rad)}; }

double measured_dip_rad(const Vec3& accel, const Vec3& mag) {
    const double na = accel.norm(), nm = mag.norm();
    if (!(na > 0.0) || !(nm > 0.0)) return std::numeric_limits<double>::quiet_NaN();
    return std::asin(std::clamp(-accel.dot(mag) / (na * nm), -1.0, 1.0));
}

std::string_view to_string(AttitudeStatus s) {
    switch (s) {
        case AttitudeStatus::ok: return "ok";
        case AttitudeStatus::zero_accel: return "zero_accel";
        case AttitudeStatus::zero_mag: return "zero_mag";
        case AttitudeStatus::parallel_vectors: return "parallel_vectors";
        case AttitudeStatus::not_finite: return "not_finite";
    }
    return "unknown";
}

namespace {

// Validates and normalises the pair; a non-ok status leaves the outputs unspecified.
AttitudeStatus unit_pair(const Vec3& accel, const Vec3& mag, const Vec3& h_ref,
                         const LmaParams& p, Vec3& f_s, Vec3& h_s) {
    if (!accel.allFinite() || !mag.allFinite() || !h_ref.allFinite())
        return AttitudeStatus::not_finite;
    const double na = accel.norm(), nm = mag.norm();
    if (na < p.min_norm) return AttitudeStatus::zero_accel;
    if (nm < p.min_norm) return AttitudeStatus::zero_mag;
    f_s = accel / na;
    h_s = mag / nm;
    const double s_min = std::sin(p.min_angle_rad);
    if (f_s.cross(h_s).norm() < s_min) return AttitudeStatus::parallel_vectors;
    if (Vec3::UnitZ().cross(h_ref).norm() < s_min * h_ref.norm())
        return AttitudeStatus::parallel_vectors;
    return AttitudeStatus::ok;
}

}  // namespace

AttitudeSolution solve_lma(const Vec3& accel, const Vec3& mag, const Vec3& h_ref_enu,
                           const Quat& q_start, const LmaParams& p) {
    AttitudeSolution r;
    Vec3 f_s, h_s;
    r.status = unit_pair(accel, mag, h_ref_enu, p, f_s, h_s);
    if (!r.ok()) return r;
    const Vec3 f_n = Vec3::UnitZ();
    const Vec3 h_n = h_ref_enu.normalized();
    Quat q = q_start.normalized();
    if (!q.coeffs().allFinite()) q = Quat::Identity();
    for (r.iterations = 0; r.iterations < p.max_iterations;) {
        // Steps 2-3: measured directions carried to the earth frame by the estimate.
        const Vec3 f_hat = rotate(q, f_s);
        const Vec3 h_hat = rotate(q, h_s);
        // Steps 4-6 with J = −2 [[ĥ]ₓ ; [f̂]ₓ] and ε = [h_n − ĥ ; f_n − f̂], written out:
        //   JᵀJ = 4 (2 I − ĥĥᵀ − f̂f̂ᵀ),   Jᵀε = 2 (ĥ × h_n + f̂ × f_n).
        const Mat3 jtj = 4.0 * (2.0 * Mat3::Identity() - h_hat * h_hat.transpose() -
                                f_hat * f_hat.transpose());
        const Vec3 jte = 2.0 * (h_hat.cross(h_n) + f_hat.cross(f_n));
        const Vec3 delta = p.alpha * (jtj + p.lambda * Mat3::Identity()).ldlt().solve(jte);
        // Step 7 (erratum): earth-side correction.
        q = (Quat(1.0, delta.x(), delta.y(), delta.z()) * q).normalized();
        ++r.iterations;
        if (delta.norm() < p.tolerance_rad) break;
    }
    const Vec3 e_h = h_n - rotate(q, h_s), e_f = f_n - rotate(q, f_s);
    r.residual = std::sqrt(e_h.squaredNorm() + e_f.squaredNorm());
    r.q_earth_sensor = canonical(q);
    return r;
}

AttitudeSolution solve_triad(const Vec3& accel, const Vec3& mag, const Vec3& h_ref_enu,
                             const LmaParams& p) {
    AttitudeSolution r;
    Vec3 f_s, h_s;
    r.status = unit_pair(accel, mag, h_ref_enu, p, f_s, h_s);
    if (!r.ok()) return r;
    Mat3 body, ref;
    const Vec3 up = Vec3::UnitZ();
    const Vec3 b2 = f_s.cross(h_s).normalized();
    const Vec3 r2 = up.cross(h_ref_enu).normalized();
    body << f_s, b2, f_s.cross(b2);
    ref << up, r2, up.cross(r2);
    // Both triads are orthonormal, so ref · bodyᵀ is a rotation mapping body onto ref.
    r.q_earth_sensor = from_rotation_matrix(ref * body.transpose());
    const Vec3 e_h = h_ref_enu.normalized() - rotate(r.q_earth_sensor, h_s);
    const Vec3 e_f = up - rotate(r.q_earth_sensor, f_s);
    r.residual = std::sqrt(e_h.squaredNorm() + e_f.squaredNorm());
    return r;
}

}  // namespace mocap::filter
