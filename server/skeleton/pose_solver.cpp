#include "skeleton/pose_solver.hpp"

#include <charconv>

#include "core/subject_ids.hpp"
#include "skeleton/forward_kinematics.hpp"

namespace mocap::skeleton {

namespace {

std::string subject_text(std::uint32_t subject_id) {
    return "subject " + std::to_string(subject_id) + ": ";
}

/// Shortest text that reads back as the same double ("1", "0.5"), as the log always showed.
std::vector<std::uint32_t> served_ids(const PoseSolverOptions& o) {
    std::vector<std::uint32_t> ids = o.subject_ids;
    if (ids.empty()) {
        for (std::uint32_t id = 1; id <= o.max_subjects; ++id)
            ids.push_back(id);
    }
    std::sort(ids.begin(), ids.end());
    ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
    return ids;
}

std::string number_text(double v) {
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    return std::string(buf, r.ptr);
}

}  // namespace

PoseSolver::PoseSolver(BodyModel model, PoseSolverOptions options, PublishFn publish,
                       std::unique_ptr<CalibrationStore> store, LogFn log)
    : model_(std::move(model)),
      options_(std::move(options)),
      publish_(std::move(publish)),
      store_(std::move(store)),
      log_(std::move(log)),
      joints_(default_joint_specs(model_)),
      ids_(served_ids(options_)),
      subjects_(ids_.size()) {
    for (auto& s : subjects_) {
        s.smoother = PoseSmoother(options_.smoothing);
        if (options_.fusion.chain.mode != fusion::HeadingMode::kMagnetometer) s.chain.emplace(model_, options_.fusion);
    }
    group_.add("frames_solved", frames_solved_);
    group_.add("calibrations_ok", calibrations_ok_);
    group_.add("calibrations_failed", calibrations_failed_);
    group_.add("auto_calibration_retries", auto_calibration_retries_);
    group_.add("calibrations_shared", calibrations_shared_);
    group_.add("calibrations_refined", calibrations_refined_);
    if (store_) {
        store_->bind(model_, [this](std::uint32_t id, const Calibration& c, const std::string& where,
                                    std::uint64_t saves_seen) { offer_calibration(id, c, where, saves_seen); });
    }
}

std::size_t PoseSolver::load_calibrations() {
    if (!store_) return 0;
    std::size_t loaded = 0;
    for (std::size_t i = 0; i < ids_.size(); ++i) {
        const std::uint32_t id = ids_[i];
        StoredCalibration stored = store_->load(model_, id);
        if (stored.calibration) {
            subjects_[i].calibration = *stored.calibration;
            if (subjects_[i].chain) subjects_[i].chain->on_calibration(*stored.calibration, false);
            subjects_[i].root.emplace(model_);
            ++loaded;
            log(LogLevel::kInfo, subject_text(id) + "calibration loaded from " + stored.where);
        } else if (!stored.error.empty()) {
            log(LogLevel::kInfo, subject_text(id) + "ignoring " + stored.where + ": " + stored.error);
        }
    }
    return loaded;
}

std::string PoseSolver::request_calibration(std::uint32_t subject_id, CalibrationPose pose) {
    if (subject_position(ids_, subject_id) < 0) {
        return "unknown subject " + std::to_string(subject_id);
    }
    std::lock_guard lock(requests_mutex_);
    requests_.emplace_back(subject_id, pose);
    has_requests_.store(true, std::memory_order_release);
    return {};
}

void PoseSolver::offer_calibration(std::uint32_t subject_id, const Calibration& calibration, const std::string& where,
                                   std::uint64_t saves_seen) {
    if (subject_position(ids_, subject_id) < 0) return;
    std::lock_guard lock(requests_mutex_);
    offers_.push_back({subject_id, calibration, where, saves_seen});
    has_requests_.store(true, std::memory_order_release);
}

PoseSolver::Subject* PoseSolver::find(std::uint32_t subject_id) noexcept {
    const int i = subject_position(ids_, subject_id);
    return i < 0 ? nullptr : &subjects_[static_cast<std::size_t>(i)];
}

void PoseSolver::install(Subject& s, const Calibration& calibration, bool made_here) {
    s.calibration = calibration;
    if (s.chain) s.chain->on_calibration(calibration, made_here);
    s.smoother.reset();
    s.root.emplace(model_);
    s.root->reset(root_position(model_));
}

void PoseSolver::apply_offer(Offer& offer) {
    Subject& s = *find(offer.subject_id);  // offer_calibration() took served ids only
    if (s.calibrated_here != offer.saves_seen) {
        // Calibrated here after the store chose this one: the local calibration is the newer
        // and the store publishes it; applying this one would undo it.
        log(LogLevel::kInfo,
            subject_text(offer.subject_id) + "calibration from " + offer.where + " not applied: calibrated here since");
        return;
    }
    install(s, offer.calibration, false);
    s.auto_pending = false;
    if (s.collecting && s.auto_run) s.collecting = false;  // calibrated now: no automatic one
    calibrations_shared_.add();
    log(LogLevel::kInfo, subject_text(offer.subject_id) + "calibration from " + offer.where + " applied");
}

void PoseSolver::take_requests() {
    std::lock_guard lock(requests_mutex_);
    for (auto& offer : offers_)
        apply_offer(offer);
    offers_.clear();
    for (const auto& [id, pose] : requests_) {
        Subject& s = *find(id);  // request_calibration() took served ids only
        s.collector.reset();
        s.collecting = true;
        s.auto_run = false;
        s.auto_pending = false;
        s.collect_start_us = -1;
        s.pose = pose;
        log(LogLevel::kInfo, subject_text(id) + "calibration (" + std::string(to_string(pose)) +
                                 ") started: stand still for " + number_text(options_.calibration_s) + " s");
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
    CalibrationOptions opt = options_.calibration;
    opt.pose = s.pose;
    auto result = calibrate(model_, s.collector, opt);
    if (!result) {
        if (s.auto_run) {  // the subject moved: try the next still period
            auto_calibration_retries_.add();
            log(LogLevel::kDebug, subject_text(subject_id) + "automatic calibration restarts: " + result.error);
            return;
        }
        calibrations_failed_.add();
        log(LogLevel::kWarn, subject_text(subject_id) + "calibration failed: " + result.error);
        return;
    }
    if (s.auto_run) {
        s.auto_pending = false;
        log(LogLevel::kInfo, subject_text(subject_id) + "calibrated automatically from its first still period (" +
                                 std::string(to_string(s.pose)) + " assumed); send a calibrate request to redo it");
    }
    install(s, *result.calibration, true);
    ++s.calibrated_here;
    calibrations_ok_.add();
    log(LogLevel::kInfo, subject_text(subject_id) + "calibrated (" + std::string(to_string(s.pose)) + ")");
    if (!store_) return;
    // Rare (one per calibration), small: saved here rather than handing it to a thread.
    const std::string error = store_->save(model_, subject_id, *s.calibration);
    if (!error.empty()) log(LogLevel::kError, subject_text(subject_id) + error);
}

void PoseSolver::refine(Subject& s, std::uint32_t subject_id, std::int64_t sample_us) {
    if (!s.chain || !s.calibration || !options_.fusion.estimate_axes) return;
    if (s.refine_checked_us >= 0 && sample_us - s.refine_checked_us < 1'000'000 && sample_us >= s.refine_checked_us) {
        return;
    }
    s.refine_checked_us = sample_us;
    Calibration refined = *s.calibration;
    if (!s.chain->refine_calibration(model_, refined)) return;
    // The pose does not jump back to a T-pose: only the mountings turn, so the smoothing and
    // the root's travel carry on.
    s.calibration = refined;
    s.chain->on_calibration(refined, true);
    calibrations_refined_.add();
    log(LogLevel::kInfo, subject_text(subject_id) + "mountings refined from the hinge axes learned from the motion");
    if (!store_) return;
    const std::string error = store_->save(model_, subject_id, refined);
    if (!error.empty()) log(LogLevel::kError, subject_text(subject_id) + error);
}

void PoseSolver::on_frame(const SubjectFrame& frame) {
    if (has_requests_.load(std::memory_order_acquire)) take_requests();
    Subject* const found = find(frame.subject_id);
    if (found == nullptr) return;
    Subject& s = *found;
    const std::size_t n = std::min<std::size_t>(frame.segment_count, model_.size());

    std::array<Quat, kMaxSegments> q_earth_sensor = identity_quats();
    for (std::size_t i = 0; i < n; ++i) {
        const auto& q = frame.segments[i].q_earth_sensor_wxyz;
        q_earth_sensor[i] = Quat(q[0], q[1], q[2], q[3]);
    }
    std::array<std::uint8_t, kMaxSegments> heading{};
    if (s.chain) {
        s.chain->apply(frame, std::span<Quat>(q_earth_sensor.data(), n), std::span<std::uint8_t>(heading.data(), n));
    } else {
        for (std::size_t i = 0; i < n; ++i) {
            const SegmentMag m = frame.segments[i].mag;
            heading[i] = m == SegmentMag::kTrusted    ? kSegmentHeadingMag
                         : m == SegmentMag::kRejected ? kSegmentHeadingGyro
                                                      : 0;
        }
    }
    if (s.first_us < 0) {
        s.first_us = frame.sample_us;
        if (store_) store_->serving(frame.subject_id);
    }
    if (options_.auto_calibrate && s.auto_pending && !s.calibration && !s.collecting &&
        frame.sample_us - s.first_us >= 500'000) {
        s.collector.reset();
        s.collecting = true;
        s.auto_run = true;
        s.collect_start_us = -1;
        s.pose = *options_.auto_calibrate;
    }
    if (s.collecting) collect(s, frame.subject_id, frame, q_earth_sensor);
    refine(s, frame.subject_id, frame.sample_us);

    std::array<Quat, kMaxSegments> q_world = q_earth_sensor;
    const std::span<const Quat> sensors(q_earth_sensor.data(), n);
    const std::span<Quat> world(q_world.data(), n);
    if (s.calibration) apply_calibration(model_, *s.calibration, sensors, world);
    s.smoother.apply(frame.sample_us, world);

    KinematicPose fk;
    if (s.root) {
        s.root->update(model_, world, fk);
    } else {
        forward_kinematics(model_, world, root_position(model_), fk);
    }

    out_.segment_count = static_cast<std::uint16_t>(n);
    for (std::size_t i = 0; i < n; ++i) {
        const Quat& q = q_world[i];
        out_.q_world_segment_wxyz[i] = {q.w(), q.x(), q.y(), q.z()};
        const auto& p = fk.joint_position_m[i];
        out_.position_m[i] = {p.x(), p.y(), p.z()};
        out_.extra_flags[i] = static_cast<std::uint8_t>(
            (s.calibration && s.calibration->calibrated[i] ? kSegmentCalibrated : 0) | heading[i]);
    }
    std::array<JointAngles, kMaxSegments> angles{};
    compute_joint_angles(joints_, std::span<const Quat>(q_world.data(), n),
                         std::span<JointAngles>(angles.data(), joints_.size()));
    out_.joint_angle_count = static_cast<std::uint16_t>(3 * joints_.size());
    for (std::size_t j = 0; j < joints_.size(); ++j) {
        out_.joint_angles_rad[3 * j] = angles[j].flexion_rad;
        out_.joint_angles_rad[3 * j + 1] = angles[j].abduction_rad;
        out_.joint_angles_rad[3 * j + 2] = angles[j].rotation_rad;
    }
    frames_solved_.add();
    publish_(frame, out_);
}

}  // namespace mocap::skeleton
