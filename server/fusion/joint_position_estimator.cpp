#include "fusion/joint_position_estimator.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>

namespace mocap::fusion {

Eigen::Matrix3d gamma_matrix(const Vec3& w, const Vec3& dw) {
    const Eigen::Matrix3d sw = math::skew(w);
    return math::skew(dw) + sw * sw;
}

JointPositionEstimator::JointPositionEstimator(const JointPositionParams& params)
    : params_(params), ring_(std::max<std::size_t>(params.capacity, 1)), interval_s_(params.solve_interval_s) {}

void JointPositionEstimator::reset() {
    gn_ = {};
    new_solution_ = false;
    reference_ = false;
    reference_cost_ = data_cost_ = 0.0;
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
    if (!may_solve) return false;
    if (gn_.phase == Phase::kIdle) {
        if (count_ < params_.min_samples) return false;
        const auto interval_us = static_cast<std::int64_t>(interval_s_ * 1e6);
        if (last_solve_us_ >= 0 && t_us - last_solve_us_ < interval_us && t_us >= last_solve_us_) return false;
        last_solve_us_ = t_us;
        if (!begin()) return false;
    }
    pass();
    return true;
}

bool JointPositionEstimator::take_solution() {
    const bool s = new_solution_;
    new_solution_ = false;
    return s;
}

void JointPositionEstimator::compare_with(const Vec3& r_parent, const Vec3& r_child) {
    reference_ = true;
    ref_p_ = r_parent;
    ref_c_ = r_child;
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

double JointPositionEstimator::evaluate(const Vec6& v, bool jacobian) {
    double cost = 0.0;
    if (jacobian) {
        gn_.jtj.setZero();
        gn_.jte.setZero();
        gn_.f2 = 0.0;
    }
    for (std::size_t k = 0; k < count_; ++k) {
        const Sample& s = ring_[k];
        const Vec3 jp = s.f_p + s.g_p * v.head<3>(), jc = s.f_c + s.g_c * v.tail<3>();
        const double np = jp.norm(), nc = jc.norm();
        const double e = np - nc;
        cost += e * e;
        if (!jacobian) continue;
        gn_.f2 += 0.5 * (s.f_p.squaredNorm() + s.f_c.squaredNorm());
        if (np < 1e-9 || nc < 1e-9) continue;
        Vec6 row;
        row << s.g_p.transpose() * (jp / np), -(s.g_c.transpose() * (jc / nc));
        gn_.jtj += row * row.transpose();
        gn_.jte += row * e;
    }
    if (jacobian) {
        // The ridge: a hundredth of an average sample's weight per unknown, towards the last
        // solution (a hinge leaves the position along its axis free).
        gn_.ridge = 1e-2 * gn_.f2 / static_cast<double>(std::max<std::size_t>(count_, 1));
        gn_.jtj.diagonal().array() += gn_.ridge;
        gn_.jte += gn_.ridge * (v - gn_.prior);
    }
    return cost + gn_.ridge * (v - gn_.prior).squaredNorm();
}

bool JointPositionEstimator::begin() {
    if (count_ < 7) return false;
    gn_.x << r_p_, r_c_;
    gn_.prior = gn_.x;
    gn_.lambda = -1.0;
    gn_.it = 0;
    // From scratch 15 iterations; from a previous solution (the usual case: the centre is a
    // constant) 4 are enough.
    gn_.iterations = was_solved_ ? 4 : 15;
    gn_.was_ready = ready_;
    gn_.finishing = false;
    was_solved_ = true;
    gn_.phase = Phase::kEvaluate;
    return true;
}

// One pass over the samples: the normal equations at x (evaluate), the cost of a trial step
// (trial), or the cost of the centre to compare with (reference).
void JointPositionEstimator::pass() {
    switch (gn_.phase) {
        case Phase::kIdle:
            return;
        case Phase::kEvaluate:
            gn_.cost = evaluate(gn_.x, true);
            if (gn_.lambda < 0.0) gn_.lambda = 1e-3 * gn_.jtj.trace() / 6.0 + 1e-12;
            if (gn_.finishing || gn_.it >= gn_.iterations) {
                finish();
                return;
            }
            next_step();
            return;
        case Phase::kTrial: {
            const Vec6 nx = gn_.x + gn_.step;
            const double nc = evaluate(nx, false);
            ++gn_.it;
            if (nc < gn_.cost) {
                gn_.x = nx;
                gn_.lambda = std::max(gn_.lambda / 3.0, 1e-12);
                gn_.finishing = gn_.step.norm() < 1e-6 || gn_.it >= gn_.iterations;
                gn_.phase = Phase::kEvaluate;  // the normal equations at the new x
            } else {
                gn_.lambda *= 4.0;
                if (gn_.it >= gn_.iterations) {
                    finish();
                } else {
                    next_step();
                }
            }
            return;
        }
        case Phase::kReference:
            reference_cost_ = cost(ref_p_, ref_c_);
            publish();
            return;
    }
}

void JointPositionEstimator::next_step() {
    Mat6 a = gn_.jtj;
    a.diagonal().array() += gn_.lambda;
    gn_.step = a.ldlt().solve(-gn_.jte);
    gn_.phase = Phase::kTrial;
}

void JointPositionEstimator::finish() {
    const Vec6& x = gn_.x;
    r_p_ = x.head<3>();
    r_c_ = x.tail<3>();
    // Identifiability: the data's normal matrix without the ridge; a direction it barely
    // sees (a segment that turns about one axis only) leaves the centre to the ridge.
    Mat6 jtj = gn_.jtj;
    jtj.diagonal().array() -= gn_.ridge;
    const Eigen::SelfAdjointEigenSolver<Mat6> eig(jtj);
    const double hi = eig.eigenvalues().maxCoeff();
    // Eigen sorts them ascending; a hinge's centre may slide along its axis (one free direction).
    const double lowest = eig.eigenvalues()[static_cast<Eigen::Index>(params_.free_directions)];
    const double conditioning = hi > 0.0 ? lowest / hi : 0.0;
    data_cost_ = std::max(gn_.cost - gn_.ridge * (x - gn_.prior).squaredNorm(), 0.0);
    relative_residual_ = std::sqrt(data_cost_ / std::max(gn_.f2, 1e-12));
    ready_ = relative_residual_ <= params_.max_residual && conditioning >= params_.min_conditioning &&
             r_p_.norm() <= params_.max_distance_m && r_c_.norm() <= params_.max_distance_m;
    // A centre that no longer moves (< 2 mm) is checked less and less often, up to
    // max_interval_s: it is a constant of the mounting.
    const bool still =
        gn_.was_ready && ready_ && (gn_.prior - x).head<3>().norm() < 0.002 && (gn_.prior - x).tail<3>().norm() < 0.002;
    interval_s_ = still ? std::min(2.0 * interval_s_, params_.max_interval_s) : params_.solve_interval_s;
    if (reference_ && ready_) {
        gn_.phase = Phase::kReference;  // its cost is one more pass, the next one
        return;
    }
    publish();
}

void JointPositionEstimator::publish() {
    gn_.phase = Phase::kIdle;
    new_solution_ = true;
}

bool JointPositionEstimator::solve() {
    if (gn_.phase == Phase::kIdle && !begin()) return false;
    while (gn_.phase != Phase::kIdle)
        pass();
    return true;
}

}  // namespace mocap::fusion
