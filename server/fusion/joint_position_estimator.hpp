// joint_position_estimator.hpp — where a joint's centre is, seen from each of its two sensors,
// learned from the motion (docs/fusion.md, "Joint centres from motion").
//
// Method (Seel, Schauer, Raisch 2012): the joint centre is one point of both segments, so its
// specific force is one earth vector seen from both sensors. From the parent's sensor at r_p
// (parent sensor frame) it is f_p + Γ_p r_p with Γ = [ω̇]× + [ω]×² (the sensor's angular
// velocity and acceleration), from the child's f_c + Γ_c r_c; their norms agree whatever the
// two frames' headings and inclinations:
//     e_k = |f_p + Γ_p r_p| − |f_c + Γ_c r_c| = 0.
// Gauss–Newton with Levenberg damping over the six unknowns, with a small ridge towards the
// last solution: along a hinge's axis every point is a centre, and the ridge picks one.
// ω̇ is the caller's (a central difference of the rates, one sample late).
//
// Samples: those where either segment turns or accelerates in rotation enough for Γ to matter
// (|ω|² + |ω̇| above min_gamma), one per sample_spacing_s, in a ring of `capacity`. A solution
// at most every solve_interval_s of sample time, computed one pass over the samples per add()
// (the normal equations, or a trial step's cost): a solve is spread over a few dozen steps, so
// no step of the live chain pays for a whole one (its p99, docs/fusion.md "Cost"); samples that
// arrive meanwhile join the passes that follow. Ready: enough samples, a residual small against
// the specific forces, and motion that identifies all six unknowns (a segment that only ever
// turns about one axis leaves the centre's place along it open: not ready, so a hinge whose
// segments turn only about it needs its other constraints).
//
// Memory: the ring at construction. Not thread-safe (one per joint, on the chain's thread).
// Cost: add() O(1), or one pass O(capacity) (~20-40 µs for 600 samples) while a solve runs;
// solve() all passes at once, O(capacity × 2 × iterations).
#pragma once

#include <cstdint>
#include <vector>

#include "math/quaternion.hpp"

namespace mocap::fusion {

using math::Vec3;

struct JointPositionParams {
    double min_gamma = 1.0;           ///< |ω|² + |ω̇| a sample needs, 1/s²
    double sample_spacing_s = 0.04;   ///< at most one sample per this interval, s
    std::size_t capacity = 600;       ///< samples kept (the most recent)
    std::size_t min_samples = 150;    ///< before the first solution
    double solve_interval_s = 2.0;    ///< sample time between solutions, s ...
    double max_interval_s = 32.0;     ///< ... doubled while the solution stays put, up to this
    double max_residual = 0.1;        ///< RMS residual / RMS specific force that still counts
    double max_distance_m = 1.0;      ///< a centre farther from its sensor is not believed, m
    double min_conditioning = 1e-3;   ///< identifiability: smallest / largest normal-matrix eigenvalue
    std::size_t free_directions = 0;  ///< directions the motion cannot fix by nature (1: a hinge's axis)
};

class JointPositionEstimator {
public:
    explicit JointPositionEstimator(const JointPositionParams& params = {});

    void reset();
    /// One step (sensor frames): rates, angular accelerations and specific forces of both
    /// segments. Returns true when it made a pass of a solve (the step's budget).
    /// may_solve false: collect only (the caller spreads several estimators' passes over its steps).
    bool add(std::int64_t t_us, const Vec3& w_p, const Vec3& dw_p, const Vec3& f_p, const Vec3& w_c, const Vec3& dw_c,
             const Vec3& f_c, bool may_solve = true);
    /// True once after each solve has finished (then ready(), the centre and the costs are new).
    bool take_solution();
    /// A centre to compare each solution with (a body model's guess): its cost over the same
    /// samples comes with the solution (reference_cost()), one more pass after the solve.
    void compare_with(const Vec3& r_parent, const Vec3& r_child);
    [[nodiscard]] double reference_cost() const { return reference_cost_; }
    /// Σ e² of the solution over the samples of its last pass.
    [[nodiscard]] double solution_cost() const { return data_cost_; }

    [[nodiscard]] bool ready() const { return ready_; }
    [[nodiscard]] const Vec3& r_parent() const { return r_p_; }
    [[nodiscard]] const Vec3& r_child() const { return r_c_; }
    [[nodiscard]] double relative_residual() const { return relative_residual_; }
    [[nodiscard]] std::size_t samples() const { return count_; }

    /// The whole solve (every pass) now; false with too few samples.
    bool solve();

private:
    using Mat6 = Eigen::Matrix<double, 6, 6>;
    using Vec6 = Eigen::Matrix<double, 6, 1>;
    struct Sample {
        Eigen::Matrix3d g_p, g_c;  // Γ of each sensor
        Vec3 f_p, f_c;
    };
    enum class Phase : std::uint8_t { kIdle, kEvaluate, kTrial, kReference };
    // Levenberg–Marquardt, one pass per step.
    struct GaussNewton {
        Phase phase = Phase::kIdle;
        Vec6 x = Vec6::Zero(), prior = Vec6::Zero(), step = Vec6::Zero(), jte = Vec6::Zero();
        Mat6 jtj = Mat6::Zero();
        double cost = 0.0, lambda = -1.0, ridge = 0.0, f2 = 0.0;
        int it = 0, iterations = 0;
        bool was_ready = false, finishing = false;
    };
    bool begin();
    void pass();
    void next_step();
    void finish();
    void publish();
    /// Σ e² of the stored samples for a candidate centre (the reference pass). O(samples).
    [[nodiscard]] double cost(const Vec3& r_parent, const Vec3& r_child) const;
    /// Cost at v (with the ridge); with jacobian, also the normal equations, f2 and the ridge.
    double evaluate(const Vec6& v, bool jacobian);

    JointPositionParams params_;
    std::vector<Sample> ring_;
    std::size_t next_ = 0, count_ = 0;
    std::int64_t last_sample_us_ = -1, last_solve_us_ = -1;
    bool ready_ = false;
    Vec3 r_p_ = Vec3::Zero(), r_c_ = Vec3::Zero();
    double relative_residual_ = 0.0;
    double interval_s_;
    bool was_solved_ = false;
    GaussNewton gn_;
    bool new_solution_ = false;
    bool reference_ = false;
    Vec3 ref_p_ = Vec3::Zero(), ref_c_ = Vec3::Zero();
    double reference_cost_ = 0.0, data_cost_ = 0.0;
};

/// Γ = [ω̇]× + [ω]×²: f at a point r from the sensor is f + Γ r.
Eigen::Matrix3d gamma_matrix(const Vec3& w, const Vec3& dw);

}  // namespace mocap::fusion
