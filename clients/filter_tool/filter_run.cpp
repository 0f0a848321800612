#include "filter_tool/filter_run.hpp"

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

RunOutput run_filter(filter::OrientationFilter& f, const Recording& recording, const RunOptions& options) {
    RunOutput out;
    out.estimates.reserve(recording.rows.size());
    out.compared.reserve(recording.rows.size());
    f.reset();
    const std::int64_t t0_us = recording.rows.empty() ? 0 : recording.rows.front().sample.t_us;
    for (const RecordingRow& row : recording.rows) {
        f.update(row.sample);
        const Quat q = math::canonical(from_enu(f.orientation(), options.frame));
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

}  // namespace mocap::tools
