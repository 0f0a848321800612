#include "daemon/pose_solver.hpp"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "skeleton/forward_kinematics.hpp"

namespace mocap::daemon {

namespace fs = std::filesystem;
using skeleton::Quat;

PoseSolver::PoseSolver(skeleton::BodyModel model, PoseSolverOptions options, PublishFn publish)
    : model_(std::move(model)),
      options_(std::move(options)),
      publish_(std::move(publish)),
      joints_(skeleton::default_joint_specs(model_)),
      subjects_(options_.max_subjects + 1) {
    for (auto& s : subjects_)
        s.smoother = skeleton::PoseSmoother(options_.smoothing);
    group_.add("frames_solved", frames_solved_);
    group_.add("calibrations_ok", calibrations_ok_);
    group_.add("calibrations_failed", calibrations_failed_);
    group_.add("auto_calibration_retries", auto_calibration_retries_);
}

std::string PoseSolver::calibration_path(std::uint32_t subject_id) const {
    return (fs::path(options_.calibration_dir) / ("calibration-subject-" + std::to_string(subject_id) + ".toml"))
        .string();
}

std::vector<std::string> PoseSolver::load_calibrations() {
    std::vector<std::string> log;
    if (options_.calibration_dir.empty()) return log;
    for (std::uint32_t id = 1; id < subjects_.size(); ++id) {
        const std::string path = calibration_path(id);
        std::error_code ec;
        if (!fs::exists(path, ec)) continue;
        std::ifstream in(path);
        std::stringstream text;
        text << in.rdbuf();
        auto r = skeleton::parse_calibration(model_, text.str());
        if (r) {
            subjects_[id].calibration = *r.calibration;
            subjects_[id].root.emplace(model_);
            log.push_back("subject " + std::to_string(id) + ": calibration loaded from " + path);
        } else {
            log.push_back("subject " + std::to_string(id) + ": ignoring " + path + ": " + r.error);
        }
    }
    return log;
}

std::string PoseSolver::request_calibration(std::uint32_t subject_id, skeleton::CalibrationPose pose) {
    if (subject_id == 0 || subject_id >= subjects_.size()) {
        return "unknown subject " + std::to_string(subject_id);
    }
    std::lock_guard lock(requests_mutex_);
    requests_.emplace_back(subject_id, pose);
    has_requests_.store(true, std::memory_order_release);
    return {};
}

void PoseSolver::take_requests() {
    std::lock_guard lock(requests_mutex_);
    for (const auto& [id, pose] : requests_) {
        Subject& s = subjects_[id];
        s.collector.reset();
        s.collecting = true;
        s.auto_run = false;
        s.auto_pending = false;
        s.collect_start_us = -1;
        s.pose = pose;
        spdlog::info("subject {}: calibration ({}) started: stand still for {} s", id, skeleton::to_string(pose),
                     options_.calibration_s);
    }
    requests_.clear();
    has_requests_.store(false, std::memory_order_relaxed);
}

void PoseSolver::collect(Subject& s, std::uint32_t subject_id, const SubjectFrame& frame,
                         const std::array<Quat, kMaxSegments>& q_earth_sensor) {
    if (s.collect_start_us < 0) s.collect_start_us = frame.sample_us;
    for (std::size_t i = 0; i < frame.segment_count; ++i) {
        if ((frame.segments[i].flags & kSegmentStale) == 0) s.collector.add(i, q_earth_sensor[i]);
    }
    const double elapsed_s = static_cast<double>(frame.sample_us - s.collect_start_us) * 1e-6;
    if (elapsed_s < options_.calibration_s) return;
    s.collecting = false;
    skeleton::CalibrationOptions opt = options_.calibration;
    opt.pose = s.pose;
    auto result = skeleton::calibrate(model_, s.collector, opt);
    if (!result) {
        if (s.auto_run) {  // the subject moved: try the next still period
            auto_calibration_retries_.add();
            spdlog::debug("subject {}: automatic calibration restarts: {}", subject_id, result.error);
            return;
        }
        calibrations_failed_.add();
        spdlog::warn("subject {}: calibration failed: {}", subject_id, result.error);
        return;
    }
    if (s.auto_run) {
        s.auto_pending = false;
        spdlog::info(
            "subject {}: calibrated automatically from its first still period ({} assumed); "
            "send a calibrate request to redo it",
            subject_id, skeleton::to_string(s.pose));
    }
    s.calibration = *result.calibration;
    s.smoother.reset();
    s.root.emplace(model_);
    s.root->reset(skeleton::root_position(model_));
    calibrations_ok_.add();
    spdlog::info("subject {}: calibrated ({})", subject_id, skeleton::to_string(s.pose));
    if (options_.calibration_dir.empty()) return;
    // Rare (one per calibration), small: written here rather than handing it to a thread.
    const std::string path = calibration_path(subject_id);
    const std::string tmp = path + ".tmp";
    {
        std::ofstream out(tmp, std::ios::trunc);
        out << skeleton::serialize_calibration(model_, *s.calibration);
        if (!out) {
            spdlog::error("subject {}: cannot write {}", subject_id, tmp);
            return;
        }
    }
    std::error_code ec;
    fs::rename(tmp, path, ec);  // atomic replace: a crash never leaves half a file
    if (ec) spdlog::error("subject {}: cannot save calibration to {}: {}", subject_id, path, ec.message());
}

void PoseSolver::on_frame(const SubjectFrame& frame) {
    if (has_requests_.load(std::memory_order_acquire)) take_requests();
    if (frame.subject_id == 0 || frame.subject_id >= subjects_.size()) return;
    Subject& s = subjects_[frame.subject_id];
    const std::size_t n = std::min<std::size_t>(frame.segment_count, model_.size());

    std::array<Quat, kMaxSegments> q_earth_sensor = skeleton::identity_quats();
    for (std::size_t i = 0; i < n; ++i) {
        const auto& q = frame.segments[i].q_earth_sensor_wxyz;
        q_earth_sensor[i] = Quat(q[0], q[1], q[2], q[3]);
    }
    if (s.first_us < 0) s.first_us = frame.sample_us;
    if (options_.auto_calibrate && s.auto_pending && !s.calibration && !s.collecting &&
        frame.sample_us - s.first_us >= 500'000) {
        s.collector.reset();
        s.collecting = true;
        s.auto_run = true;
        s.collect_start_us = -1;
        s.pose = *options_.auto_calibrate;
    }
    if (s.collecting) collect(s, frame.subject_id, frame, q_earth_sensor);

    std::array<Quat, kMaxSegments> q_world = q_earth_sensor;
    const std::span<const Quat> sensors(q_earth_sensor.data(), n);
    const std::span<Quat> world(q_world.data(), n);
    if (s.calibration) skeleton::apply_calibration(model_, *s.calibration, sensors, world);
    s.smoother.apply(frame.sample_us, world);

    skeleton::SkeletonPose fk;
    if (s.root) {
        s.root->update(model_, world, fk);
    } else {
        skeleton::forward_kinematics(model_, world, skeleton::root_position(model_), fk);
    }

    out_.segment_count = static_cast<std::uint16_t>(n);
    for (std::size_t i = 0; i < n; ++i) {
        const Quat& q = q_world[i];
        out_.q_world_segment_wxyz[i] = {q.w(), q.x(), q.y(), q.z()};
        const auto& p = fk.joint_position_m[i];
        out_.position_m[i] = {p.x(), p.y(), p.z()};
        out_.extra_flags[i] = s.calibration && s.calibration->calibrated[i] ? kSegmentCalibrated : 0;
    }
    std::array<skeleton::JointAngles, kMaxSegments> angles{};
    skeleton::compute_joint_angles(joints_, std::span<const Quat>(q_world.data(), n),
                                   std::span<skeleton::JointAngles>(angles.data(), joints_.size()));
    out_.joint_angle_count = static_cast<std::uint16_t>(3 * joints_.size());
    for (std::size_t j = 0; j < joints_.size(); ++j) {
        out_.joint_angles_rad[3 * j] = angles[j].flexion_rad;
        out_.joint_angles_rad[3 * j + 1] = angles[j].abduction_rad;
        out_.joint_angles_rad[3 * j + 2] = angles[j].rotation_rad;
    }
    frames_solved_.add();
    publish_(frame, out_);
}

}  // namespace mocap::daemon
