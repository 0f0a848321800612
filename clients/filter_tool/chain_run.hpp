// chain_run.hpp — `mocap-filter --chain`: every segment's filter and the chain stage
// (fusion/chain_estimator.hpp) over a chain recording, and the errors against its reference.
//
// Run: one filter per segment (the same name and parameters for all), fed row by row; after
// each row the chain estimator takes every filter's heading split (6D part, magnetometer
// heading, trust, field) and bias-corrected rate and returns each segment's q_earth_sensor.
// With no_mag every magnetometer reading is dropped before the filters see it. With the
// heading mode "magnetometer" the output is each filter's own estimate.
//
// Evaluation: per segment the metrics of evaluation.hpp (movement mask and skip window as
// mocap-filter --eval); per joint the angle of the relative orientation
// conj(q_parent) ⊗ q_child against the reference's, over the samples where both segments have
// a reference: its mean after the first joint_skip_s seconds, its mean over the last
// last_window_s seconds (drift shows as a larger late mean), RMSE and maximum after the skip.
//
// Thread-safety: none needed (pure functions over owned data). Cost: one filter update per
// segment and row plus one chain step per row; memory O(rows × segments).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "filter/filter_factory.hpp"
#include "filter_tool/chain_file.hpp"
#include "filter_tool/evaluation.hpp"

namespace mocap::tools {

struct ChainRunOptions {
    std::string filter = "mocap";
    filter::FilterParamList params;
    fusion::ChainParams chain;
    bool no_mag = false;
    bool offline = false;         ///< run_chain_offline (informational: the JSON names it)
    double skip_seconds = 0.0;    ///< per-segment metrics: first seconds not evaluated
    double joint_skip_s = 5.0;    ///< joint mean: first seconds not counted
    double last_window_s = 30.0;  ///< joint drift: the mean over this many final seconds
};

struct ChainRunOutput {
    /// q_earth_sensor (ENU) per segment, per row.
    std::vector<std::vector<Quat>> q;
    /// Heading source of each segment per row.
    std::vector<std::vector<fusion::HeadingSource>> source;
    /// Per joint, per row: δ (rad) and its standard deviation (rad).
    std::vector<std::vector<double>> delta_rad, sigma_rad;
    std::vector<fusion::JointStatus> joint_status;  ///< at the end
};

/// Runs the chain; nullopt + *error when the filter cannot be made.
std::optional<ChainRunOutput> run_chain(const ChainRecording& chain, const ChainRunOptions& options,
                                        std::string* error);

/// The non-causal re-solve (--offline): every segment's 6D orientation and magnetometer
/// heading re-solved over the whole take by the offline smoother (filter/offline_smoother.hpp;
/// once without the field for q6, once with it for d), a constant gyro bias per segment from
/// the re-solved motion, then the chain smoother (fusion/chain_smoother.hpp).
std::optional<ChainRunOutput> run_chain_offline(const ChainRecording& chain, const ChainRunOptions& options,
                                                std::string* error);

struct JointError {
    std::size_t samples = 0;
    double mean_deg = 0.0;       ///< after joint_skip_s
    double last_mean_deg = 0.0;  ///< over the last last_window_s
    double rmse_deg = 0.0;       ///< after joint_skip_s
    double max_deg = 0.0;        ///< after joint_skip_s
};

/// One joint's relative-orientation error (needs the reference in both segments' files).
JointError joint_error(const ChainRecording& chain, const ChainRunOutput& run, std::size_t joint,
                       const ChainRunOptions& options);

/// The per-segment metrics of one segment (its recording's movement mask, skip_seconds).
EvalResult segment_error(const ChainRecording& chain, const ChainRunOutput& run, std::size_t segment,
                         const ChainRunOptions& options);

/// One JSON object: filter, heading, no_mag, segments {name: metrics}, joints [{parent, child,
/// type, samples, mean_deg, last30_mean_deg (named for last_window_s), rmse_deg, max_deg}],
/// joints_mean_deg and hinge_mean_deg (means over the joints, over the hinges).
std::string chain_eval_json(const ChainRecording& chain, const ChainRunOutput& run, const ChainRunOptions& options);

/// Writes DIR/<segment>.csv (t,qw,qx,qy,qz) for every segment and DIR/joints.csv (t, then per
/// joint <parent>-<child>_delta_deg, _sigma_deg, _source). false + *error on a write failure.
bool write_chain_outputs(const std::string& dir, const ChainRecording& chain, const ChainRunOutput& run,
                         std::string* error);

}  // namespace mocap::tools
