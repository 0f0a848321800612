#include "filter_tool/chain_run.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <numbers>

#include <nlohmann/json.hpp>

#include "filter/offline_smoother.hpp"
#include "filter_tool/recording_csv.hpp"
#include "fusion/chain_smoother.hpp"
#include "pipeline/chain_offline.hpp"

namespace mocap::tools {
namespace {

constexpr double kRadToDeg = 180.0 / std::numbers::pi;

std::vector<fusion::JointDef> joint_defs(const ChainRecording& chain) {
    std::vector<fusion::JointDef> defs;
    defs.reserve(chain.joints.size());
    for (const ChainJoint& j : chain.joints)
        defs.push_back(j.def);
    return defs;
}

double seconds_since(const Recording& r, std::size_t row) {
    return static_cast<double>(r.rows[row].sample.t_us - r.rows.front().sample.t_us) * 1e-6;
}

}  // namespace

std::optional<ChainRunOutput> run_chain(const ChainRecording& chain, const ChainRunOptions& options,
                                        std::string* error) {
    const std::size_t ns = chain.segments.size();
    const std::size_t rows = chain.segments.front().recording.rows.size();
    std::vector<std::unique_ptr<filter::OrientationFilter>> filters;
    for (std::size_t s = 0; s < ns; ++s) {
        filters.push_back(filter::make_filter(options.filter, options.params, error));
        if (!filters.back()) return std::nullopt;
    }
    const std::vector<fusion::JointDef> defs = joint_defs(chain);
    fusion::ChainEstimator estimator(ns, defs, options.chain);

    ChainRunOutput out;
    out.q.assign(ns, std::vector<Quat>(rows));
    out.source.assign(ns, std::vector<fusion::HeadingSource>(rows));
    out.delta_rad.assign(defs.size(), std::vector<double>(rows));
    out.sigma_rad.assign(defs.size(), std::vector<double>(rows));
    std::vector<fusion::SegmentInput> in(ns);
    std::vector<fusion::SegmentOutput> est(ns);
    for (std::size_t k = 0; k < rows; ++k) {
        for (std::size_t s = 0; s < ns; ++s) {
            ImuSample sample = chain.segments[s].recording.rows[k].sample;
            if (options.no_mag) sample.flags |= kImuNoMag;
            filter::OrientationFilter& f = *filters[s];
            f.update(sample);
            const filter::HeadingSplit h = f.heading_split();
            fusion::SegmentInput& x = in[s];
            x.fresh = true;
            x.q6 = h.q6;
            x.gyro_rad_s = math::to_vec3(sample.gyro_rad_s) - f.gyro_bias_rad_s();
            x.accel_m_s2 = math::to_vec3(sample.accel_m_s2);
            x.mag_available = h.has_mag_heading;
            x.mag_heading_rad = h.mag_heading_rad;
            x.mag_trusted = h.mag_trusted;
            x.field_norm_ut = h.field_norm_ut;
            x.field_heading_rad = h.field_heading_rad;
            x.field_usable = h.field_usable;
            x.field_dip_rad = h.field_dip_rad;
        }
        estimator.update(chain.segments.front().recording.rows[k].sample.t_us, in, est);
        for (std::size_t s = 0; s < ns; ++s) {
            out.q[s][k] = est[s].q_earth_sensor;
            out.source[s][k] = est[s].source;
        }
        for (std::size_t j = 0; j < defs.size(); ++j) {
            const fusion::JointStatus st = estimator.status(j);
            out.delta_rad[j][k] = st.delta_rad;
            out.sigma_rad[j][k] = st.sigma_rad;
        }
    }
    for (std::size_t j = 0; j < defs.size(); ++j)
        out.joint_status.push_back(estimator.status(j));
    return out;
}

std::optional<ChainRunOutput> run_chain_offline(const ChainRecording& chain, const ChainRunOptions& options,
                                                std::string* error) {
    const std::size_t ns = chain.segments.size();
    const std::size_t rows = chain.segments.front().recording.rows.size();
    std::unique_ptr<filter::OrientationFilter> f = filter::make_filter(options.filter, options.params, error);
    if (!f) return std::nullopt;
    const filter::OfflineSmoother smoother;
    std::vector<fusion::SegmentInput> in(rows * ns);
    std::vector<std::int64_t> t_us(rows);
    for (std::size_t k = 0; k < rows; ++k)
        t_us[k] = chain.segments.front().recording.rows[k].sample.t_us;
    std::vector<ImuSample> samples;
    for (std::size_t s = 0; s < ns; ++s) {
        samples.clear();
        for (const RecordingRow& r : chain.segments[s].recording.rows) {
            samples.push_back(r.sample);
            if (options.no_mag) samples.back().flags |= kImuNoMag;
        }
        const std::vector<fusion::SegmentInput> seg = pipeline::offline_segment_inputs(smoother, *f, samples);
        for (std::size_t k = 0; k < rows; ++k)
            in[k * ns + s] = seg[k];
    }
    const std::vector<fusion::JointDef> defs = joint_defs(chain);
    const fusion::ChainSmoothResult sm = fusion::smooth_chain(ns, defs, options.chain, t_us, in);
    ChainRunOutput out;
    out.q.assign(ns, std::vector<Quat>(rows));
    out.source.assign(ns, std::vector<fusion::HeadingSource>(rows));
    out.delta_rad.assign(defs.size(), std::vector<double>(rows));
    out.sigma_rad.assign(defs.size(), std::vector<double>(rows));
    for (std::size_t k = 0; k < rows; ++k) {
        for (std::size_t s = 0; s < ns; ++s) {
            out.q[s][k] = sm.out[k * ns + s].q_earth_sensor;
            out.source[s][k] = sm.out[k * ns + s].source;
        }
        for (std::size_t j = 0; j < defs.size(); ++j) {
            out.delta_rad[j][k] = sm.delta_rad[k * defs.size() + j];
            out.sigma_rad[j][k] = sm.sigma_rad[k * defs.size() + j];
        }
    }
    out.joint_status = sm.joints;
    return out;
}

JointError joint_error(const ChainRecording& chain, const ChainRunOutput& run, std::size_t joint,
                       const ChainRunOptions& options) {
    const ChainJoint& j = chain.joints[joint];
    const auto p = static_cast<std::size_t>(j.def.parent), c = static_cast<std::size_t>(j.def.child);
    const Recording& rp = chain.segments[p].recording;
    const Recording& rc = chain.segments[c].recording;
    JointError e;
    if (!rp.has_reference || !rc.has_reference) return e;
    const double end_s = seconds_since(rp, rp.rows.size() - 1);
    double sum = 0.0, sum2 = 0.0, last_sum = 0.0;
    std::size_t last_n = 0;
    for (std::size_t k = 0; k < rp.rows.size(); ++k) {
        if (!rp.rows[k].ref_valid || !rc.rows[k].ref_valid) continue;
        const double t = seconds_since(rp, k);
        const Quat rel_est = math::conj(run.q[p][k]) * run.q[c][k];
        const Quat rel_ref = math::conj(rp.rows[k].q_ref) * rc.rows[k].q_ref;
        const double err_deg = math::error_total_rad(rel_est * math::conj(rel_ref)) * kRadToDeg;
        if (t >= end_s - options.last_window_s) {
            last_sum += err_deg;
            ++last_n;
        }
        if (t < options.joint_skip_s) continue;
        ++e.samples;
        sum += err_deg;
        sum2 += err_deg * err_deg;
        e.max_deg = std::max(e.max_deg, err_deg);
    }
    if (e.samples > 0) {
        e.mean_deg = sum / static_cast<double>(e.samples);
        e.rmse_deg = std::sqrt(sum2 / static_cast<double>(e.samples));
    }
    if (last_n > 0) e.last_mean_deg = last_sum / static_cast<double>(last_n);
    return e;
}

EvalResult segment_error(const ChainRecording& chain, const ChainRunOutput& run, std::size_t segment,
                         const ChainRunOptions& options) {
    const Recording& r = chain.segments[segment].recording;
    std::vector<EvalSample> samples(r.rows.size());
    for (std::size_t k = 0; k < r.rows.size(); ++k) {
        EvalSample& s = samples[k];
        s.t_s = seconds_since(r, k);
        s.q_est = math::canonical(run.q[segment][k]);
        s.q_ref = r.rows[k].q_ref;
        s.has_reference = r.has_reference && r.rows[k].ref_valid;
        s.evaluated = r.rows[k].movement && s.t_s >= options.skip_seconds;
    }
    return evaluate(samples);
}

std::string chain_eval_json(const ChainRecording& chain, const ChainRunOutput& run, const ChainRunOptions& options) {
    nlohmann::ordered_json j;
    j["filter"] = options.filter;
    j["heading"] = std::string(fusion::to_string(options.chain.mode));
    j["no_mag"] = options.no_mag;
    j["offline"] = options.offline;
    nlohmann::ordered_json segs = nlohmann::ordered_json::object();
    for (std::size_t s = 0; s < chain.segments.size(); ++s) {
        segs[chain.segments[s].name] =
            nlohmann::ordered_json::parse(eval_json(segment_error(chain, run, s, options), options.filter));
        segs[chain.segments[s].name].erase("filter");
    }
    j["segments"] = segs;
    nlohmann::ordered_json joints = nlohmann::ordered_json::array();
    double sum = 0.0, hinge_sum = 0.0;
    std::size_t n = 0, hinges = 0;
    const std::string last_key = "last" + std::to_string(static_cast<int>(options.last_window_s)) + "_mean_deg";
    for (std::size_t k = 0; k < chain.joints.size(); ++k) {
        const JointError e = joint_error(chain, run, k, options);
        const ChainJoint& cj = chain.joints[k];
        joints.push_back({{"parent", cj.parent},
                          {"child", cj.child},
                          {"type", std::string(fusion::to_string(cj.def.type))},
                          {"samples", e.samples},
                          {"mean_deg", e.mean_deg},
                          {last_key, e.last_mean_deg},
                          {"rmse_deg", e.rmse_deg},
                          {"max_deg", e.max_deg}});
        if (k < run.joint_status.size()) {
            const fusion::JointStatus& st = run.joint_status[k];
            const auto v = [](const math::Vec3& x) { return nlohmann::ordered_json::array({x.x(), x.y(), x.z()}); };
            nlohmann::ordered_json& o = joints.back();
            o["axes"] = st.axes_known ? nlohmann::ordered_json{{"estimated", st.axes_estimated},
                                                               {"parent", v(st.axis_parent)},
                                                               {"child", v(st.axis_child)}}
                                      : nlohmann::ordered_json(nullptr);
            o["centre"] = st.centre_known
                              ? nlohmann::ordered_json{{"parent_m", v(st.r_parent)}, {"child_m", v(st.r_child)}}
                              : nlohmann::ordered_json(nullptr);
            o["constraint_updates"] = st.joint_updates;
            o["mag_updates"] = st.mag_updates;
            o["refused"] = st.refused;
            o["restarts"] = st.restarts;
        }
        if (e.samples == 0) continue;
        sum += e.mean_deg;
        ++n;
        if (cj.def.type == fusion::JointType::kHinge) {
            hinge_sum += e.mean_deg;
            ++hinges;
        }
    }
    j["joints"] = joints;
    j["joints_mean_deg"] =
        n > 0 ? nlohmann::ordered_json(sum / static_cast<double>(n)) : nlohmann::ordered_json(nullptr);
    j["hinge_mean_deg"] =
        hinges > 0 ? nlohmann::ordered_json(hinge_sum / static_cast<double>(hinges)) : nlohmann::ordered_json(nullptr);
    return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

bool write_chain_outputs(const std::string& dir, const ChainRecording& chain, const ChainRunOutput& run,
                         std::string* error) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) {
        if (error) *error = "cannot create '" + dir + "': " + ec.message();
        return false;
    }
    const Recording& first = chain.segments.front().recording;
    for (std::size_t s = 0; s < chain.segments.size(); ++s) {
        std::vector<OrientationRow> rows(first.rows.size());
        for (std::size_t k = 0; k < rows.size(); ++k)
            rows[k] = {first.rows[k].sample.t_us, math::canonical(run.q[s][k])};
        const std::string path = (std::filesystem::path(dir) / (chain.segments[s].name + ".csv")).string();
        std::ofstream out(path, std::ios::binary | std::ios::trunc);
        if (!out || !write_orientation_csv(out, rows) || !out.flush()) {
            if (error) *error = "cannot write '" + path + "'";
            return false;
        }
    }
    const std::string path = (std::filesystem::path(dir) / "joints.csv").string();
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << 't';
    for (const ChainJoint& j : chain.joints) {
        const std::string n = j.parent + "-" + j.child;
        out << ',' << n << "_delta_deg," << n << "_sigma_deg," << n << "_source";
    }
    out << '\n';
    char buf[64];
    for (std::size_t k = 0; k < first.rows.size(); ++k) {
        std::snprintf(buf, sizeof buf, "%.6f", static_cast<double>(first.rows[k].sample.t_us) * 1e-6);
        out << buf;
        for (std::size_t j = 0; j < chain.joints.size(); ++j) {
            const auto child = static_cast<std::size_t>(chain.joints[j].def.child);
            std::snprintf(buf, sizeof buf, ",%.4f,%.4f,", run.delta_rad[j][k] * kRadToDeg,
                          run.sigma_rad[j][k] * kRadToDeg);
            out << buf << fusion::to_string(run.source[child][k]);
        }
        out << '\n';
    }
    if (!out.flush()) {
        if (error) *error = "cannot write '" + path + "'";
        return false;
    }
    return true;
}

}  // namespace mocap::tools
