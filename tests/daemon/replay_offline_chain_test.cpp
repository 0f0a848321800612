// mocapd --replay --offline with [fusion] heading = "joints" (daemon/replay.hpp, "Offline"):
// the joints hold a hinge's relative heading over the whole take where the per-segment
// re-solve follows each sensor's own field.
//
// The take is written by this test as a raw recording: the simulator's walk (sim/stream_motion.hpp)
// on the default body, read by ideal sensors (sim/stream_node.hpp, ideal_reading) with
// mountings up to 30° off their segments, a constant gyro bias and white noise, 50 Hz, 12 s.
// The left calf's sensor reads the earth's field turned by 40° about the vertical (steel near
// that shin): the same norm and dip, so no filter can tell it from the earth's own field. The
// right hand's node sends nothing, and the left thigh misses every 37th instant. One take adds
// a sideways swing of the legs so that the knees' axes can be learned from it, the other does
// not and gives the axes through a calibration.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "daemon/calibration_files.hpp"
#include "daemon/config.hpp"
#include "daemon/replay.hpp"
#include "serve/raw_recorder.hpp"
#include "sim/stream_motion.hpp"
#include "sim/stream_node.hpp"
#include "skeleton/forward_kinematics.hpp"
#include "skeleton/joint_angles.hpp"

namespace mocap::daemon {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kRateHz = 50.0;
constexpr int kRows = 600;                  // 12 s
constexpr double kStillS = 1.0;             // T-pose, then 1 s blending into the walk
constexpr double kEvaluateFromS = 3.0;      // the walk proper
constexpr double kCalfFieldTurnDeg = 40.0;  // the left calf's field
constexpr std::uint64_t kFirstSync = 1000;

using math::Quat;
using math::Vec3;

Quat rot_z(double a_rad) {
    return Quat(std::cos(0.5 * a_rad), 0.0, 0.0, std::sin(0.5 * a_rad));
}

class ReplayOfflineChain : public ::testing::Test {
protected:
    void SetUp() override {
        std::string tmpl = (std::filesystem::temp_directory_path() / "mocap-replay-chain.XXXXXX").string();
        ASSERT_NE(::mkdtemp(tmpl.data()), nullptr);
        dir_ = tmpl;
    }
    void TearDown() override {
        std::error_code ec;
        std::filesystem::remove_all(dir_, ec);
    }

    /// The simulated take as a raw recording (the legs also swing sideways with `sway`); keeps
    /// every segment's true orientation per instant.
    void write_take(bool sway) {
        const sim::StreamMotion walk = sim::StreamMotion::walk(model_, kStillS);
        const std::size_t ns = model_.size();
        std::mt19937_64 rng(20261203);
        std::normal_distribution<double> n01;
        std::uniform_real_distribution<double> u(-1.0, 1.0);
        for (std::size_t s = 0; s < ns; ++s) {
            const Vec3 axis = Vec3(n01(rng), n01(rng), n01(rng)).normalized();
            mount_[s] = Quat(Eigen::AngleAxisd(30.0 * kDeg * std::abs(u(rng)), axis));  // q_segment_sensor
            bias_[s] = Vec3(u(rng), u(rng), u(rng)) * 1.5 * kDeg;
        }
        const double dt = 1.0 / kRateHz;
        const std::size_t pelvis = static_cast<std::size_t>(model_.index_of(skeleton::seg::kPelvis));
        const std::array<std::array<int, 3>, 2> legs{
            {{model_.index_of(skeleton::seg::kLeftThigh), model_.index_of(skeleton::seg::kLeftCalf),
              model_.index_of(skeleton::seg::kLeftFoot)},
             {model_.index_of(skeleton::seg::kRightThigh), model_.index_of(skeleton::seg::kRightCalf),
              model_.index_of(skeleton::seg::kRightFoot)}}};
        const auto pose = [&](int k) {
            const double t = k * dt;
            sim::BodyPose p;
            Vec3 root;
            walk.orientations(t, 0.3, Vec3::Zero(), p.q_earth_segment, root);
            // The walk swings the legs in its sagittal plane only, so a knee's axis stays
            // horizontal and the legs turn about nothing else but the vertical: the sign of an
            // axis learned from that motion is left to noise (fusion/hinge_axis_estimator.hpp,
            // "Signs"). With `sway` each leg also swings sideways at the hip (±12°), which keeps
            // the knee a hinge and makes its axis observable.
            const double w = sway ? std::clamp(t - kStillS, 0.0, 1.0) : 0.0;
            const Vec3 forward = math::rotate(p.q_earth_segment[pelvis], Vec3::UnitX());
            for (std::size_t side = 0; side < 2; ++side) {
                const double a = w * 12.0 * kDeg * std::sin(2.0 * std::numbers::pi * 0.4 * t + 1.3 * side);
                const Quat hip(Eigen::AngleAxisd(a, forward));
                for (const int s : legs[side])
                    p.q_earth_segment[static_cast<std::size_t>(s)] =
                        (hip * p.q_earth_segment[static_cast<std::size_t>(s)]).normalized();
            }
            skeleton::KinematicPose fk;
            skeleton::forward_kinematics(model_, std::span<const Quat>(p.q_earth_segment.data(), model_.size()), root,
                                         fk);
            for (std::size_t s = 0; s < model_.size(); ++s)
                p.sensor_position_m[s] = 0.5 * (fk.joint_position_m[s] + fk.end_position_m[s]);
            return p;
        };
        const Vec3 earth = sim::stream_mag_earth_ut();
        std::string file(serve::kRawMagic, sizeof serve::kRawMagic);
        sim::BodyPose before = pose(-1), now = pose(0);
        for (int k = 0; k < kRows; ++k) {
            const sim::BodyPose after = pose(k + 1);
            truth_segment_.push_back(now.q_earth_segment);
            for (std::size_t s = 0; s < ns; ++s) {
                const auto& segment = model_.segments[s];
                if (segment.node_id < 0 || segment.name == skeleton::seg::kRightHand) continue;
                if (segment.name == skeleton::seg::kLeftThigh && k % 37 == 5) continue;
                const Quat q_prev = before.q_earth_segment[s] * mount_[s];
                const Quat q = now.q_earth_segment[s] * mount_[s];
                const Vec3 lin_acc =
                    (after.sensor_position_m[s] - 2.0 * now.sensor_position_m[s] + before.sensor_position_m[s]) /
                    (dt * dt);
                const Vec3 field = segment.name == skeleton::seg::kLeftCalf
                                       ? math::rotate(rot_z(kCalfFieldTurnDeg * kDeg), earth)
                                       : earth;
                const sim::SensorReading r = sim::ideal_reading(q_prev, q, dt, lin_acc, field);
                const Vec3 gyro = r.gyro_rad_s + bias_[s] + 0.005 * Vec3(n01(rng), n01(rng), n01(rng));
                const Vec3 accel = r.accel_m_s2 + 0.05 * Vec3(n01(rng), n01(rng), n01(rng));
                const Vec3 mag = r.mag_ut + 0.3 * Vec3(n01(rng), n01(rng), n01(rng));
                SegmentSample x;
                x.subject_id = 1;
                x.node_id = static_cast<std::uint8_t>(segment.node_id);
                x.sync = kFirstSync + static_cast<std::uint64_t>(k);
                x.imu.t_us = 50'000'000 + static_cast<std::int64_t>(k) * 20'000;
                x.imu.gyro_rad_s = math::to_array(gyro);
                x.imu.accel_m_s2 = math::to_array(accel);
                x.imu.mag_ut = math::to_array(mag);
                x.times.received_us = 1'800'000'000'000'000 + x.imu.t_us + 2'000 + static_cast<std::int64_t>(s) * 10;
                serve::append_raw_sample_record(x, file);
            }
            before = now;
            now = after;
        }
        raw_path_ = (dir_ / "take.mocapraw").string();
        std::ofstream(raw_path_, std::ios::binary) << file;
    }

    /// Writes the subject's true mountings as its calibration (earth frame kept).
    std::string write_calibration() {
        skeleton::Calibration cal;
        cal.segment_count = model_.size();
        cal.heading_mode = skeleton::HeadingMode::kKeepEarth;
        for (std::size_t s = 0; s < model_.size(); ++s) {
            cal.q_sensor_segment[s] = mount_[s].conjugate();
            cal.calibrated[s] = model_.segments[s].name != skeleton::seg::kRightHand;
        }
        const std::string cal_dir = (dir_ / "calibrations").string();
        std::filesystem::create_directories(cal_dir);
        const std::string err = CalibrationFiles(cal_dir).save(model_, 1, cal);
        EXPECT_EQ(err, "");
        return cal_dir;
    }

    struct KneeErrors {
        double left_rms_deg = 0.0, right_rms_deg = 0.0;
        std::size_t frames = 0;
    };

    /// Replays the take offline with [fusion] heading, then compares the knees' joint angles
    /// with the truth's (from the segments' true orientations, or without a calibration the
    /// sensors', which is what the solver serves then).
    KneeErrors replay(const std::string& heading, const std::string& calibration_dir = "") {
        DaemonConfig config;
        config.stats_interval_s = 0;
        config.auto_calibrate = "off";
        config.fusion_heading = heading;
        ReplayOptions options;
        options.files = {raw_path_};
        options.offline = true;
        options.calibration_dir = calibration_dir;
        options.angles_out = (dir_ / ("angles-" + heading + ".csv")).string();
        std::filesystem::remove(options.angles_out);
        ReplayResult result;
        std::string error;
        EXPECT_TRUE(run_replay(config, options, &result, &error)) << error;
        EXPECT_EQ(result.samples_smoothed, result.samples) << "every sample re-solved";
        EXPECT_EQ(result.samples_unknown_node + result.samples_rejected, 0u);
        return knee_errors(options.angles_out, !calibration_dir.empty());
    }

    KneeErrors knee_errors(const std::string& csv, bool calibrated) const {
        const std::vector<skeleton::JointSpec> specs = skeleton::default_joint_specs(model_);
        std::size_t left = 0, right = 0;
        for (std::size_t j = 0; j < specs.size(); ++j) {
            if (specs[j].name == "left_knee") left = j;
            if (specs[j].name == "right_knee") right = j;
        }
        std::ifstream in(csv);
        std::string line;
        std::getline(in, line);  // subject,sync,t_s, then three angles per joint
        EXPECT_NE(line.find("left_knee.flexion_deg"), std::string::npos) << line;
        KneeErrors e;
        double left_sum = 0.0, right_sum = 0.0;
        while (std::getline(in, line)) {
            std::vector<double> v;
            std::stringstream ss(line);
            for (std::string cell; std::getline(ss, cell, ',');)
                v.push_back(std::stod(cell));
            const auto k = static_cast<std::size_t>(v[1]) - kFirstSync;
            if (k >= truth_segment_.size() || static_cast<double>(k) / kRateHz < kEvaluateFromS) continue;
            std::array<Quat, kMaxSegments> q = truth_segment_[k];
            for (std::size_t s = 0; s < model_.size() && !calibrated; ++s)
                q[s] = q[s] * mount_[s];  // uncalibrated: the sensors' orientations are served
            std::vector<skeleton::JointAngles> truth(specs.size());
            skeleton::compute_joint_angles(specs, std::span<const Quat>(q.data(), model_.size()), truth);
            const auto err2 = [&](std::size_t j) {
                const double* got = &v[3 + 3 * j];
                const double d0 = got[0] - truth[j].flexion_rad / kDeg;
                const double d1 = got[1] - truth[j].abduction_rad / kDeg;
                const double d2 = got[2] - truth[j].rotation_rad / kDeg;
                return d0 * d0 + d1 * d1 + d2 * d2;
            };
            left_sum += err2(left);
            right_sum += err2(right);
            ++e.frames;
        }
        if (e.frames > 0) {
            e.left_rms_deg = std::sqrt(left_sum / static_cast<double>(e.frames));
            e.right_rms_deg = std::sqrt(right_sum / static_cast<double>(e.frames));
        }
        return e;
    }

    skeleton::BodyModel model_ = skeleton::default_body_model(1.75, "mocap");
    std::filesystem::path dir_;
    std::string raw_path_;
    std::array<Quat, kMaxSegments> mount_ = skeleton::identity_quats();
    std::array<Vec3, kMaxSegments> bias_ = skeleton::zero_vec3s();
    std::vector<std::array<Quat, kMaxSegments>> truth_segment_;
};

// Each knee's error is the RMS over the walk (from 3 s) of the norm of its three angles'
// differences from the truth, °. Measured (this seed): per segment, the left knee 48° (the
// calf's heading follows its field, 40° off: most of it shows in the knee's rotation and
// abduction) and the right knee 4.8° (a clean field); with the joints 5.2° and 2.8°, the
// same with the left calf's field not turned (the joints do not look at it). The bounds: the
// joints as good as a clean field within a margin (8°), the per-segment left knee most of
// the field's turn (25°).
constexpr double kJointsMaxDeg = 8.0;
constexpr double kTurnedMinDeg = 25.0;

// Without a calibration the knees learn their axes from the take (the legs sway, so they can).
TEST_F(ReplayOfflineChain, JointsKeepTheKneeWhereTheCalfsFieldIsTurned) {
    write_take(true);
    const KneeErrors mag = replay("magnetometer");
    const KneeErrors joints = replay("joints");
    ASSERT_GT(mag.frames, 400u);
    ASSERT_EQ(joints.frames, mag.frames);
    std::printf("knee angle error RMS, deg: per segment left %.2f right %.2f; joints left %.2f right %.2f\n",
                mag.left_rms_deg, mag.right_rms_deg, joints.left_rms_deg, joints.right_rms_deg);
    EXPECT_GT(mag.left_rms_deg, kTurnedMinDeg);
    EXPECT_LT(mag.right_rms_deg, kJointsMaxDeg) << "a clean field: the per-segment re-solve is right";
    EXPECT_LT(joints.left_rms_deg, kJointsMaxDeg) << "the joints hold the calf to the thigh whatever its field says";
    EXPECT_LT(joints.right_rms_deg, kJointsMaxDeg);
}

// With the subject's calibration in --calibration-dir the knees' axes come from its mountings
// (j_sensor = q_sensor_segment ⊗ y). The legs do not sway: axes learned from this take get
// the left knee's sign wrong (measured: 195° without the calibration), the calibration's
// hold it (measured 4.8°, right knee 3.0°; per segment 50° and 5.2°).
TEST_F(ReplayOfflineChain, CalibrationGivesTheKneesAxes) {
    write_take(false);
    const std::string cal_dir = write_calibration();
    const KneeErrors mag = replay("magnetometer", cal_dir);
    const KneeErrors joints = replay("joints", cal_dir);
    ASSERT_GT(joints.frames, 400u);
    std::printf(
        "calibrated: knee angle error RMS, deg: per segment left %.2f right %.2f; joints left %.2f right %.2f\n",
        mag.left_rms_deg, mag.right_rms_deg, joints.left_rms_deg, joints.right_rms_deg);
    EXPECT_GT(mag.left_rms_deg, kTurnedMinDeg);
    EXPECT_LT(joints.left_rms_deg, kJointsMaxDeg);
    EXPECT_LT(joints.right_rms_deg, kJointsMaxDeg);
}

}  // namespace
}  // namespace mocap::daemon
