#include "skeleton/pose_smoother.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace mocap::skeleton {

void PoseSmoother::apply(std::int64_t t_us, std::span<Quat> q_world_segment) {
    assert(q_world_segment.size() <= kMaxSegments);
    const std::int64_t dt_us = t_us - last_us_;
    const bool restart = !started_ || dt_us < 0 || dt_us > params_.reset_gap_us;
    last_us_ = t_us;
    if (restart) {
        std::copy(q_world_segment.begin(), q_world_segment.end(), state_.begin());
        started_ = true;
        return;
    }
    double alpha = params_.alpha;
    if (params_.time_constant_s > 0.0) {
        alpha = 1.0 - std::exp(-1e-6 * static_cast<double>(dt_us) / params_.time_constant_s);
    }
    alpha = std::clamp(alpha, 0.0, 1.0);
    for (std::size_t i = 0; i < q_world_segment.size(); ++i) {
        state_[i] = alpha >= 1.0 ? q_world_segment[i] : math::slerp(state_[i], q_world_segment[i], alpha);
        q_world_segment[i] = state_[i];
    }
}

}  // namespace mocap::skeleton
