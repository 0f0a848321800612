// chain_smoother.hpp — the chain stage over a whole take, non-causally (mocap-filter --chain
// --offline, mocapd --replay --offline): every joint's δ from the constraints before and
// after each instant (docs/fusion.md, "Offline").
//
// Method: the caller gives every segment's 6D orientation already re-solved over the whole
// take (filter/offline_smoother.hpp, magnetometer readings removed, so one heading frame per
// segment), its magnetometer heading (the same re-solve with the field, as
// d = heading(q9 ⊗ conj(q6))) and its rate. Then:
//  1. Hinges without axes: the axes from the whole take's motion (hinge_axis_estimator.hpp,
//     its ring spread over the take), given to both passes.
//  2. Forward pass: a ChainEstimator from the first instant to the last: δ_f, σ_f per joint.
//  3. Backward pass: a ChainEstimator from the last instant to the first over the same 6D
//     frames (time reversed, rates negated: the same motion played backwards): δ_b, σ_b.
//     Both passes estimate the same quantity in the same frames, so they blend directly.
//  4. δ = δ_f + σ_f²/(σ_f² + σ_b²) · wrap(δ_b − δ_f): each pass counts where it has seen the
//     joint more recently; the segments are composed from it as the causal stage does.
//
// Memory O(rows × (segments + joints)); allocates. Not for the live pipeline: it needs the
// whole take. Thread-safety: a pure function. Cost: two chain passes and one axis solve
// per hinge without axes.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "fusion/chain_estimator.hpp"

namespace mocap::fusion {

struct ChainSmoothResult {
    std::vector<SegmentOutput> out;   ///< rows × segments, row-major
    std::vector<double> delta_rad;    ///< rows × joints: the blended δ
    std::vector<double> sigma_rad;    ///< rows × joints: its standard deviation
    std::vector<JointStatus> joints;  ///< the forward pass's status at the end (counts, axes)
};

/// in: rows × segment_count inputs, row-major (a segment without a sample at an instant: its
/// previous input, fresh = false); t_us: rows instants,
/// increasing. Requires ChainEstimator::check(segment_count, joints) to pass.
ChainSmoothResult smooth_chain(std::size_t segment_count, std::span<const JointDef> joints, const ChainParams& params,
                               std::span<const std::int64_t> t_us, std::span<const SegmentInput> in);

}  // namespace mocap::fusion
