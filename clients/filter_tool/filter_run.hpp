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

#include <iosfwd>
#include <optional>
#include <string_view>
#include <vector>

#include "filter/offline_smoother.hpp"
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
    bool trace = false;         ///< collect RunOutput::trace
};

/// The filter's diagnostics and gyro bias estimate after one sample (mocap-filter --trace).
struct TraceRow {
    std::int64_t t_us = 0;
    filter::FilterDiagnostics diagnostics;
    math::Vec3 gyro_bias_rad_s = math::Vec3::Zero();
};

struct RunOutput {
    std::vector<OrientationRow> estimates;  ///< one per row, in RunOptions::frame
    std::vector<EvalSample> compared;       ///< one per row; has_reference false if none
    std::vector<TraceRow> trace;            ///< one per row if RunOptions::trace, else empty
};

/// Resets the filter, feeds every row in order and collects the estimates. Evaluated
/// samples: movement = 1 (or no movement column), t - t_first >= skip_seconds, a reference.
RunOutput run_filter(filter::OrientationFilter& f, const Recording& recording, const RunOptions& options);

/// The non-causal re-solve of the whole recording with `f` (offline_smoother.hpp), evaluated
/// as run_filter is. RunOptions::trace is not honoured (a smoothed estimate has no
/// per-sample filter state); the caller rejects it.
RunOutput run_offline(filter::OrientationFilter& f, const filter::OfflineSmoother& smoother, const Recording& recording,
                      const RunOptions& options);

/// Columns t,rest,mag_field_disturbed,mag_heading_disturbed,mag_rejected,mag_offset_weight,
/// bias_x,bias_y,bias_z (gyro bias estimate, °/s, sensor frame),mag_offset_x,mag_offset_y,
/// mag_offset_z (µT, sensor frame); flags 0/1. Returns false if the stream failed.
bool write_trace_csv(std::ostream& out, const std::vector<TraceRow>& rows);

}  // namespace mocap::tools
