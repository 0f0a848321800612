#include "skeleton/calibration.hpp"

#include <gtest/gtest.h>

#include <random>

namespace mocap::skeleton {
namespace {

double deg(double rad) {
    return rad * 180.0 / M_PI;
}
double rad(double d) {
    return d * M_PI / 180.0;
}

Quat random_quat(std::mt19937& rng) {
    std::normal_distribution<double> n;
    return Quat(n(rng), n(rng), n(rng), n(rng)).normalized();
}

/// A small random rotation with sigma_rad per axis.
Quat noise(std::mt19937& rng, double sigma_rad) {
    std::normal_distribution<double> n(0.0, sigma_rad);
    return math::quat_from_rotvec(Vec3(n(rng), n(rng), n(rng)));
}

Quat rz(double a) {
    return Quat(Eigen::AngleAxisd(a, Vec3::UnitZ()));
}

struct Rig {
    BodyModel model = default_body_model();
    std::array<Quat, kMaxSegments> q_sensor_segment_true = identity_quats();
    std::mt19937 rng{42};
    Rig() {
        for (std::size_t i = 0; i < model.size(); ++i)
            q_sensor_segment_true[i] = random_quat(rng);
    }
    /// What the sensor's filter reports for a true segment orientation, with noise.
    Quat sensor(std::size_t i, const Quat& q_earth_segment, double sigma_rad) {
        return q_earth_segment * q_sensor_segment_true[i].conjugate() * noise(rng, sigma_rad);
    }
    /// Simulated still period: 200 samples per segment, 1° noise per axis.
    CalibrationCollector still(CalibrationPose pose, double psi) {
        CalibrationCollector c;
        const auto body = pose_orientations(model, pose);
        for (int k = 0; k < 200; ++k) {
            for (std::size_t i = 0; i < model.size(); ++i) {
                Quat q = sensor(i, rz(psi) * body[i], rad(1.0));
                if (k % 2) q.coeffs() = -q.coeffs();  // the sign of a quaternion must not matter
                c.add(i, q);
            }
        }
        return c;
    }
};

void expect_recovers(Rig& rig, const CalibrationOptions& opt, double psi) {
    const auto r = calibrate(rig.model, rig.still(opt.pose, psi), opt);
    ASSERT_TRUE(r) << r.error;
    const Calibration& cal = *r.calibration;
    double worst = 0;
    for (std::size_t i = 0; i < rig.model.size(); ++i) {
        ASSERT_TRUE(cal.calibrated[i]);
        worst = std::max(worst, deg(cal.q_sensor_segment[i].angularDistance(rig.q_sensor_segment_true[i])));
    }
    EXPECT_LT(worst, 0.5) << to_string(opt.pose);
    EXPECT_NEAR(cal.facing_heading_rad, psi, rad(0.5));

    // Motion: random segment orientations come back through the calibration.
    std::array<Quat, kMaxSegments> truth = identity_quats(), sensors = identity_quats(), out = identity_quats();
    double worst_motion = 0;
    for (int f = 0; f < 100; ++f) {
        for (std::size_t i = 0; i < rig.model.size(); ++i) {
            truth[i] = random_quat(rig.rng);
            sensors[i] = rig.sensor(i, truth[i], 0.0);
        }
        apply_calibration(rig.model, cal, sensors, out);
        const Quat world = opt.heading_mode == HeadingMode::kAlignToForward ? rz(-psi) : Quat::Identity();
        for (std::size_t i = 0; i < rig.model.size(); ++i) {
            worst_motion = std::max(worst_motion, deg(out[i].angularDistance(world * truth[i])));
        }
    }
    EXPECT_LT(worst_motion, 0.5);
}

TEST(Calibration, TPoseRecoversRandomMountingsUnderNoise) {
    Rig rig;
    CalibrationOptions opt;
    opt.facing_heading_rad = 1.1;
    expect_recovers(rig, opt, 1.1);
    opt.heading_mode = HeadingMode::kKeepEarth;
    expect_recovers(rig, opt, 1.1);
}

TEST(Calibration, NPoseRecoversRandomMountings) {
    Rig rig;
    CalibrationOptions opt;
    opt.pose = CalibrationPose::kNPose;
    opt.facing_heading_rad = -2.5;
    expect_recovers(rig, opt, -2.5);
}

TEST(Calibration, NPoseHangsTheArms) {
    const BodyModel m = default_body_model();
    const auto q = pose_orientations(m, CalibrationPose::kNPose);
    for (const auto& name : {seg::kLeftUpperArm, seg::kLeftForearm, seg::kLeftHand, seg::kRightUpperArm,
                             seg::kRightForearm, seg::kRightHand}) {
        const auto i = static_cast<std::size_t>(m.index_of(name));
        const Vec3 axis = q[i]._transformVector(m.segments[i].end_m).normalized();
        EXPECT_LT((axis - Vec3(0, 0, -1)).norm(), 1e-12) << name;
    }
    const auto thigh = static_cast<std::size_t>(m.index_of(seg::kLeftThigh));
    EXPECT_LT(q[thigh].angularDistance(Quat::Identity()), 1e-12);
}

TEST(Calibration, HeadingFromASensorAxis) {
    Rig rig;
    CalibrationOptions opt;
    opt.facing_source = FacingSource::kFromSensorAxis;
    opt.facing_segment = 0;
    // The pelvis sensor axis that points along the pelvis's forward (x) axis.
    opt.facing_sensor_axis = rig.q_sensor_segment_true[0]._transformVector(Vec3::UnitX());
    opt.facing_heading_rad = 99.0;  // ignored
    expect_recovers(rig, opt, 0.7);
}

TEST(Calibration, RejectsMovementAndMissingData) {
    Rig rig;
    CalibrationOptions opt;
    CalibrationCollector c = rig.still(CalibrationPose::kTPose, 0.0);
    // The left forearm swings 20° during the "still" period.
    for (int k = 0; k < 200; ++k)
        c.add(4, rig.sensor(4, Quat(Eigen::AngleAxisd(rad(20.0), Vec3::UnitZ())), 0.0));
    auto r = calibrate(rig.model, c, opt);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error.find("'left_forearm' moved"), std::string::npos) << r.error;

    CalibrationCollector empty;
    r = calibrate(rig.model, empty, opt);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error.find("'pelvis': 0 still samples"), std::string::npos) << r.error;

    // With allow_missing, a segment without samples follows its parent rigidly.
    BodyModel m = rig.model;
    m.segments[5].node_id = -1;  // left hand has no sensor
    CalibrationCollector c2;
    for (std::size_t i = 0; i < m.size(); ++i) {
        if (i == 5) continue;
        for (int k = 0; k < 20; ++k)
            c2.add(i, rig.sensor(i, Quat::Identity(), 0.0));
    }
    r = calibrate(m, c2, opt);
    ASSERT_TRUE(r) << r.error;
    EXPECT_FALSE(r.calibration->calibrated[5]);
    std::array<Quat, kMaxSegments> sensors = identity_quats(), out = identity_quats();
    const Quat forearm = Quat(Eigen::AngleAxisd(0.5, Vec3::UnitZ()));
    for (std::size_t i = 0; i < m.size(); ++i)
        sensors[i] = rig.sensor(i, i == 4 ? forearm : Quat::Identity(), 0.0);
    apply_calibration(m, *r.calibration, sensors, out);
    EXPECT_LT(out[5].angularDistance(forearm), 1e-9);
}

TEST(Calibration, SpreadMeasuresTheScatter) {
    std::mt19937 rng(1);
    CalibrationCollector c;
    for (int k = 0; k < 5000; ++k)
        c.add(0, noise(rng, rad(1.0)));
    // RMS angle of a 3-D Gaussian rotation vector with 1° per axis is √3 °.
    EXPECT_NEAR(deg(c.spread_rad(0)), std::sqrt(3.0), 0.1);
    EXPECT_LT(deg(c.mean(0).angularDistance(Quat::Identity())), 0.1);
}

TEST(Calibration, SavedTextReloadsExactly) {
    Rig rig;
    CalibrationOptions opt;
    opt.facing_heading_rad = 0.3;
    opt.pose = CalibrationPose::kNPose;
    const auto r = calibrate(rig.model, rig.still(opt.pose, 0.3), opt);
    ASSERT_TRUE(r);
    const std::string text = serialize_calibration(rig.model, *r.calibration);
    const auto back = parse_calibration(rig.model, text);
    ASSERT_TRUE(back) << back.error << "\n" << text;
    const Calibration &a = *r.calibration, &b = *back.calibration;
    EXPECT_EQ(b.pose, CalibrationPose::kNPose);
    EXPECT_EQ(b.heading_mode, a.heading_mode);
    EXPECT_EQ(b.facing_heading_rad, a.facing_heading_rad);
    EXPECT_EQ(b.q_world_earth.coeffs(), a.q_world_earth.coeffs());
    for (std::size_t i = 0; i < rig.model.size(); ++i) {
        EXPECT_EQ(b.calibrated[i], a.calibrated[i]);
        EXPECT_LT((b.q_sensor_segment[i].coeffs() - a.q_sensor_segment[i].coeffs()).norm(), 1e-15);
    }
}

TEST(Calibration, ParseErrorsNameTheLine) {
    const BodyModel m = default_body_model();
    const std::string head = "format = \"mocapd-calibration\"\nversion = 1\n";
    auto err = [&](const std::string& text) {
        const auto r = parse_calibration(m, text);
        EXPECT_FALSE(r) << text;
        return r.error;
    };
    EXPECT_NE(err("").find("not a mocapd calibration"), std::string::npos);
    EXPECT_NE(err(head + "[q_sensor_segment]\nelbow = [1, 0, 0, 0]\n").find("line 4: unknown segment 'elbow'"),
              std::string::npos);
    EXPECT_NE(err(head + "[q_sensor_segment]\npelvis = [1, 0, 0]\n").find("4 numbers"), std::string::npos);
    EXPECT_NE(err(head + "[q_sensor_segment]\npelvis = [2, 0, 0, 0]\n").find("norm"), std::string::npos);
    EXPECT_NE(err(head + "[q_sensor_segment]\npelvis = [1, 0, 0, nan]\n").find("finite"), std::string::npos);
    EXPECT_NE(err(head + "[q_sensor_segment]\npelvis = [1, 0, 0, 0]\npelvis = [1, 0, 0, 0]\n").find("listed twice"),
              std::string::npos);
    EXPECT_NE(err(head + "colour = 3\n").find("line 3: unknown key 'colour'"), std::string::npos);
    EXPECT_NE(err(head + "pose = \"x-pose\"\n").find("pose must be"), std::string::npos);
    EXPECT_NE(err("format = \"mocapd-calibration\"\nversion = 2\n").find("line 2: unsupported version"),
              std::string::npos);
    EXPECT_NE(err(head + "garbage\n").find("expected key = value"), std::string::npos);
    EXPECT_NE(err(head + "[other]\n").find("unknown table"), std::string::npos);
    // Comments, blank lines and CRLF are fine.
    EXPECT_TRUE(
        parse_calibration(m, "# saved\r\n" + head + "\r\n[q_sensor_segment] # all\r\npelvis = [1, 0, 0, 0]\r\n"));
}

TEST(Stillness, DetectsAStillWindowFromTimestamps) {
    StillnessParams p;
    p.window_us = 500'000;
    StillnessDetector d(p);
    std::int64_t t = 0;
    const Quat q0 = Quat::Identity();
    for (int k = 0; k < 40; ++k, t += 10'000)
        EXPECT_FALSE(d.update(t, q0, 0.01));
    for (int k = 0; k < 20; ++k, t += 10'000)
        d.update(t, q0, 0.01);
    EXPECT_TRUE(d.still());
    // A 5° turn restarts the period; small jitter does not.
    EXPECT_FALSE(d.update(t, Quat(Eigen::AngleAxisd(rad(5.0), Vec3::UnitX()))));
    t += 10'000;
    for (int k = 0; k < 60; ++k, t += 10'000) {
        d.update(t, Quat(Eigen::AngleAxisd(rad(5.0 + 0.5 * (k % 2)), Vec3::UnitX())));
    }
    EXPECT_TRUE(d.still());
    // Gyro above threshold restarts.
    EXPECT_FALSE(d.update(t, Quat(Eigen::AngleAxisd(rad(5.0), Vec3::UnitX())), 1.0));
    // Time going backwards restarts.
    for (int k = 0; k < 60; ++k, t += 10'000)
        d.update(t, q0);
    EXPECT_TRUE(d.still());
    EXPECT_FALSE(d.update(t - 1'000'000, q0));
}

}  // namespace
}  // namespace mocap::skeleton
