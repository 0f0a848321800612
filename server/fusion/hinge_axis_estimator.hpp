// hinge_axis_estimator.hpp — a hinge joint's axis in both sensors' frames, learned from the
// motion (docs/fusion.md, "Joint axes from motion").
//
// Method (Seel, Raisch, Schauer 2014): for a hinge, the two segments' angular velocities
// differ only along the axis, so their parts perpendicular to it have the same length:
//     e_k = |ω_p,k × j_p| − |ω_c,k × j_c| = 0
// for the unit axes j_p (parent sensor frame) and j_c (child sensor frame). Neither heading
// nor inclination enters: the gyroscopes alone identify the axes once the joint moves and the
// segments turn about more than the axis. Gauss–Newton with Levenberg damping on the two
// tangent planes (two parameters per axis, no singular parametrisation), started from the
// nine pairs of sensor axes and then from the last solution.
// Signs: the equation does not see the sign of either axis. Both flipped is the same hinge;
// one flipped turns δ by 180°. The vertical parts of the axes in the two 6D frames are
// heading-free and equal for a consistent pair, so the sign of Σ a_z b_z decides; where the
// axis stays horizontal (Σ a_z b_z too small) the vector pairs decide: the angular-velocity
// pair does not depend on the signs, the axis pair does, and a wrong sign makes them 180° apart.
//
// Samples: only those where either segment turns faster than min_rate_rad_s, one per
// sample_spacing_s, in a ring of `capacity` (the most recent motion). solve() runs at most
// every solve_interval_s of sample time, on the caller's thread.
// Ready: after min_samples informative samples, when the solution's residual is small against
// the rates and the motion identifies all four parameters (the smallest eigenvalue of the
// normal matrix, relative to its largest, above min_conditioning).
//
// Memory: the ring is allocated at construction; nothing after. Not thread-safe (one per
// joint, on the chain's thread). Cost: add() O(1); solve() O(capacity × 40 iterations)
// (~1–3 ms for 600 samples), every solve_interval_s.
#pragma once

#include <cstdint>
#include <vector>

#include "math/quaternion.hpp"

namespace mocap::fusion {

using math::Quat;
using math::Vec3;

struct HingeAxisParams {
    double min_rate_rad_s = 0.5;     ///< a sample counts when a segment turns faster, rad/s
    double sample_spacing_s = 0.04;  ///< at most one sample per this interval, s
    std::size_t capacity = 600;      ///< samples kept (the most recent)
    std::size_t min_samples = 150;   ///< informative samples before the first solution
    double solve_interval_s = 2.0;   ///< sample time between solutions, s ...
    double max_interval_s = 32.0;    ///< ... doubled while the solution stays put, up to this
    double max_residual = 0.15;      ///< RMS residual / RMS rate that still counts as a hinge
    double min_conditioning = 1e-3;  ///< identifiability: smallest / largest normal-matrix eigenvalue
};

class HingeAxisEstimator {
public:
    explicit HingeAxisEstimator(const HingeAxisParams& params = {});

    void reset();
    /// One step: both segments' bias-corrected rates (sensor frames) and 6D orientations.
    /// Returns true when a new solution was computed in this call.
    /// may_solve false: collect only (the caller spreads several estimators' solves over its
    /// steps, one per step, so no frame pays for two).
    bool add(std::int64_t t_us, const Vec3& rate_parent, const Vec3& rate_child, const Quat& q6_parent,
             const Quat& q6_child, bool may_solve = true);

    [[nodiscard]] bool ready() const { return ready_; }
    [[nodiscard]] const Vec3& axis_parent() const { return j_p_; }
    [[nodiscard]] const Vec3& axis_child() const { return j_c_; }
    /// RMS residual of the last solution relative to the RMS rate (0: none yet).
    [[nodiscard]] double relative_residual() const { return relative_residual_; }
    [[nodiscard]] std::size_t samples() const { return count_; }

    /// Solves over the stored samples now (tests; add() calls it on its schedule).
    bool solve();

private:
    struct Sample {
        Vec3 w_p, w_c;
        Quat q_p, q_c;
    };
    /// Gauss–Newton from (jp, jc); returns the final cost (sum of squares).
    double refine(Vec3& jp, Vec3& jc, int iterations, double* conditioning) const;
    void fix_signs();

    HingeAxisParams params_;
    std::vector<Sample> ring_;
    std::size_t next_ = 0, count_ = 0;
    std::int64_t last_sample_us_ = -1, last_solve_us_ = -1;
    bool solved_once_ = false, ready_ = false;
    Vec3 j_p_ = Vec3::UnitX(), j_c_ = Vec3::UnitX();
    double relative_residual_ = 0.0;
    double interval_s_;
};

}  // namespace mocap::fusion
