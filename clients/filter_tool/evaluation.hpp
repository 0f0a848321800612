// evaluation.hpp — orientation error metrics of a filter run against a reference.
//
// Definitions (docs/design.md, "Error metrics", as in the BROAD benchmark): q_err = q_est ⊗ conj(q_ref);
// total = 2·acos(|w|), heading = 2·atan(|z/w|), inclination = 2·acos(√(w²+z²)); the
// earth z axis must be vertical (ENU or NED). Roll/pitch/yaw errors are differences of
// ZYX Euler angles of q_est and q_ref, wrapped to (-180°, 180°]. RMSE over the evaluated
// samples, in degrees.
//
// Thread-safety: pure functions. Cost: linear in the samples, no allocation.
#pragma once

#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "math/quaternion.hpp"

namespace mocap::tools {

using math::Quat;

/// One compared instant.
struct EvalSample {
    double t_s = 0.0;
    Quat q_est = Quat::Identity();
    Quat q_ref = Quat::Identity();
    bool has_reference = true;  ///< false: the reference is missing here (ignored entirely)
    bool evaluated = true;      ///< counts towards the RMSEs (movement mask, skip window)
};

struct EvalResult {
    std::size_t samples = 0;  ///< evaluated samples
    double rmse_total_deg = 0.0;
    double rmse_heading_deg = 0.0;
    double rmse_inclination_deg = 0.0;
    double rmse_roll_deg = 0.0;
    double rmse_pitch_deg = 0.0;
    double rmse_yaw_deg = 0.0;
    double max_total_deg = 0.0;  ///< largest total error over the evaluated samples
    /// Time from the first sample (all samples, mask ignored) after which the total error
    /// stays below the threshold until the end; nullopt if it is above it at the end.
    std::optional<double> convergence_time_s;
    /// Time from the first sample at which the total error first falls below the threshold
    /// (nullopt if never). With noisy data it can be much earlier than convergence_time_s,
    /// which a single late excursion above the threshold pushes back.
    std::optional<double> first_below_s;
    double convergence_threshold_deg = 10.0;
};

/// RMSEs over the samples with a reference and evaluated = true (all zero if none), and
/// the convergence time over the samples with a reference.
EvalResult evaluate(std::span<const EvalSample> samples, double convergence_threshold_deg = 10.0);

/// One JSON object (no newline): the EvalResult fields plus "filter"; convergence_time_s
/// and first_below_s are null when the run never stays / never gets below the threshold.
std::string eval_json(const EvalResult& result, std::string_view filter_name);

}  // namespace mocap::tools
