#include "skeleton/pose_solver.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace mocap::skeleton {
namespace {

/// Calibrations kept in maps the test owns, so it can look at them after the solver took
/// the store. `broken` subjects have an unusable stored calibration.
struct Shelf {
    std::map<std::uint32_t, Calibration> saved;
    std::map<std::uint32_t, std::string> broken;
    int saves = 0;
    std::string save_error;  ///< returned by every save when set
    OfferFn offer;           ///< what the solver bound: a shared store's way in
    std::vector<std::uint32_t> serving;
};

class MemoryStore final : public CalibrationStore {
public:
    explicit MemoryStore(Shelf& shelf) : shelf_(shelf) {}
    StoredCalibration load(const BodyModel&, std::uint32_t subject_id) override {
        StoredCalibration out;
        out.where = "shelf " + std::to_string(subject_id);
        if (auto b = shelf_.broken.find(subject_id); b != shelf_.broken.end()) {
            out.error = b->second;
        } else if (auto s = shelf_.saved.find(subject_id); s != shelf_.saved.end()) {
            out.calibration = s->second;
        }
        return out;
    }
    std::string save(const BodyModel&, std::uint32_t subject_id, const Calibration& calibration) override {
        ++shelf_.saves;
        if (!shelf_.save_error.empty()) return shelf_.save_error;
        shelf_.saved[subject_id] = calibration;
        return {};
    }
    void bind(const BodyModel&, OfferFn offer) override { shelf_.offer = std::move(offer); }
    void serving(std::uint32_t subject_id) override { shelf_.serving.push_back(subject_id); }

private:
    Shelf& shelf_;
};

Quat rz(double a) {
    return Quat(Eigen::AngleAxisd(a, Vec3::UnitZ()));
}

/// Feeds frames at 100 Hz to a solver and keeps what it publishes and logs.
struct Rig {
    BodyModel model = default_body_model();
    Shelf shelf;
    std::vector<std::pair<LogLevel, std::string>> log;
    std::map<std::uint32_t, SkeletonPose> last;  // per subject
    std::uint64_t published = 0;
    std::unique_ptr<PoseSolver> solver;
    std::int64_t t_us = 0;

    explicit Rig(PoseSolverOptions options = {}, bool with_store = true) {
        options.calibration_s = 0.5;
        if (options.subject_ids.empty()) options.max_subjects = 4;
        solver = std::make_unique<PoseSolver>(
            model, options,
            [this](const SubjectFrame& f, const SkeletonPose& p) {
                last[f.subject_id] = p;
                ++published;
            },
            with_store ? std::make_unique<MemoryStore>(shelf) : nullptr,
            [this](LogLevel level, const std::string& line) { log.emplace_back(level, line); });
    }

    /// One frame of subject_id with every sensor at q_sensor(t).
    void frame(std::uint32_t subject_id, const Quat& q_sensor) {
        SubjectFrame f;
        f.subject_id = subject_id;
        f.sample_us = t_us;
        f.segment_count = static_cast<std::uint16_t>(model.size());
        for (std::size_t i = 0; i < model.size(); ++i) {
            f.segments[i].q_earth_sensor_wxyz = {q_sensor.w(), q_sensor.x(), q_sensor.y(), q_sensor.z()};
            f.segments[i].sample_us = t_us;
            f.segments[i].flags = 0;
        }
        solver->on_frame(f);
    }
    /// duration_s of frames of subject 1; the sensors turn about up at rate_rad_s from q0.
    void run(double duration_s, const Quat& q0, double rate_rad_s = 0.0, std::uint32_t subject_id = 1) {
        const std::int64_t end = t_us + static_cast<std::int64_t>(duration_s * 1e6);
        for (; t_us < end; t_us += 10'000)
            frame(subject_id, rz(rate_rad_s * static_cast<double>(t_us) * 1e-6) * q0);
    }
    /// Subject 1 stands still with sensors at q_sensor and is calibrated (T-pose) on request.
    void calibrate_still(const Quat& q_sensor) {
        run(0.2, q_sensor);
        ASSERT_EQ(solver->request_calibration(1, CalibrationPose::kTPose), "");
        run(0.7, q_sensor);
    }
    std::uint64_t counter(std::string_view name) const { return solver->counters().value(name).value_or(999); }
    bool logged(LogLevel level, const std::string& line) const {
        for (const auto& [l, text] : log)
            if (l == level && text == line) return true;
        return false;
    }
    /// Every segment of the subject's last pose is calibrated and at identity (the T-pose
    /// facing world +x).
    ::testing::AssertionResult in_calibrated_t_pose(std::uint32_t subject_id) const {
        const auto it = last.find(subject_id);
        if (it == last.end()) return ::testing::AssertionFailure() << "nothing published";
        const SkeletonPose& p = it->second;
        for (std::size_t i = 0; i < model.size(); ++i) {
            if ((p.extra_flags[i] & kSegmentCalibrated) == 0)
                return ::testing::AssertionFailure() << "segment " << i << " not calibrated";
            const double w = std::abs(p.q_world_segment_wxyz[i][0]);
            if (w < 1.0 - 1e-9) return ::testing::AssertionFailure() << "segment " << i << " |w| " << w;
        }
        return ::testing::AssertionSuccess();
    }
};

const Quat kMounted = Quat(Eigen::AngleAxisd(0.7, Vec3(1.0, 2.0, 3.0).normalized()));

TEST(PoseSolver, UncalibratedSubjectStreamsRawOrientations) {
    Rig rig;
    rig.run(0.1, kMounted);
    ASSERT_EQ(rig.published, 10u);
    const SkeletonPose& p = rig.last.at(1);
    EXPECT_EQ(p.segment_count, rig.model.size());
    EXPECT_EQ(p.extra_flags[0] & kSegmentCalibrated, 0);
    EXPECT_NEAR(p.q_world_segment_wxyz[0][0], kMounted.w(), 1e-12);
    EXPECT_NEAR(p.q_world_segment_wxyz[0][3], kMounted.z(), 1e-12);
    EXPECT_EQ(p.joint_angle_count, 3 * rig.solver->joints().size());
}

TEST(PoseSolver, RequestedCalibrationWhileStillIsAppliedSavedAndLogged) {
    Rig rig;
    rig.run(0.2, kMounted);
    EXPECT_EQ(rig.solver->request_calibration(1, CalibrationPose::kTPose), "");
    rig.run(0.7, kMounted);
    EXPECT_EQ(rig.counter("calibrations_ok"), 1u);
    EXPECT_EQ(rig.counter("calibrations_failed"), 0u);
    EXPECT_TRUE(rig.in_calibrated_t_pose(1));
    ASSERT_EQ(rig.shelf.saves, 1);
    ASSERT_EQ(rig.shelf.saved.count(1), 1u);
    EXPECT_TRUE(rig.shelf.saved.at(1).calibrated[0]);
    EXPECT_TRUE(rig.logged(LogLevel::kInfo, "subject 1: calibration (t-pose) started: stand still for 0.5 s"));
    EXPECT_TRUE(rig.logged(LogLevel::kInfo, "subject 1: calibrated (t-pose)"));
}

TEST(PoseSolver, SubjectThatMovesFailsAndKeepsTheOldCalibration) {
    Rig rig;
    rig.solver->request_calibration(1, CalibrationPose::kTPose);
    rig.run(0.7, kMounted);
    ASSERT_EQ(rig.counter("calibrations_ok"), 1u);
    const Calibration first = rig.shelf.saved.at(1);

    rig.solver->request_calibration(1, CalibrationPose::kNPose);
    rig.run(0.7, kMounted, /*rate_rad_s=*/1.0);  // turning: far above the spread limit
    EXPECT_EQ(rig.counter("calibrations_ok"), 1u);
    EXPECT_EQ(rig.counter("calibrations_failed"), 1u);
    EXPECT_EQ(rig.shelf.saves, 1) << "a failed calibration is not saved";
    bool warned = false;
    for (const auto& [level, line] : rig.log)
        warned |= level == LogLevel::kWarn && line.rfind("subject 1: calibration failed: ", 0) == 0;
    EXPECT_TRUE(warned);

    // The first calibration still applies: standing at the mounting orientation again is the T-pose.
    rig.t_us += 1'000'000;
    rig.frame(1, kMounted);
    EXPECT_TRUE(rig.in_calibrated_t_pose(1));
    EXPECT_TRUE(rig.shelf.saved.at(1).q_sensor_segment[0].isApprox(first.q_sensor_segment[0], 1e-12));
}

TEST(PoseSolver, AutoCalibratesFromTheFirstStillPeriod) {
    PoseSolverOptions o;
    o.auto_calibrate = CalibrationPose::kTPose;
    Rig rig(o);
    rig.run(1.5, kMounted, /*rate_rad_s=*/1.0);  // moving: every automatic attempt restarts
    EXPECT_EQ(rig.counter("calibrations_ok"), 0u);
    EXPECT_GE(rig.counter("auto_calibration_retries"), 1u);
    EXPECT_EQ(rig.last.at(1).extra_flags[0] & kSegmentCalibrated, 0);

    const Quat still = rz(1.5) * kMounted;  // where the turn stopped
    rig.run(1.5, still);
    EXPECT_EQ(rig.counter("calibrations_ok"), 1u);
    EXPECT_EQ(rig.counter("calibrations_failed"), 0u) << "automatic retries are not failures";
    EXPECT_TRUE(rig.in_calibrated_t_pose(1));
    EXPECT_EQ(rig.shelf.saves, 1);
    EXPECT_TRUE(rig.logged(LogLevel::kInfo,
                           "subject 1: calibrated automatically from its first still period (t-pose assumed); "
                           "send a calibrate request to redo it"));

    // Calibrated once: standing still longer does not calibrate again.
    rig.run(1.0, still);
    EXPECT_EQ(rig.counter("calibrations_ok"), 1u);
}

TEST(PoseSolver, AutoCalibrationWaitsForFiltersToSettle) {
    PoseSolverOptions o;
    o.auto_calibrate = CalibrationPose::kTPose;
    Rig rig(o);
    rig.run(0.9, kMounted);  // 0.5 s settling + 0.5 s collection not yet over
    EXPECT_EQ(rig.counter("calibrations_ok"), 0u);
    rig.run(0.2, kMounted);
    EXPECT_EQ(rig.counter("calibrations_ok"), 1u);
}

TEST(PoseSolver, LoadsSavedCalibrationsFromTheStoreAtStart) {
    Rig first;
    first.solver->request_calibration(2, CalibrationPose::kTPose);
    first.run(0.7, kMounted, 0.0, 2);
    ASSERT_EQ(first.shelf.saved.count(2), 1u);

    Rig rig;
    rig.shelf.saved[2] = first.shelf.saved.at(2);
    rig.shelf.broken[3] = "line 1: unknown key";
    EXPECT_EQ(rig.solver->load_calibrations(), 1u);
    EXPECT_TRUE(rig.logged(LogLevel::kInfo, "subject 2: calibration loaded from shelf 2"));
    EXPECT_TRUE(rig.logged(LogLevel::kInfo, "subject 3: ignoring shelf 3: line 1: unknown key"));
    EXPECT_EQ(rig.log.size(), 2u) << "subjects without a stored calibration are not logged";

    rig.frame(2, kMounted);
    rig.frame(1, kMounted);
    EXPECT_TRUE(rig.in_calibrated_t_pose(2));
    EXPECT_EQ(rig.last.at(1).extra_flags[0] & kSegmentCalibrated, 0);
    EXPECT_EQ(rig.counter("calibrations_ok"), 0u) << "loading is not calibrating";
}

TEST(PoseSolver, WithoutAStoreNothingIsLoadedOrSaved) {
    Rig rig({}, /*with_store=*/false);
    EXPECT_EQ(rig.solver->load_calibrations(), 0u);
    rig.solver->request_calibration(1, CalibrationPose::kTPose);
    rig.run(0.7, kMounted);
    EXPECT_EQ(rig.counter("calibrations_ok"), 1u);
    EXPECT_TRUE(rig.in_calibrated_t_pose(1));
}

TEST(PoseSolver, AFailedSaveIsLoggedAndTheCalibrationStillApplies) {
    Rig rig;
    rig.shelf.save_error = "cannot write shelf";
    rig.solver->request_calibration(1, CalibrationPose::kTPose);
    rig.run(0.7, kMounted);
    EXPECT_EQ(rig.counter("calibrations_ok"), 1u);
    EXPECT_TRUE(rig.in_calibrated_t_pose(1));
    EXPECT_TRUE(rig.logged(LogLevel::kError, "subject 1: cannot write shelf"));
}

// A calibration made on another host (offered by a shared store) replaces the subject's at
// its next frame, as one made here would, and stops its automatic calibration.
TEST(PoseSolver, ACalibrationOfferedByTheStoreIsAppliedAtTheNextFrame) {
    PoseSolverOptions o;
    o.auto_calibrate = CalibrationPose::kTPose;
    Rig rig(o);
    ASSERT_TRUE(rig.shelf.offer) << "the solver binds its store";
    rig.run(0.1, kMounted);
    EXPECT_EQ(rig.shelf.serving, std::vector<std::uint32_t>{1}) << "the store hears of the subject's first frame once";
    // What a T-pose calibration with these sensors gives, made by another solver.
    Rig other;
    other.calibrate_still(kMounted);
    ASSERT_EQ(other.shelf.saved.count(1), 1u);

    rig.shelf.offer(1, other.shelf.saved.at(1), "bucket (key venue.1, revision 3)", 0);
    rig.shelf.offer(9, other.shelf.saved.at(1), "an unknown subject", 0);  // ignored
    rig.run(0.02, kMounted);
    EXPECT_TRUE(rig.in_calibrated_t_pose(1));
    EXPECT_EQ(rig.counter("calibrations_shared"), 1u);
    EXPECT_TRUE(rig.logged(LogLevel::kInfo, "subject 1: calibration from bucket (key venue.1, revision 3) applied"));
    rig.run(1.5, kMounted);
    EXPECT_EQ(rig.counter("calibrations_ok"), 0u) << "calibrated from elsewhere: no automatic calibration";
    EXPECT_EQ(rig.shelf.saves, 0) << "the store saved it already; the solver does not save it back";
}

// The store chose a calibration before this host calibrated the subject (saves_seen 0), and
// the solver takes the offer after its own calibration: the local one is newer and stays.
TEST(PoseSolver, AnOfferOlderThanALocalCalibrationIsNotApplied) {
    Rig rig;
    rig.calibrate_still(kMounted);
    ASSERT_EQ(rig.counter("calibrations_ok"), 1u);
    Calibration elsewhere = rig.shelf.saved.at(1);
    elsewhere.q_sensor_segment[0] = rz(0.5);  // different from the local one
    rig.shelf.offer(1, elsewhere, "bucket (key venue.1, revision 7)", 0);
    rig.run(0.02, kMounted);
    EXPECT_EQ(rig.counter("calibrations_shared"), 0u);
    EXPECT_TRUE(rig.in_calibrated_t_pose(1)) << "the local calibration stays";
    EXPECT_TRUE(
        rig.logged(LogLevel::kInfo,
                   "subject 1: calibration from bucket (key venue.1, revision 7) not applied: calibrated here since"));
    // Offered after the store saw the local save: applied.
    rig.shelf.offer(1, elsewhere, "bucket (key venue.1, revision 9)", 1);
    rig.run(0.02, kMounted);
    EXPECT_EQ(rig.counter("calibrations_shared"), 1u);
    EXPECT_FALSE(rig.in_calibrated_t_pose(1)) << "segment 0 now has the other calibration";
}

TEST(PoseSolver, SparseWideSubjectIdsAreServedCalibratedAndLoadedByTheirOwnId) {
    // A zone's ids (subject_id_base 4'000'000'000 + sink ids) and a SocketCAN bus's id, in
    // any order: an id-indexed table would need 4 G entries.
    PoseSolverOptions options;
    options.subject_ids = {4'000'000'002, 7, 4'000'000'001};
    Rig first(options);
    EXPECT_EQ(first.solver->request_calibration(4'000'000'001, CalibrationPose::kTPose), "");
    first.run(0.7, kMounted, 0.0, 4'000'000'001);
    EXPECT_TRUE(first.in_calibrated_t_pose(4'000'000'001));
    ASSERT_EQ(first.shelf.saved.count(4'000'000'001), 1u);
    first.run(0.05, kMounted, 0.0, 7);
    EXPECT_EQ(first.last.at(7).extra_flags[0] & kSegmentCalibrated, 0) << "another subject, not calibrated";
    const std::uint64_t published = first.published;
    for (const std::uint32_t unknown : {0u, 1u, 4'000'000'000u, 4'000'000'003u}) {
        EXPECT_EQ(first.solver->request_calibration(unknown, CalibrationPose::kTPose),
                  "unknown subject " + std::to_string(unknown));
        first.frame(unknown, kMounted);
    }
    EXPECT_EQ(first.published, published) << "frames of subjects not served are dropped";

    Rig rig(options);
    rig.shelf.saved[4'000'000'002] = first.shelf.saved.at(4'000'000'001);
    EXPECT_EQ(rig.solver->load_calibrations(), 1u);
    EXPECT_TRUE(rig.logged(LogLevel::kInfo, "subject 4000000002: calibration loaded from shelf 4000000002"));
    rig.frame(4'000'000'002, kMounted);
    EXPECT_TRUE(rig.in_calibrated_t_pose(4'000'000'002));
}

TEST(PoseSolver, CountsFramesAndRejectsUnknownSubjects) {
    Rig rig;
    EXPECT_EQ(rig.solver->counters().component(), "skeleton");
    EXPECT_EQ(rig.solver->request_calibration(0, CalibrationPose::kTPose), "unknown subject 0");
    EXPECT_EQ(rig.solver->request_calibration(5, CalibrationPose::kTPose), "unknown subject 5");
    rig.run(0.05, kMounted, 0.0, 1);
    rig.run(0.05, kMounted, 0.0, 4);
    rig.frame(0, kMounted);  // out of range: dropped
    rig.frame(5, kMounted);
    EXPECT_EQ(rig.counter("frames_solved"), 10u);
    EXPECT_EQ(rig.published, 10u);
    std::vector<std::string> names;
    for (const auto& c : rig.solver->counters().snapshot())
        names.push_back(c.name);
    EXPECT_EQ(names,
              (std::vector<std::string>{"frames_solved", "calibrations_ok", "calibrations_failed",
                                        "auto_calibration_retries", "calibrations_shared", "calibrations_refined"}));
}

}  // namespace
}  // namespace mocap::skeleton
