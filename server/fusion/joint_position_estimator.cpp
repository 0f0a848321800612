#include "fusion/joint_position_estimator.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>

namespace mocap::fusion {

using Mat6 = Eigen::Matrix<double, 6, 6>;
using Vec6 = Eigen::Matrix<double, 6, 1>;

Eigen::Matrix3d gamma_matrix(const Vec3& w, const Vec3& dw) {
    const Eigen::Matrix3d sw = math::skew(w);
    return math::skew(dw) + sw * sw;
}

JointPositionEstimator::JointPositionEstimator(const JointPositionParams& params)
    : params_(params), ring_(std::max<std::size_t>(params.capacity, 1)), interval_s_(params.solve_interval_s) {}

void JointPositionEstimator::reset() {
    next_ = count_ = 0;
    last_sample_us_ = last_solve_us_ = -1;
    ready_ = false;
    was_solved_ = false;
    interval_s_ = params_.solve_interval_s;
    r_p_ = r_c_ = Vec3::Zero();
    relative_residual_ = 0.0;
}

bool JointPositionEstimator::add(std::int64_t t_us, const Vec3& w_p, const Vec3& dw_p, const Vec3& f_p, const Vec3& w_c,
                                 const Vec3& dw_c, const Vec3& f_c, bool may_solve) {
    const double gamma = std::max(w_p.squaredNorm() + dw_p.norm(), w_c.squaredNorm() + dw_c.norm());
    const auto spacing_us = static_cast<std::int64_t>(params_.sample_spacing_s * 1e6);
    const bool finite = w_p.allFinite() && dw_p.allFinite() && f_p.allFinite() && w_c.allFinite() && dw_c.allFinite() &&
                        f_c.allFinite();
    if (finite && gamma >= params_.min_gamma &&
        (last_sample_us_ < 0 || t_us - last_sample_us_ >= spacing_us || t_us < last_sample_us_)) {
        ring_[next_] = {gamma_matrix(w_p, dw_p), gamma_matrix(w_c, dw_c), f_p, f_c};
        next_ = (next_ + 1) % ring_.size();
        count_ = std::min(count_ + 1, ring_.size());
        last_sample_us_ = t_us;
    }
    if (count_ < params_.min_samples || !may_solve) return false;
    const auto interval_us = static_cast<std::int64_t>(interval_s_ * 1e6);
    if (last_solve_us_ >= 0 && t_us - last_solve_us_ < interval_us && t_us >= last_solve_us_) return false;
    last_solve_us_ = t_us;
    const Vec3 rp = r_p_, rc = r_c_;
    const bool was_ready = ready_;
    if (!solve()) return false;
    // A centre that no longer moves (< 2 mm) is checked less and less often, up to
    // max_interval_s: it is a constant of the mounting.
    const bool still = was_ready && ready_ && (rp - r_p_).norm() < 0.002 && (rc - r_c_).norm() < 0.002;
    interval_s_ = still ? std::min(2.0 * interval_s_, params_.max_interval_s) : params_.solve_interval_s;
    return true;
}

double JointPositionEstimator::cost(const Vec3& r_parent, const Vec3& r_child) const {
    double c = 0.0;
    for (std::size_t k = 0; k < count_; ++k) {
        const Sample& s = ring_[k];
        const double e = (s.f_p + s.g_p * r_parent).norm() - (s.f_c + s.g_c * r_child).norm();
        c += e * e;
    }
    return c;
}

bool JointPositionEstimator::solve() {
    if (count_ < 7) return false;
    Vec6 x;
    x << r_p_, r_c_;
    const Vec6 prior = x;
    double f2 = 0.0;
    for (std::size_t k = 0; k < count_; ++k)
        f2 += 0.5 * (ring_[k].f_p.squaredNorm() + ring_[k].f_c.squaredNorm());
    // The ridge: a hundredth of an average sample's weight per unknown, towards the last
    // solution (a hinge leaves the position along its axis free).
    const double ridge = 1e-2 * f2 / static_cast<double>(count_);
    const auto cost_of = [&](const Vec6& v, Mat6* jtj, Vec6* jte) {
        double cost = 0.0;
        if (jtj) jtj->setZero();
        if (jte) jte->setZero();
        for (std::size_t k = 0; k < count_; ++k) {
            const Sample& s = ring_[k];
            const Vec3 jp = s.f_p + s.g_p * v.head<3>(), jc = s.f_c + s.g_c * v.tail<3>();
            const double np = jp.norm(), nc = jc.norm();
            const double e = np - nc;
            cost += e * e;
            if (!jtj || np < 1e-9 || nc < 1e-9) continue;
            Vec6 row;
            row << s.g_p.transpose() * (jp / np), -(s.g_c.transpose() * (jc / nc));
            *jtj += row * row.transpose();
            *jte += row * e;
        }
        cost += ridge * (v - prior).squaredNorm();
        if (jtj) {
            jtj->diagonal().array() += ridge;
            *jte += ridge * (v - prior);
        }
        return cost;
    };
    Mat6 jtj;
    Vec6 jte;
    double cost = cost_of(x, &jtj, &jte);
    double lambda = 1e-3 * jtj.trace() / 6.0 + 1e-12;
    // From scratch 15 iterations; from a previous solution (the usual case: the centre is a
    // constant) 3 are enough and keep a solve under a millisecond.
    const int iterations = was_solved_ ? 4 : 15;
    was_solved_ = true;
    for (int it = 0; it < iterations; ++it) {
        Mat6 a = jtj;
        a.diagonal().array() += lambda;
        const Vec6 step = a.ldlt().solve(-jte);
        const Vec6 nx = x + step;
        const double nc = cost_of(nx, nullptr, nullptr);
        if (nc < cost) {
            x = nx;
            cost = cost_of(x, &jtj, &jte);
            lambda = std::max(lambda / 3.0, 1e-12);
            if (step.norm() < 1e-6) break;
        } else {
            lambda *= 4.0;
        }
    }
    r_p_ = x.head<3>();
    r_c_ = x.tail<3>();
    // Identifiability: the data's normal matrix without the ridge; a direction it barely
    // sees (a segment that turns about one axis only) leaves the centre to the ridge.
    jtj.diagonal().array() -= ridge;
    const Eigen::SelfAdjointEigenSolver<Mat6> eig(jtj);
    const double hi = eig.eigenvalues().maxCoeff();
    // Eigen sorts them ascending; a hinge's centre may slide along its axis (one free direction).
    const double lowest = eig.eigenvalues()[static_cast<Eigen::Index>(params_.free_directions)];
    const double conditioning = hi > 0.0 ? lowest / hi : 0.0;
    relative_residual_ = std::sqrt(std::max(cost - ridge * (x - prior).squaredNorm(), 0.0) / std::max(f2, 1e-12));
    ready_ = relative_residual_ <= params_.max_residual && conditioning >= params_.min_conditioning &&
             r_p_.norm() <= params_.max_distance_m && r_c_.norm() <= params_.max_distance_m;
    return true;
}

}  // namespace mocap::fusion
