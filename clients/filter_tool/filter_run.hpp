// filter_run.hpp — runs one orientation filter over a recording, as mocap-filter does.
//
// The filter always works in ENU on the sensor-frame samples (specific force and field are
// measured in the sensor frame whatever the earth frame is called). With EarthFrame::ned
// the reference in the recording is NED and every estimate is reported in NED:
// q_ned_sensor = q_enu_ned ⊗ q_enu_sensor; the errors are then computed in NED too (total,
// heading and inclination are the same in both frames; Euler angles are not).
//
// Thread-safety: none (drives one filter instance). Cost: one filter update per row plus
// two small allocations for the result vectors.
#pragma once

#include <optional>
#include <string_view>
#include <vector>

#include "filter/orientation_filter.hpp"
#include "filter_tool/evaluation.hpp"
#include "filter_tool/recording_csv.hpp"

namespace mocap::tools {

enum class EarthFrame { enu, ned };

/// "enu" | "ned" -> frame; nullopt otherwise.
std::optional<EarthFrame> parse_earth_frame(std::string_view name);

/// Earth frame `frame` <- sensor, from an ENU orientation.
Quat from_enu(const Quat& q_enu_sensor, EarthFrame frame);

struct RunOptions {
    EarthFrame frame = EarthFrame::enu;
    double skip_seconds = 0.0;  ///< samples before first t + skip are not evaluated
};

struct RunOutput {
    std::vector<OrientationRow> estimates;  ///< one per row, in RunOptions::frame
    std::vector<EvalSample> compared;       ///< one per row; has_reference false if none
};

/// Resets the filter, feeds every row in order and collects the estimates. Evaluated
/// samples: movement = 1 (or no movement column), t - t_first >= skip_seconds, a reference.
RunOutput run_filter(filter::OrientationFilter& f, const Recording& recording, const RunOptions& options);

}  // namespace mocap::tools
