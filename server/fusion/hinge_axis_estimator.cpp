#include "fusion/hinge_axis_estimator.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>

namespace mocap::fusion {
namespace {

using Mat4 = Eigen::Matrix4d;
using Vec4 = Eigen::Vector4d;
using Mat32 = Eigen::Matrix<double, 3, 2>;

/// Two unit vectors spanning the plane perpendicular to the unit vector j.
Mat32 tangent_basis(const Vec3& j) {
    const Vec3 helper = std::abs(j.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
    const Vec3 e1 = j.cross(helper).normalized();
    Mat32 b;
    b.col(0) = e1;
    b.col(1) = j.cross(e1);
    return b;
}

}  // namespace

HingeAxisEstimator::HingeAxisEstimator(const HingeAxisParams& params)
    : params_(params), ring_(std::max<std::size_t>(params.capacity, 1)), interval_s_(params.solve_interval_s) {}

void HingeAxisEstimator::reset() {
    next_ = count_ = 0;
    last_sample_us_ = last_solve_us_ = -1;
    solved_once_ = ready_ = false;
    interval_s_ = params_.solve_interval_s;
    j_p_ = j_c_ = Vec3::UnitX();
    relative_residual_ = 0.0;
}

bool HingeAxisEstimator::add(std::int64_t t_us, const Vec3& rate_parent, const Vec3& rate_child, const Quat& q6_parent,
                             const Quat& q6_child, bool may_solve) {
    const double min2 = params_.min_rate_rad_s * params_.min_rate_rad_s;
    const bool moving = rate_parent.squaredNorm() > min2 || rate_child.squaredNorm() > min2;
    const auto spacing_us = static_cast<std::int64_t>(params_.sample_spacing_s * 1e6);
    if (moving && rate_parent.allFinite() && rate_child.allFinite() &&
        (last_sample_us_ < 0 || t_us - last_sample_us_ >= spacing_us || t_us < last_sample_us_)) {
        ring_[next_] = {rate_parent, rate_child, q6_parent, q6_child};
        next_ = (next_ + 1) % ring_.size();
        count_ = std::min(count_ + 1, ring_.size());
        last_sample_us_ = t_us;
    }
    if (count_ < params_.min_samples || !may_solve) return false;
    const auto interval_us = static_cast<std::int64_t>(interval_s_ * 1e6);
    if (last_solve_us_ >= 0 && t_us - last_solve_us_ < interval_us && t_us >= last_solve_us_) return false;
    last_solve_us_ = t_us;
    const Vec3 jp = j_p_, jc = j_c_;
    const bool was_ready = ready_;
    if (!solve()) return false;
    // A solution that no longer moves (< 0.2°) is checked less and less often, up to
    // max_interval_s: the axes are constants of the mounting.
    const bool still = was_ready && ready_ && std::abs(jp.dot(j_p_)) > 0.999994 && std::abs(jc.dot(j_c_)) > 0.999994;
    interval_s_ = still ? std::min(2.0 * interval_s_, params_.max_interval_s) : params_.solve_interval_s;
    return true;
}

double HingeAxisEstimator::refine(Vec3& jp, Vec3& jc, int iterations, double* conditioning) const {
    const auto evaluate = [&](const Vec3& a, const Vec3& b, Mat4* jtj, Vec4* jte) {
        double cost = 0.0;
        const Mat32 ba = tangent_basis(a), bb = tangent_basis(b);
        if (jtj) jtj->setZero();
        if (jte) jte->setZero();
        for (std::size_t k = 0; k < count_; ++k) {
            const Sample& s = ring_[k];
            const Vec3 fp = s.w_p.cross(a), fc = s.w_c.cross(b);
            const double np = fp.norm(), nc = fc.norm();
            const double e = np - nc;
            cost += e * e;
            if (!jtj) continue;
            // d|ω × j|/dj = (f × ω)ᵀ / |f| with f = ω × j.
            const Vec3 gp = np > 1e-9 ? Vec3(fp.cross(s.w_p) / np) : Vec3::Zero();
            const Vec3 gc = nc > 1e-9 ? Vec3(fc.cross(s.w_c) / nc) : Vec3::Zero();
            Vec4 row;
            row << ba.transpose() * gp, -(bb.transpose() * gc);
            *jtj += row * row.transpose();
            *jte += row * e;
        }
        return cost;
    };
    Mat4 jtj;
    Vec4 jte;
    double cost = evaluate(jp, jc, &jtj, &jte);
    double lambda = 1e-3 * jtj.trace() / 4.0 + 1e-12;
    for (int it = 0; it < iterations; ++it) {
        Mat4 a = jtj;
        a.diagonal().array() += lambda;
        const Vec4 step = a.ldlt().solve(-jte);
        const Mat32 ba = tangent_basis(jp), bb = tangent_basis(jc);
        const Vec3 jp_new = (jp + ba * step.head<2>()).normalized();
        const Vec3 jc_new = (jc + bb * step.tail<2>()).normalized();
        const double cost_new = evaluate(jp_new, jc_new, nullptr, nullptr);
        if (cost_new < cost) {
            jp = jp_new;
            jc = jc_new;
            cost = evaluate(jp, jc, &jtj, &jte);
            lambda = std::max(lambda / 3.0, 1e-12);
            if (step.norm() < 1e-7) break;
        } else {
            lambda *= 4.0;
        }
    }
    if (conditioning) {
        const Eigen::SelfAdjointEigenSolver<Mat4> eig(jtj);
        const double hi = eig.eigenvalues().maxCoeff();
        *conditioning = hi > 0.0 ? eig.eigenvalues().minCoeff() / hi : 0.0;
    }
    return cost;
}

bool HingeAxisEstimator::solve() {
    if (count_ < 4) return false;
    double rate2 = 0.0;
    for (std::size_t k = 0; k < count_; ++k)
        rate2 += 0.5 * (ring_[k].w_p.squaredNorm() + ring_[k].w_c.squaredNorm());
    const auto relative = [&](double cost) { return std::sqrt(cost / std::max(rate2, 1e-12)); };
    Vec3 best_p = j_p_, best_c = j_c_;
    double best = solved_once_ ? refine(best_p, best_c, 10, nullptr) : 1e300;
    // From scratch the first time, and whenever the last solution no longer fits the motion
    // (a local minimum, or the sensor slipped on the segment).
    if (!solved_once_ || relative(best) > params_.max_residual) {
        const std::array<Vec3, 3> axes = {Vec3::UnitX(), Vec3::UnitY(), Vec3::UnitZ()};
        for (const Vec3& a : axes) {
            for (const Vec3& b : axes) {
                Vec3 p = a, c = b;
                const double cost = refine(p, c, 8, nullptr);
                if (cost < best) {
                    best = cost;
                    best_p = p;
                    best_c = c;
                }
            }
        }
    }
    double conditioning = 0.0;
    best = refine(best_p, best_c, 30, &conditioning);
    j_p_ = best_p;
    j_c_ = best_c;
    solved_once_ = true;
    relative_residual_ = relative(best);
    fix_signs();
    ready_ = relative_residual_ <= params_.max_residual && conditioning >= params_.min_conditioning;
    return true;
}

void HingeAxisEstimator::fix_signs() {
    // Heading-free: the axis' vertical part is the same in both 6D frames.
    double zz = 0.0, z2 = 0.0;
    // Drift-free per sample: the axis pair turns by 180° with a wrong sign, the rate pair does not.
    double agree = 0.0;
    for (std::size_t k = 0; k < count_; ++k) {
        const Sample& s = ring_[k];
        const Vec3 a = math::rotate(s.q_p, j_p_), b = math::rotate(s.q_c, j_c_);
        zz += a.z() * b.z();
        z2 += 0.5 * (a.z() * a.z() + b.z() * b.z());
        const Vec3 u = math::rotate(s.q_p, s.w_p), v = math::rotate(s.q_c, s.w_c);
        const Vec3 up = u - u.dot(a) * a, vp = v - v.dot(b) * b;
        // Angle from b_h to a_h and from vp_h to up_h, as unit complex numbers; their product
        // with one conjugated is the difference.
        const std::complex<double> axis(b.x() * a.x() + b.y() * a.y(), b.x() * a.y() - b.y() * a.x());
        const std::complex<double> rate(vp.x() * up.x() + vp.y() * up.y(), vp.x() * up.y() - vp.y() * up.x());
        agree += (axis * std::conj(rate)).real();
    }
    const bool vertical_decides = z2 > 0.0 && std::abs(zz) > 0.1 * z2;
    if ((vertical_decides && zz < 0.0) || (!vertical_decides && agree < 0.0)) j_c_ = -j_c_;
}

}  // namespace mocap::fusion
