// pose_solver.hpp — the assembler's FrameSink: turns each subject's filtered sensor
// orientations into the calibrated skeleton pose and hands it to the pose service.
//
// Per frame: q_earth_sensor of every segment -> (calibration) q_world_segment -> optional
// Slerp smoothing -> forward kinematics (positions; once calibrated the root travels by
// foot contacts, skeleton/root_motion.hpp, otherwise it stays at its T-pose height) ->
// joint angles -> publish.
// A subject without a calibration is served with its raw sensor orientations (flags lack
// kSegmentCalibrated), so poses stream from the first sample.
//
// Automatic calibration (options.auto_calibrate): a subject that has no calibration is
// calibrated from its first still period of calibration_s (after 0.5 s of data, so filters
// have settled), assuming the configured pose; while it moves, collection restarts. Any
// calibrate command replaces it.
// Calibration on command: request_calibration() (any thread, e.g. a control request) asks
// the subject to stand still in a T- or N-pose; the solver collects calibration_s of
// frames (sample time, not wall time), calibrates (skeleton/calibration.hpp), and on success
// applies it at once and saves it to <calibration_dir>/calibration-subject-<id>.toml
// (loaded again at start). A subject that moved (spread above the limit) or a segment without
// data fails the calibration; the old one stays. Results are counted and logged.
//
// Threading: on_frame() runs on the assembler thread; request_calibration() and
// calibration_status() on any thread (a mutex guards the request/result hand-over only).
// Cost per frame: O(segments) quaternion math, no allocation.
#pragma once

#include <atomic>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/counters.hpp"
#include "core/subject_assembler.hpp"
#include "serve/pose_frame.hpp"
#include "skeleton/body_model.hpp"
#include "skeleton/calibration.hpp"
#include "skeleton/joint_angles.hpp"
#include "skeleton/pose_smoother.hpp"
#include "skeleton/root_motion.hpp"

namespace mocap::daemon {

struct PoseSolverOptions {
    std::uint32_t max_subjects = 64;             ///< subject ids 1..max_subjects
    double calibration_s = 1.0;                  ///< still period collected per calibration
    skeleton::CalibrationOptions calibration{};  ///< pose is set per request
    skeleton::PoseSmootherParams smoothing{};
    std::string calibration_dir;  ///< "" = do not save or load
    /// Calibrate a subject without a calibration from its first still period, assuming
    /// this pose (nullopt = only on command).
    std::optional<skeleton::CalibrationPose> auto_calibrate;
};

using PublishFn = std::function<void(const SubjectFrame&, const serve::SkeletonPose&)>;

class PoseSolver final : public FrameSink {
public:
    PoseSolver(skeleton::BodyModel model, PoseSolverOptions options, PublishFn publish);

    /// Loads saved calibrations (set-up, before frames flow). Returns log lines.
    std::vector<std::string> load_calibrations();

    void on_frame(const SubjectFrame& frame) override;

    /// Any thread. Starts collecting a still period for the subject; returns an error text
    /// for an unknown subject (empty = accepted).
    std::string request_calibration(std::uint32_t subject_id, skeleton::CalibrationPose pose);

    [[nodiscard]] const skeleton::BodyModel& model() const { return model_; }
    [[nodiscard]] const std::vector<skeleton::JointSpec>& joints() const { return joints_; }
    /// Component "skeleton": frames_solved, calibrations_ok, calibrations_failed,
    /// auto_calibration_retries (automatic attempts restarted because the subject moved).
    [[nodiscard]] const CounterGroup& counters() const { return group_; }

private:
    struct Subject {
        std::optional<skeleton::Calibration> calibration;
        skeleton::PoseSmoother smoother;
        skeleton::CalibrationCollector collector;
        bool collecting = false;
        std::int64_t collect_start_us = -1;
        skeleton::CalibrationPose pose = skeleton::CalibrationPose::kTPose;
        std::optional<skeleton::FootContactRootTracker> root;  // travel once calibrated
        bool auto_pending = true;    // no calibration yet: calibrate from the first still period
        bool auto_run = false;       // the collection in progress is the automatic one
        std::int64_t first_us = -1;  // sample time of the subject's first frame
    };

    void take_requests();
    void collect(Subject& s, std::uint32_t subject_id, const SubjectFrame& frame,
                 const std::array<skeleton::Quat, kMaxSegments>& q_earth_sensor);
    [[nodiscard]] std::string calibration_path(std::uint32_t subject_id) const;

    skeleton::BodyModel model_;
    PoseSolverOptions options_;
    PublishFn publish_;
    std::vector<skeleton::JointSpec> joints_;
    std::vector<Subject> subjects_;  // index = subject id
    serve::SkeletonPose out_{};

    std::mutex requests_mutex_;
    std::vector<std::pair<std::uint32_t, skeleton::CalibrationPose>> requests_;
    std::atomic<bool> has_requests_{false};

    Counter frames_solved_, calibrations_ok_, calibrations_failed_, auto_calibration_retries_;
    CounterGroup group_{"skeleton"};
};

}  // namespace mocap::daemon
