// joint_constraints.hpp — what one sample of two adjacent segments says about their relative
// heading δ (docs/fusion.md, "Constraints"), for the heading filter (heading_filter.hpp).
//
// Frames: the parent's 6D earth frame P and the child's C differ by a rotation about the
// vertical, q_P = Rz(δ) ⊗ q_C; a vector x_C in C is Rz(δ) x_C in P. Every constraint of a joint
// is an equation in δ built from quantities each sensor measures in its own frame:
//
//   vector pair   two vectors that are the same physical vector, a in P and b in C:
//                 a = Rz(δ) b. A hinge has two: its axis (a = R_P j_p, b = R_C j_c) and the
//                 part of the angular velocity perpendicular to the axis, which the two
//                 segments share (a = (I − âaᵀ) ω_P, b = (I − b̂b̂ᵀ) ω_C). δ follows from the
//                 horizontal parts of a and b alone (the angle from b_h to a_h), so a pair
//                 says nothing when either is nearly vertical.
//   scalar        g(δ) = 0 with g = C cos δ + S sin δ + K. A 2-DoF joint (axis j1 fixed in the
//                 parent, j2 in the child) keeps the angle between its axes:
//                 (R_P j1)ᵀ Rz(δ) (R_C j2) = cos α, and its relative angular velocity has no
//                 part along the common normal n = a × Rz(δ) b: (Rz(δ) ω_C − ω_P) · n = 0.
//                 Linearised at the current estimate, it is a measurement of δ whose variance
//                 grows as the slope g'(δ) vanishes.
//
// Each returns a residual (the measurement minus the current estimate) and its variance for
// one sample; the caller applies the correlation scaling and the filter update. Pure
// functions, no allocation, a few dozen flops each.
#pragma once

#include "math/quaternion.hpp"

namespace mocap::fusion {

using math::Quat;
using math::Vec3;

/// One measurement of δ relative to the current estimate.
struct HeadingMeasurement {
    bool ok = false;          ///< false: the sample says nothing (vectors vertical, slope zero)
    double residual_rad = 0;  ///< measured δ minus the estimate, wrapped
    double var_rad2 = 0;      ///< variance of the measured δ (one sample, uncorrelated)
};

/// The coefficients of xᵀ Rz(δ) y = c cos δ + s sin δ + k.
struct TrigLinear {
    double c = 0, s = 0, k = 0;
    [[nodiscard]] double value(double delta_rad) const;
    [[nodiscard]] double slope(double delta_rad) const;
};
TrigLinear dot_rz(const Vec3& x, const Vec3& y);

/// A cost over δ that is a sum of squared TrigLinear residuals: a trigonometric polynomial
/// of order two, J(δ) = a0 + a1 cos δ + b1 sin δ + a2 cos 2δ + b2 sin 2δ, so any number of
/// samples sums into five numbers. For constraints whose single sample has more than one root
/// (2dof): the sum over a window of motion has one clear minimum once the motion is rich
/// enough, which starts the heading filter without a magnetometer.
struct TrigQuad {
    double a0 = 0, a1 = 0, b1 = 0, a2 = 0, b2 = 0;
    /// Adds w · g(δ)².
    void add(const TrigLinear& g, double w);
    /// Multiplies every coefficient (exponential forgetting).
    void scale(double f);
    /// Moves the cost along δ by s: J_new(δ) = J(δ − s) (the frames drifted by s).
    void shift(double s_rad);
    [[nodiscard]] double value(double delta_rad) const;

    struct Minimum {
        double delta_rad = 0;  ///< where J is smallest
        double value = 0;      ///< J there
        double curvature = 0;  ///< J'' there
        double runner_up = 0;  ///< smallest J at least 45° away
    };
    /// Grid of 5° refined by Newton steps.
    [[nodiscard]] Minimum minimum() const;
};

/// Rz(δ) v: v turned about the vertical.
Vec3 rotate_z(double delta_rad, const Vec3& v);

/// Vector pair: a (parent frame) and b (child frame) with a = Rz(δ) b. sigma: the noise of
/// each vector, in their units; min_horizontal: the shortest horizontal part that counts.
HeadingMeasurement pair_measurement(const Vec3& a, const Vec3& b, double delta_rad, double sigma,
                                    double min_horizontal);

/// A hinge's axes learned from the motion carry a sign the motion may not yet show
/// (hinge_axis_estimator.hpp): with the child's axis flipped the axis pair says δ + 180°. A δ
/// already known can tell: true when a (the parent's axis in P) and b (the child's in C) put δ
/// more than a right angle from delta_rad, both horizontal parts at least min_horizontal long.
bool pair_contradicts(const Vec3& a, const Vec3& b, double delta_rad, double min_horizontal);

/// Scalar constraint g(δ) = 0 with noise sigma_g (in g's units), linearised at delta_rad.
/// min_slope: the smallest |g'| that counts (below it the sample is not informative).
HeadingMeasurement scalar_measurement(const TrigLinear& g, double delta_rad, double sigma_g, double min_slope);

/// The 2-DoF joint's axis-angle constraint: (R_P j1)ᵀ Rz(δ) (R_C j2) − cos α.
TrigLinear two_dof_axis_constraint(const Vec3& a_parent, const Vec3& b_child, double cos_alpha);
/// The 2-DoF joint's angular velocity constraint: (Rz(δ) v − u) · (a × Rz(δ) b) with u, v the
/// rates and a, b the axes in the parent's and the child's frames.
TrigLinear two_dof_rate_constraint(const Vec3& a_parent, const Vec3& b_child, const Vec3& u_parent,
                                   const Vec3& v_child);

}  // namespace mocap::fusion
