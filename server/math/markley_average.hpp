// markley_average.hpp — quaternion averaging (Markley, Cheng, Crassidis, Oshman,
// "Averaging Quaternions", J. Guidance 2007).
//
// The weighted average of attitudes q_i is the unit eigenvector of the 4x4 symmetric matrix
// M for its largest eigenvalue; it is invariant to the sign of every q_i (q and -q are the
// same rotation), unlike a normalised sum.
//   scalar weights: M = Σ w_i q_i q_iᵀ                                  (paper eq. 12)
//   matrix weights: M = -Σ Ξ(q_i) R_i⁻¹ Ξ(q_i)ᵀ                        (eq. 26-32)
// The paper writes quaternions as (vector, scalar); this code uses (w, x, y, z), so
//   Ξ(q) = [ -q_vecᵀ ; q_w I₃ + [q_vec]ₓ ]   (4x3),  Ξ(q)ᵀ p = vec(q* ⊗ p) (Hamilton),
// and R_i is the covariance (rad²) of the small rotation δθ with q_true = q_i ⊗ exp(δθ/2),
// i.e. an error in the SENSOR frame (Markley's body-frame error). With R_i⁻¹ = w_i I the
// matrix-weight M equals the scalar-weight M minus (Σ w_i) I: same eigenvectors.
//
// Cost: the accumulator adds 10 multiply-adds per quaternion; mean() runs a few power
// iterations on the 4x4 (falls back to Eigen's SelfAdjointEigenSolver when they do not
// converge). Nothing allocates. All functions are pure; QuatAccumulator is a plain value
// (not thread-safe to share while writing).
#pragma once

#include <Eigen/Core>
#include <span>

#include "math/quaternion.hpp"

namespace mocap::math {

using Mat4 = Eigen::Matrix4d;
using Mat43 = Eigen::Matrix<double, 4, 3>;

/// Ξ(q) in (w, x, y, z) ordering (see the file comment).
Mat43 xi_matrix(const Quat& q);

/// Unit eigenvector of the largest eigenvalue of a symmetric 4x4 M, as a quaternion with
/// w >= 0, and that eigenvalue (Eigen's SelfAdjointEigenSolver; ~1 µs).
struct MaxEigen {
    Quat q = Quat::Identity();
    double eigenvalue = 0.0;
};
MaxEigen max_eigenvector(const Mat4& m);

/// Same result by power iteration seeded with `hint` (the previous estimate makes it
/// converge in 2-4 steps for a concentrated cloud). `psd` says M is positive semidefinite
/// (scalar weights); otherwise M is shifted by a Gershgorin bound first. The result is
/// accepted only when 2λ > trace(M), which proves λ is the largest eigenvalue of a PSD
/// matrix (every other eigenvalue is <= trace − λ < λ); otherwise, or when the iteration
/// does not converge, it falls back to max_eigenvector(m).
MaxEigen max_eigenvector_power(const Mat4& m, const Quat& hint, bool psd);

/// Incremental M for weighted averaging of many quaternions without allocation (the
/// particle filter adds up to thousands per update).
class QuatAccumulator {
public:
    void reset() {
        m_.setZero();
        weight_sum_ = 0.0;
        psd_ = true;
    }
    /// Scalar weight w >= 0 (q need not be canonical; its sign does not matter).
    void add(const Quat& q, double w) {
        const Vec4 v = to_wxyz(q);
        m_.noalias() += (w * v) * v.transpose();
        weight_sum_ += w;
    }
    /// Same as add(q, w) from raw components, for structure-of-arrays callers.
    void add(double qw, double qx, double qy, double qz, double w) {
        const Vec4 v(qw, qx, qy, qz);
        m_.noalias() += (w * v) * v.transpose();
        weight_sum_ += w;
    }
    /// Adds n quaternions stored as structure of arrays (w, x, y, z components and scalar
    /// weights): the 10 distinct sums of M in one vectorisable pass (~1 ns per quaternion).
    void add(const double* qw, const double* qx, const double* qy, const double* qz, const double* w, int n);
    /// Matrix weight: info = R⁻¹ (rad⁻², sensor frame, symmetric positive semidefinite).
    void add(const Quat& q, const Mat3& info) {
        const Mat43 xi = xi_matrix(q);
        m_.noalias() -= xi * info * xi.transpose();
        weight_sum_ += info.trace() / 3.0;
        psd_ = false;
    }

    [[nodiscard]] const Mat4& matrix() const { return m_; }
    [[nodiscard]] double weight_sum() const { return weight_sum_; }
    /// The average (w >= 0). Undefined content if nothing was added (returns `hint`).
    [[nodiscard]] Quat mean(const Quat& hint = Quat::Identity()) const;

private:
    Mat4 m_ = Mat4::Zero();
    double weight_sum_ = 0.0;
    bool psd_ = true;  // only scalar weights added: M is positive semidefinite
};

/// Weighted average with scalar weights w_i >= 0 (eq. 12). Sizes must match; returns
/// identity for an empty or all-zero input.
Quat average_quaternions(std::span<const Quat> qs, std::span<const double> weights);
/// Unweighted average.
Quat average_quaternions(std::span<const Quat> qs);

/// Weighted average with matrix weights info_i = R_i⁻¹ (eq. 26-32, sensor-frame errors).
Quat average_quaternions(std::span<const Quat> qs, std::span<const Mat3> info);

/// Closed form for two quaternions with scalar weights (eq. 19):
///   z = √((w1 − w2)² + 4 w1 w2 (q1ᵀq2)²)
///   q̄ = √(w1 (w1 − w2 + z) / (z (w1 + w2 + z))) q1
///      + sign(q1ᵀq2) √(w2 (w2 − w1 + z) / (z (w1 + w2 + z))) q2.
/// Returns w >= 0, always a unit quaternion:
///  * equal weights and orthogonal q1, q2 (rotations 180° apart; z = 0): the largest
///    eigenvalue is double and any unit combination of q1 and q2 is an average; the result is
///    (q1 + q2)/√2, the limit of the formula as q1ᵀq2 -> 0⁺ (the arc's midpoint, 90° from each);
///  * a negative or NaN weight counts as 0, an infinite one outweighs every finite one (two
///    infinite ones are equal); both 0 gives identity, as average_quaternions does.
Quat average_two(const Quat& q1, double w1, const Quat& q2, double w2);

/// Covariance (rad², sensor frame) of the averaged attitude's error δθ
/// (q_true = q̄ ⊗ exp(δθ/2)) when the inputs carry independent errors with R_i = info_i⁻¹
/// (eq. 38): P = [λ_max I₃ − Ξ(q̄)ᵀ M Ξ(q̄)]⁻¹ with M the matrix-weight M, λ_max its largest
/// eigenvalue and q̄ its eigenvector (the Fisher information of the cost at q̄).
Mat3 average_covariance(std::span<const Quat> qs, std::span<const Mat3> info);
/// Small-spread approximation (eq. 39): P ≈ (Σ R_i⁻¹)⁻¹.
Mat3 average_covariance_approx(std::span<const Mat3> info);

}  // namespace mocap::math
