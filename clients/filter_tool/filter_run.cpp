#include "filter_tool/filter_run.hpp"

#include <cstddef>
#include <cstdio>
#include <numbers>
#include <ostream>
#include <span>
#include <utility>

namespace mocap::tools {

std::optional<EarthFrame> parse_earth_frame(std::string_view name) {
    if (name == "enu") return EarthFrame::enu;
    if (name == "ned") return EarthFrame::ned;
    return std::nullopt;
}

Quat from_enu(const Quat& q_enu_sensor, EarthFrame frame) {
    // q_enu_ned is its own inverse, so the same product converts in both directions.
    return frame == EarthFrame::ned ? math::mul(math::q_enu_ned(), q_enu_sensor) : q_enu_sensor;
}

namespace {

// The output rows of one run from its per-sample ENU estimates.
RunOutput collect(const Recording& recording, const RunOptions& options, std::span<const Quat> q_enu) {
    RunOutput out;
    out.estimates.reserve(recording.rows.size());
    out.compared.reserve(recording.rows.size());
    const std::int64_t t0_us = recording.rows.empty() ? 0 : recording.rows.front().sample.t_us;
    for (std::size_t i = 0; i < recording.rows.size(); ++i) {
        const RecordingRow& row = recording.rows[i];
        const Quat q = math::canonical(from_enu(q_enu[i], options.frame));
        out.estimates.push_back({row.sample.t_us, q});
        EvalSample s;
        s.t_s = static_cast<double>(row.sample.t_us - t0_us) * 1e-6;
        s.q_est = q;
        s.q_ref = row.q_ref;
        s.has_reference = recording.has_reference && row.ref_valid;
        s.evaluated = row.movement && s.t_s >= options.skip_seconds;
        out.compared.push_back(s);
    }
    return out;
}

std::vector<ImuSample> samples_of(const Recording& recording) {
    std::vector<ImuSample> samples;
    samples.reserve(recording.rows.size());
    for (const RecordingRow& row : recording.rows)
        samples.push_back(row.sample);
    return samples;
}

}  // namespace

RunOutput run_filter(filter::OrientationFilter& f, const Recording& recording, const RunOptions& options) {
    std::vector<Quat> q_enu;
    q_enu.reserve(recording.rows.size());
    std::vector<TraceRow> trace;
    if (options.trace) trace.reserve(recording.rows.size());
    f.reset();
    for (const RecordingRow& row : recording.rows) {
        f.update(row.sample);
        q_enu.push_back(f.orientation());
        if (options.trace) trace.push_back({row.sample.t_us, f.diagnostics(), f.gyro_bias_rad_s()});
    }
    RunOutput out = collect(recording, options, q_enu);
    out.trace = std::move(trace);
    return out;
}

RunOutput run_offline(filter::OrientationFilter& f, const filter::OfflineSmoother& smoother, const Recording& recording,
                      const RunOptions& options) {
    const std::vector<ImuSample> samples = samples_of(recording);
    return collect(recording, options, smoother.smooth(f, samples).orientation);
}

bool write_trace_csv(std::ostream& out, const std::vector<TraceRow>& rows) {
    out << "t,rest,mag_field_disturbed,mag_heading_disturbed,mag_rejected,mag_offset_weight,bias_x,bias_y,bias_z,"
           "mag_offset_x,mag_offset_y,mag_offset_z\n";
    constexpr double kDeg = 180.0 / std::numbers::pi;
    char buf[320];
    for (const TraceRow& r : rows) {
        const filter::FilterDiagnostics& d = r.diagnostics;
        const math::Vec3 b = r.gyro_bias_rad_s * kDeg;
        const int n = std::snprintf(buf, sizeof buf, "%.6f,%d,%d,%d,%d,%.4g,%.6g,%.6g,%.6g,%.5g,%.5g,%.5g\n",
                                    static_cast<double>(r.t_us) * 1e-6, d.rest, d.mag_field_disturbed,
                                    d.mag_heading_disturbed, d.mag_rejected, d.mag_offset_weight, b.x(), b.y(), b.z(),
                                    d.mag_offset_ut.x(), d.mag_offset_ut.y(), d.mag_offset_ut.z());
        out.write(buf, n);
    }
    return static_cast<bool>(out);
}

}  // namespace mocap::tools
