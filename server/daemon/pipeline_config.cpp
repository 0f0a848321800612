#include "daemon/pipeline_config.hpp"

#include <algorithm>

#include "daemon/calibration_files.hpp"

namespace mocap::daemon {

namespace {
constexpr double kPi = 3.14159265358979323846;
}  // namespace

std::optional<skeleton::BodyModel> body_model_from_config(const DaemonConfig& config, std::string* error) {
    skeleton::BodyModel model;
    if (config.segments.empty()) {
        model = skeleton::default_body_model(1.75, config.filter_name);
    } else {
        for (const auto& sc : config.segments) {
            skeleton::SegmentDef d;
            d.name = sc.name;
            d.parent = sc.parent.empty() ? -1 : model.index_of(sc.parent);
            d.offset_m = {sc.offset_m[0], sc.offset_m[1], sc.offset_m[2]};
            d.end_m = {sc.end_m[0], sc.end_m[1], sc.end_m[2]};
            d.node_id = sc.node;
            d.filter = sc.filter.empty() ? config.filter_name : sc.filter;
            model.segments.push_back(std::move(d));
        }
        model.root_height_m = config.root_height_m;
    }
    const auto problems = skeleton::validate(model);
    if (!problems.empty()) {
        *error = "skeleton: " + problems.front();
        return std::nullopt;
    }
    return model;
}

std::vector<std::uint32_t> subject_ids_from_config(const DaemonConfig& config) {
    std::vector<std::uint32_t> ids;
    for (std::uint32_t n = 1; n <= config.max_subjects; ++n)
        ids.push_back(config.subject_id_base + n);
    for (const auto& can : config.socketcan) {
        if (std::find(ids.begin(), ids.end(), can.subject) == ids.end()) ids.push_back(can.subject);
    }
    std::sort(ids.begin(), ids.end());
    return ids;
}

serve::BvhOutputOptions bvh_options_from_config(const DaemonConfig& config) {
    serve::BvhOutputOptions o;
    o.write.units_per_m = config.bvh_units_per_m;
    if (const auto order = skeleton::parse_rotation_order(config.bvh_rotation_order)) o.write.order = *order;
    o.frame_time_s = config.bvh_frame_time_s;
    return o;
}

skeleton::PoseSolverOptions pose_solver_options_from_config(const DaemonConfig& config) {
    skeleton::PoseSolverOptions so;
    so.calibration_s = config.calibration_s;
    so.calibration.heading_mode =
        config.heading_align ? skeleton::HeadingMode::kAlignToForward : skeleton::HeadingMode::kKeepEarth;
    so.calibration.facing_source =
        config.facing_from_sensor ? skeleton::FacingSource::kFromSensorAxis : skeleton::FacingSource::kGiven;
    so.calibration.facing_heading_rad = config.facing_heading_deg * kPi / 180.0;
    so.calibration.facing_sensor_axis = {config.facing_sensor_axis[0], config.facing_sensor_axis[1],
                                         config.facing_sensor_axis[2]};
    so.smoothing.alpha = config.smoothing_alpha;
    if (config.auto_calibrate == "t-pose") so.auto_calibrate = skeleton::CalibrationPose::kTPose;
    if (config.auto_calibrate == "n-pose") so.auto_calibrate = skeleton::CalibrationPose::kNPose;
    so.fusion.chain.mode = fusion::parse_heading_mode(config.fusion_heading).value_or(fusion::HeadingMode::kAuto);
    so.fusion.estimate_axes = config.fusion_estimate_axes;
    return so;
}

std::optional<pipeline::PipelineConfig> pipeline_config_from_config(const DaemonConfig& config, std::string* error) {
    auto model = body_model_from_config(config, error);
    if (!model) return std::nullopt;
    pipeline::PipelineConfig pc;
    pc.model = std::move(*model);
    pc.subjects = subject_ids_from_config(config);
    pc.filter_params = config.filter_params;
    pc.workers = config.workers;
    pc.ring_capacity = config.ring_capacity;
    pc.assembler.deadline_us = static_cast<std::int64_t>(config.assembly_deadline_ms * 1000.0);
    pc.solver = pose_solver_options_from_config(config);
    pc.calibration_store = calibration_files(config.calibration_dir);
    pc.solver_log = log_to_spdlog;
    return pc;
}

cluster::ClusterConfig cluster_config_from_config(const DaemonConfig& c) {
    cluster::ClusterConfig cc;
    cc.nats_url = c.cluster_nats_url;
    cc.site = c.cluster_site;
    cc.host_id = cluster_host_id(c);
    cc.user = c.cluster_user;
    cc.password = c.cluster_password;
    cc.creds_file = c.cluster_creds_file;
    cc.nkey_seed_file = c.cluster_nkey_seed_file;
    cc.tls_ca_file = c.cluster_tls_ca_file;
    cc.tls_cert_file = c.cluster_tls_cert_file;
    cc.tls_key_file = c.cluster_tls_key_file;
    cc.queue_frames = c.cluster_queue_frames;
    cc.raw_replicas = c.cluster_raw_replicas;
    cc.raw_queue_samples = c.cluster_raw_queue_samples;
    cc.subject_ids = subject_ids_from_config(c);
    cc.calibration_key_file = c.cluster_calibration_key_file;
    return cc;
}

}  // namespace mocap::daemon
