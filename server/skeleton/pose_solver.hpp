// pose_solver.hpp — the assembler's FrameSink: turns each subject's filtered sensor
// orientations into the calibrated skeleton pose and hands it to the outputs (PublishFn).
//
// Per frame: q_earth_sensor of every segment -> (chain stage, body_chain.hpp: headings held
// by the joints, unless options.fusion says magnetometer) -> (calibration) q_world_segment -> optional
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
// applies it at once and saves it to the injected CalibrationStore (calibration_store.hpp;
// the daemon's keeps <calibration_dir>/calibration-subject-<id>.toml), which
// load_calibrations() reads again at start. A subject that moved (spread above the limit) or
// a segment without data fails the calibration; the old one stays. Results are counted and
// logged through the injected LogFn: this layer does no file I/O and has no logger.
//
// Calibrations made elsewhere: a store shared by several hosts (cluster/calibration_bucket.hpp)
// hands the solver a newer calibration of a subject through offer_calibration() (any thread);
// it is applied at the next frame like a calibration made here, unless this host calibrated
// the subject after the store decided to offer it (then the local one, which the store
// publishes as the newer, stays). The solver tells the store when a subject's first frame
// arrives (CalibrationStore::serving), so the store can look for the subject's calibration.
//
// Threading: on_frame() runs on the assembler thread; request_calibration() and
// offer_calibration() on any thread (a mutex guards the hand-over only). The store and the
// log are called on the thread of load_calibrations() and on_frame() (and the store calls
// offer_calibration() from its own thread).
// Cost per frame: O(segments) quaternion math, no allocation (except in the rare frame that
// completes a calibration: log text, store).
#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/counters.hpp"
#include "core/subject_assembler.hpp"
#include "skeleton/body_chain.hpp"
#include "skeleton/body_model.hpp"
#include "skeleton/calibration.hpp"
#include "skeleton/calibration_store.hpp"
#include "skeleton/joint_angles.hpp"
#include "skeleton/pose_smoother.hpp"
#include "skeleton/root_motion.hpp"
#include "skeleton/skeleton_pose.hpp"

namespace mocap::skeleton {

struct PoseSolverOptions {
    /// Subject ids served, each once, any order (empty = 1..max_subjects). Ids are sparse
    /// 32-bit numbers (subject_id_base + sink id), so subjects are found by search.
    std::vector<std::uint32_t> subject_ids;
    std::uint32_t max_subjects = 64;   ///< subject ids 1..max_subjects when subject_ids is empty
    double calibration_s = 1.0;        ///< still period collected per calibration
    CalibrationOptions calibration{};  ///< pose is set per request
    PoseSmootherParams smoothing{};
    /// Calibrate a subject without a calibration from its first still period, assuming
    /// this pose (nullopt = only on command).
    std::optional<CalibrationPose> auto_calibrate;
    /// Where the segments' headings come from (body_chain.hpp); magnetometer: each filter's own.
    FusionOptions fusion{};
};

using PublishFn = std::function<void(const SubjectFrame&, const SkeletonPose&)>;

enum class LogLevel : std::uint8_t { kDebug, kInfo, kWarn, kError };
/// One finished log line ("subject 3: calibrated (t-pose)"); the caller adds time and level.
using LogFn = std::function<void(LogLevel, const std::string&)>;

class PoseSolver final : public FrameSink {
public:
    /// store: nullptr = calibrations are neither loaded nor saved. log: nullptr = silent.
    PoseSolver(BodyModel model, PoseSolverOptions options, PublishFn publish,
               std::unique_ptr<CalibrationStore> store = nullptr, LogFn log = nullptr);
    /// The store goes first: its thread may still offer calibrations until it stops.
    ~PoseSolver() override { store_.reset(); }
    PoseSolver(const PoseSolver&) = delete;
    PoseSolver& operator=(const PoseSolver&) = delete;

    /// Loads every subject's saved calibration from the store (set-up, before frames flow)
    /// and logs what it found. Returns how many were loaded.
    std::size_t load_calibrations();

    void on_frame(const SubjectFrame& frame) override;

    /// Any thread. Starts collecting a still period for the subject; returns an error text
    /// for an unknown subject (empty = accepted).
    std::string request_calibration(std::uint32_t subject_id, CalibrationPose pose);

    /// Any thread: a calibration of the subject made elsewhere (`where` names it in the log),
    /// applied at the subject's next frame unless this host has calibrated the subject more
    /// than `saves_seen` times by then (OfferFn, calibration_store.hpp). Unknown ids are ignored.
    void offer_calibration(std::uint32_t subject_id, const Calibration& calibration, const std::string& where,
                           std::uint64_t saves_seen);

    /// The injected store (nullptr = none), for its metrics.
    [[nodiscard]] const CalibrationStore* store() const { return store_.get(); }

    [[nodiscard]] const BodyModel& model() const { return model_; }
    [[nodiscard]] const std::vector<JointSpec>& joints() const { return joints_; }
    /// Component "skeleton": frames_solved, calibrations_ok, calibrations_failed,
    /// auto_calibration_retries (automatic attempts restarted because the subject moved),
    /// calibrations_shared (calibrations made elsewhere and applied here), calibrations_refined
    /// (mountings turned to agree with hinge axes learned from the motion).
    [[nodiscard]] const CounterGroup& counters() const { return group_; }

private:
    struct Subject {
        std::optional<Calibration> calibration;
        PoseSmoother smoother;
        CalibrationCollector collector;
        bool collecting = false;
        std::int64_t collect_start_us = -1;
        CalibrationPose pose = CalibrationPose::kTPose;
        std::optional<FootContactRootTracker> root;  // travel once calibrated
        bool auto_pending = true;                    // no calibration yet: calibrate from the first still period
        bool auto_run = false;                       // the collection in progress is the automatic one
        std::int64_t first_us = -1;                  // sample time of the subject's first frame
        std::uint64_t calibrated_here = 0;           // successful calibrations made by this solver
        std::optional<BodyChain> chain;              // the chain stage (none: per-segment headings)
        std::int64_t refine_checked_us = -1;         // sample time the learned axes were last looked at
    };
    struct Offer {
        std::uint32_t subject_id = 0;
        Calibration calibration;
        std::string where;
        std::uint64_t saves_seen = 0;
    };

    void take_requests();
    void apply_offer(Offer& offer);
    /// Installs a calibration and starts the subject's smoothing and root travel afresh.
    /// made_here: taken from this solver's frames (the chain keeps the headings it showed).
    void install(Subject& s, const Calibration& calibration, bool made_here);
    void collect(Subject& s, std::uint32_t subject_id, const SubjectFrame& frame,
                 const std::array<Quat, kMaxSegments>& q_earth_sensor);
    /// Once a second of sample time: mountings turned to the hinge axes the chain learned.
    void refine(Subject& s, std::uint32_t subject_id, std::int64_t sample_us);
    /// The subject with this id, nullptr if it is not served.
    [[nodiscard]] Subject* find(std::uint32_t subject_id) noexcept;
    void log(LogLevel level, const std::string& line) const {
        if (log_) log_(level, line);
    }

    BodyModel model_;
    PoseSolverOptions options_;
    PublishFn publish_;
    std::unique_ptr<CalibrationStore> store_;
    LogFn log_;
    std::vector<JointSpec> joints_;
    std::vector<std::uint32_t> ids_;  // served subject ids, ascending
    std::vector<Subject> subjects_;   // subjects_[i] is subject ids_[i]
    SkeletonPose out_{};

    std::mutex requests_mutex_;
    std::vector<std::pair<std::uint32_t, CalibrationPose>> requests_;  // guarded by requests_mutex_
    std::vector<Offer> offers_;                                        // guarded by requests_mutex_
    std::atomic<bool> has_requests_{false};

    Counter frames_solved_, calibrations_ok_, calibrations_failed_, auto_calibration_retries_, calibrations_shared_,
        calibrations_refined_;
    CounterGroup group_{"skeleton"};
};

}  // namespace mocap::skeleton
