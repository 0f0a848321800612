// pose_smoother.hpp — optional Slerp smoothing of segment orientations between frames
// (the seed system smooths its output this way).
//
// Per segment: q_out = slerp(q_out_prev, q_in, α) along the shortest arc. α is either fixed
// (alpha, 1 = no smoothing, output = input) or derived from the frames' own timestamps
// as α = 1 − exp(−Δt / time_constant_s) when time_constant_s > 0, so the smoothing does not
// depend on the frame rate. Δt comes from the sample timestamps passed in (no clock): a
// repeated timestamp gives α = 0 (output held), a timestamp going backwards or a gap
// longer than reset_gap_us restarts the filter at the input.
// The first frame after construction or reset() passes through unchanged.
//
// A first-order low-pass: the lag is about time_constant_s (or (1−α)/α frames).
// Fixed arrays: no allocation. O(segments) per frame. Not thread-safe (one per subject).
#pragma once

#include <array>
#include <cstdint>
#include <span>

#include "core/frame.hpp"
#include "skeleton/body_model.hpp"

namespace mocap::skeleton {

struct PoseSmootherParams {
    double alpha = 1.0;                   ///< fixed blend factor in (0, 1] when time_constant_s == 0
    double time_constant_s = 0.0;         ///< > 0: α from the timestamps
    std::int64_t reset_gap_us = 500'000;  ///< a longer gap restarts at the input
};

class PoseSmoother {
public:
    explicit PoseSmoother(const PoseSmootherParams& params = {}) : params_(params) {}

    /// Smooths q_world_segment in place (all entries; size <= kMaxSegments).
    void apply(std::int64_t t_us, std::span<Quat> q_world_segment);
    void reset() { started_ = false; }
    const PoseSmootherParams& params() const { return params_; }

private:
    PoseSmootherParams params_;
    bool started_ = false;
    std::int64_t last_us_ = 0;
    std::array<Quat, kMaxSegments> state_ = identity_quats();
};

}  // namespace mocap::skeleton
