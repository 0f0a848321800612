#include "math/markley_average.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cassert>
#include <cmath>

namespace mocap::math {

Mat43 xi_matrix(const Quat& q) {
    Mat43 xi;
    xi.row(0) = -q.vec().transpose();
    xi.bottomRows<3>() = q.w() * Mat3::Identity() + skew(q.vec());
    return xi;
}

namespace {

Quat canonical_from(const Vec4& v) {
    return canonical(from_wxyz(v.normalized()));
}

}  // namespace

MaxEigen max_eigenvector(const Mat4& m) {
    // 4x4 symmetric: the closed-form-free solver is exact to rounding and never fails.
    const Eigen::SelfAdjointEigenSolver<Mat4> es(m);
    // Eigenvalues come sorted ascending.
    return {canonical_from(es.eigenvectors().col(3)), es.eigenvalues()[3]};
}

MaxEigen max_eigenvector_power(const Mat4& m, const Quat& hint, bool psd) {
    Mat4 shifted = m;
    double shift = 0.0;
    if (!psd) {
        // Gershgorin: every eigenvalue >= min_i (m_ii − Σ_j≠i |m_ij|).
        double lo = 0.0;
        for (int i = 0; i < 4; ++i) {
            const double off = m.row(i).cwiseAbs().sum() - std::abs(m(i, i));
            lo = std::min(lo, m(i, i) - off);
        }
        shift = -lo;
        shifted.diagonal().array() += shift;
    }
    Vec4 x = to_wxyz(hint).normalized();
    // Make sure the start is not (nearly) orthogonal to the dominant subspace.
    Vec4 y = shifted * x;
    if (y.norm() < 1e-6 * shifted.norm()) {
        Eigen::Index j = 0;
        shifted.colwise().norm().maxCoeff(&j);
        y = shifted.col(j);
    }
    constexpr int kMaxIter = 32;
    for (int it = 0; it < kMaxIter; ++it) {
        const double n = y.norm();
        if (!(n > 0.0) || !std::isfinite(n)) break;
        const Vec4 xn = y / n;
        const bool done = (xn - x).squaredNorm() < 1e-24;
        x = xn;
        y = shifted * x;
        if (done) {
            const double lambda = x.dot(y);
            // Rayleigh quotient of an eigenvector of a PSD matrix: if it exceeds the sum of
            // the other three eigenvalues it is the largest (see the header).
            if (2.0 * lambda > shifted.trace()) return {canonical_from(x), lambda - shift};
            break;
        }
    }
    return max_eigenvector(m);
}

void QuatAccumulator::add(const double* qw, const double* qx, const double* qy, const double* qz, const double* w,
                          int n) {
    double ww = 0, wx = 0, wy = 0, wz = 0, xx = 0, xy = 0, xz = 0, yy = 0, yz = 0, zz = 0, s = 0;
    for (int i = 0; i < n; ++i) {
        const double a = w[i] * qw[i], b = w[i] * qx[i], c = w[i] * qy[i], d = w[i] * qz[i];
        ww += a * qw[i];
        wx += a * qx[i];
        wy += a * qy[i];
        wz += a * qz[i];
        xx += b * qx[i];
        xy += b * qy[i];
        xz += b * qz[i];
        yy += c * qy[i];
        yz += c * qz[i];
        zz += d * qz[i];
        s += w[i];
    }
    Mat4 m;
    m << ww, wx, wy, wz, wx, xx, xy, xz, wy, xy, yy, yz, wz, xz, yz, zz;
    m_ += m;
    weight_sum_ += s;
}

Quat QuatAccumulator::mean(const Quat& hint) const {
    if (weight_sum_ <= 0.0 && m_.isZero()) return hint;
    return max_eigenvector_power(m_, hint, psd_).q;
}

Quat average_quaternions(std::span<const Quat> qs, std::span<const double> weights) {
    assert(qs.size() == weights.size());
    QuatAccumulator acc;
    for (std::size_t i = 0; i < qs.size(); ++i)
        acc.add(qs[i], weights[i]);
    if (!(acc.weight_sum() > 0.0)) return Quat::Identity();
    return max_eigenvector(acc.matrix()).q;
}

Quat average_quaternions(std::span<const Quat> qs) {
    QuatAccumulator acc;
    for (const Quat& q : qs)
        acc.add(q, 1.0);
    if (qs.empty()) return Quat::Identity();
    return max_eigenvector(acc.matrix()).q;
}

Quat average_quaternions(std::span<const Quat> qs, std::span<const Mat3> info) {
    assert(qs.size() == info.size());
    QuatAccumulator acc;
    for (std::size_t i = 0; i < qs.size(); ++i)
        acc.add(qs[i], info[i]);
    if (qs.empty()) return Quat::Identity();
    return max_eigenvector(acc.matrix()).q;
}

Quat average_two(const Quat& q1, double w1, const Quat& q2, double w2) {
    // A negative or NaN weight counts as zero (NaN > 0 is false); dividing by the larger
    // weight keeps w1·w2 finite, and an infinite weight outweighs every finite one.
    w1 = w1 > 0.0 ? w1 : 0.0;
    w2 = w2 > 0.0 ? w2 : 0.0;
    const double scale = std::max(w1, w2);
    if (scale == 0.0) return Quat::Identity();
    if (std::isinf(scale)) {
        w1 = std::isinf(w1) ? 1.0 : 0.0;
        w2 = std::isinf(w2) ? 1.0 : 0.0;
    } else {
        w1 /= scale;
        w2 /= scale;
    }
    const double d = q1.coeffs().dot(q2.coeffs());
    const double s = d < 0.0 ? -1.0 : 1.0;
    const double z = std::sqrt((w1 - w2) * (w1 - w2) + 4.0 * w1 * w2 * d * d);
    if (z == 0.0) {
        // Equal weights, orthogonal inputs: the largest eigenvalue is double and every unit
        // combination of q1 and q2 is an average. The formula's limit as q1ᵀq2 -> 0 from
        // the side of s is (q1 + s q2)/√2, the midpoint of the arc between them.
        return canonical_from(to_wxyz(q1) + s * to_wxyz(q2));
    }
    const double den = z * (w1 + w2 + z);
    const double a = std::sqrt(std::max(0.0, w1 * (w1 - w2 + z) / den));
    const double b = std::sqrt(std::max(0.0, w2 * (w2 - w1 + z) / den));
    const Vec4 v = a * to_wxyz(q1) + s * b * to_wxyz(q2);
    return canonical_from(v);
}

Mat3 average_covariance(std::span<const Quat> qs, std::span<const Mat3> info) {
    assert(qs.size() == info.size());
    QuatAccumulator acc;
    for (std::size_t i = 0; i < qs.size(); ++i)
        acc.add(qs[i], info[i]);
    const MaxEigen me = max_eigenvector(acc.matrix());
    const Mat43 xi = xi_matrix(me.q);
    const Mat3 fisher = me.eigenvalue * Mat3::Identity() - xi.transpose() * acc.matrix() * xi;
    return fisher.inverse();
}

Mat3 average_covariance_approx(std::span<const Mat3> info) {
    Mat3 sum = Mat3::Zero();
    for (const Mat3& m : info)
        sum += m;
    return sum.inverse();
}

}  // namespace mocap::math
