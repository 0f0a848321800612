// attitude_solver.hpp — attitude q_earth_sensor from one accelerometer + magnetometer pair.
//
// Two solvers of the same problem (find q with q ⊗ f_s ⊗ q* = up and q ⊗ h_s ⊗ q* = h_ref):
//  - solve_lma: Levenberg–Marquardt, Fourati et al. (CSMO paper) steps 1–7, with the errata
//    of docs/design.md, "Errata: LMA": the Jacobian is the 6x3 stack J = −2 [[ĥᴺ]ₓ ; [f̂ᴺ]ₓ]
//    and the correction is applied on the earth side, q ← [1, Δ] ⊗ q. Both directions weigh the
//    same, so magnetometer noise also tilts the result (as in the paper). Warm-started from a
//    previous estimate it converges in 1–3 iterations.
//  - solve_triad: closed form (TRIAD, accelerometer primary): tilt exactly from the
//    accelerometer, heading from the field's horizontal direction. Used to initialise.
//
// Frame: ENU earth (x east, y north, z up). The accelerometer gives specific force, so a
// sensor at rest measures "up" (a level sensor reads +g on its up axis). The field points
// north and, for dip > 0, downwards: h_ref = (0, cos dip, −sin dip).
// Inputs are only used as directions (any units: m/s², µT or G).
// Degenerate inputs (zero, non-finite or nearly parallel vectors) return a status, never NaN.
// Cost: LMA ~30 ns per iteration; TRIAD ~50 ns. Pure functions, thread-safe, no allocation.
#pragma once

#include <string_view>

#include "math/quaternion.hpp"

namespace mocap::filter {

/// Unit field direction in ENU for an inclination (dip) below the horizon, rad.
math::Vec3 field_direction_enu(double dip_rad);

/// The reference for a pair measured at its own dip, (0, cos dip, −sin dip) with
/// sin dip = −â·m̂, without trigonometric calls. Returns false if either vector is zero or
/// the pair is parallel (no horizontal component).
bool own_dip_field_direction(const math::Vec3& accel, const math::Vec3& mag, math::Vec3& h_ref_enu);

/// Dip of a measured accel/mag pair (angle of the field below the plane normal to the
/// specific force), rad; NaN if either vector is zero.
double measured_dip_rad(const math::Vec3& accel, const math::Vec3& mag);

enum class AttitudeStatus {
    ok,
    zero_accel,        ///< accelerometer norm below min_norm (free fall, missing data)
    zero_mag,          ///< magnetometer norm below min_norm
    parallel_vectors,  ///< accel and mag (or up and the reference field) nearly parallel
    not_finite,        ///< NaN or Inf in the input
};
std::string_view to_string(AttitudeStatus s);

struct AttitudeSolution {
    math::Quat q_earth_sensor = math::Quat::Identity();  ///< valid only if ok(); w >= 0
    AttitudeStatus status = AttitudeStatus::ok;
    int iterations = 0;     ///< LMA iterations used (0 for TRIAD)
    double residual = 0.0;  ///< |ε| of the stacked unit-vector residual at the result
    [[nodiscard]] bool ok() const { return status == AttitudeStatus::ok; }
};

struct LmaParams {
    double lambda = 0.01;          ///< key "lm_lambda": LM damping added to JᵀJ (dimensionless)
    double alpha = 1.0;            ///< key "lm_alpha": step scale (1 = full Gauss–Newton step)
    int max_iterations = 10;       ///< key "lm_iterations": upper bound per solve
    double tolerance_rad = 1e-10;  ///< key "lm_tol": stop when the correction |Δ| is below
    double min_norm = 1e-9;        ///< key "min_norm": smaller vectors count as zero (input units)
    double min_angle_rad = 0.035;  ///< key "min_angle": accel/mag closer than this (2°) are degenerate
};

/// Levenberg–Marquardt from `q_start` (identity, the previous estimate, or solve_triad's
/// result). h_ref_enu must be a unit vector not parallel to up.
AttitudeSolution solve_lma(const math::Vec3& accel, const math::Vec3& mag, const math::Vec3& h_ref_enu,
                           const math::Quat& q_start, const LmaParams& p = {});

/// TRIAD closed form. Only the horizontal direction of h_ref_enu matters.
AttitudeSolution solve_triad(const math::Vec3& accel, const math::Vec3& mag, const math::Vec3& h_ref_enu,
                             const LmaParams& p = {});

}  // namespace mocap::filter
