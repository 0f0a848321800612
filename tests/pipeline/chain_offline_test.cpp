// The offline chain stage's inputs (pipeline/chain_offline.hpp): one segment's take through
// the offline smoother, the segments on one time line of SYNC instants, and the body's joints
// with the axes a calibration gives.
#include "pipeline/chain_offline.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "filter/filter_factory.hpp"
#include "math/quaternion.hpp"

namespace mocap::pipeline {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

fusion::SegmentInput input_with_rate(double wz) {
    fusion::SegmentInput x;
    x.fresh = true;
    x.gyro_rad_s = math::Vec3(0.0, 0.0, wz);
    return x;
}

TEST(ChainRows, InstantsBySyncMissingSegmentsHoldTheirInputNotFresh) {
    // Segment 0 at every instant, segment 1 misses SYNC 11, segment 2 sends nothing.
    const std::vector<std::uint64_t> sync0{10, 11, 12, 13}, sync1{10, 12, 13};
    // Segment 0's time runs backwards at SYNC 12: the instant keeps the previous one's.
    const std::vector<std::int64_t> t0{1000, 2000, 1500, 4000}, t1{1010, 3010, 4010};
    const std::vector<fusion::SegmentInput> in0{input_with_rate(0.0), input_with_rate(0.1), input_with_rate(0.2),
                                                input_with_rate(0.3)};
    const std::vector<fusion::SegmentInput> in1{input_with_rate(1.0), input_with_rate(1.2), input_with_rate(1.3)};
    const std::vector<ChainTrack> tracks{{sync0, t0, in0}, {sync1, t1, in1}, {}};
    const ChainRows rows = chain_rows(tracks);

    ASSERT_EQ(rows.sync, (std::vector<std::uint64_t>{10, 11, 12, 13}));
    EXPECT_EQ(rows.t_us, (std::vector<std::int64_t>{1000, 2000, 2000, 4000}));
    ASSERT_EQ(rows.in.size(), 4u * 3u);
    ASSERT_EQ(rows.row_of.size(), 3u);
    EXPECT_EQ(rows.row_of[0], (std::vector<std::size_t>{0, 1, 2, 3}));
    EXPECT_EQ(rows.row_of[1], (std::vector<std::size_t>{0, 2, 3}));
    EXPECT_TRUE(rows.row_of[2].empty());
    const auto at = [&](std::size_t row, std::size_t segment) { return rows.in[row * 3 + segment]; };
    for (std::size_t r = 0; r < 4; ++r) {
        EXPECT_TRUE(at(r, 0).fresh) << r;
        EXPECT_DOUBLE_EQ(at(r, 0).gyro_rad_s.z(), 0.1 * static_cast<double>(r)) << r;
        EXPECT_FALSE(at(r, 2).fresh) << "a segment without samples is never fresh";
        EXPECT_EQ(at(r, 2).gyro_rad_s, math::Vec3::Zero());
    }
    EXPECT_TRUE(at(0, 1).fresh);
    EXPECT_FALSE(at(1, 1).fresh) << "missing at SYNC 11";
    EXPECT_DOUBLE_EQ(at(1, 1).gyro_rad_s.z(), 1.0) << "holds its previous input";
    EXPECT_TRUE(at(2, 1).fresh);
    EXPECT_DOUBLE_EQ(at(2, 1).gyro_rad_s.z(), 1.2);
}

TEST(ChainRows, ASegmentThatStartsLateIsNotFreshBeforeItsFirstSample) {
    const std::vector<std::uint64_t> sync0{1, 2, 3}, sync1{3};
    const std::vector<std::int64_t> t0{10, 20, 30}, t1{31};
    const std::vector<fusion::SegmentInput> in0(3, input_with_rate(0.5)), in1{input_with_rate(2.0)};
    const std::vector<ChainTrack> tracks{{sync0, t0, in0}, {sync1, t1, in1}};
    const ChainRows rows = chain_rows(tracks);
    ASSERT_EQ(rows.sync.size(), 3u);
    EXPECT_FALSE(rows.in[0 * 2 + 1].fresh);
    EXPECT_FALSE(rows.in[1 * 2 + 1].fresh);
    EXPECT_TRUE(rows.in[2 * 2 + 1].fresh);
    EXPECT_EQ(rows.row_of[1], (std::vector<std::size_t>{2}));
}

TEST(BodyChainJoints, AxesFromTheCalibrationsMountingsOtherwiseHingesLearnThem) {
    const skeleton::BodyModel model = skeleton::default_body_model(1.75, "mocap");
    const std::vector<skeleton::BodyJoint> body = skeleton::body_joints(model);
    const skeleton::FusionOptions model_axes{};

    // No calibration: no joint has axes, every hinge learns them, every joint its centre.
    std::vector<fusion::JointDef> defs = body_chain_joints(model, model_axes, nullptr);
    ASSERT_EQ(defs.size(), body.size());
    std::size_t hinges = 0;
    for (std::size_t j = 0; j < defs.size(); ++j) {
        EXPECT_EQ(defs[j].parent, body[j].def.parent);
        EXPECT_EQ(defs[j].child, body[j].def.child);
        EXPECT_EQ(defs[j].type, body[j].def.type);
        EXPECT_FALSE(defs[j].axes_known) << j;
        EXPECT_EQ(defs[j].estimate_axes, defs[j].type == fusion::JointType::kHinge) << j;
        EXPECT_TRUE(defs[j].estimate_centre && !defs[j].centre_known) << j;
        hinges += defs[j].type == fusion::JointType::kHinge ? 1 : 0;
    }
    EXPECT_EQ(hinges, 2u) << "the knees";
    EXPECT_TRUE(fusion::ChainEstimator::check(model.size(), defs).empty());

    // A calibration of every segment but the right hand, with mountings off the segment axes.
    skeleton::Calibration cal;
    cal.segment_count = model.size();
    std::mt19937_64 rng(7);
    std::normal_distribution<double> n01;
    for (std::size_t s = 0; s < model.size(); ++s) {
        cal.q_sensor_segment[s] = math::Quat(1.0, 0.3 * n01(rng), 0.3 * n01(rng), 0.3 * n01(rng)).normalized();
        cal.calibrated[s] = model.segments[s].name != skeleton::seg::kRightHand;
    }
    defs = body_chain_joints(model, model_axes, &cal);
    for (std::size_t j = 0; j < defs.size(); ++j) {
        const auto p = static_cast<std::size_t>(defs[j].parent), c = static_cast<std::size_t>(defs[j].child);
        const bool ball = defs[j].type == fusion::JointType::kBall;
        const bool expect_axes = !ball && cal.calibrated[p] && cal.calibrated[c];
        ASSERT_EQ(defs[j].axes_known, expect_axes) << model.segments[c].name;
        EXPECT_FALSE(defs[j].estimate_axes) << "axis = model: the calibration's axes are kept";
        if (!expect_axes) continue;
        // j_sensor = q_sensor_segment ⊗ j_segment: the axis turned into each sensor's frame.
        const math::Vec3 ap = math::rotate(cal.q_sensor_segment[p], body[j].axis_parent_segment);
        const math::Vec3 ac = math::rotate(cal.q_sensor_segment[c], body[j].axis_child_segment);
        EXPECT_NEAR((defs[j].axis_parent - ap).norm(), 0.0, 1e-12) << model.segments[c].name;
        EXPECT_NEAR((defs[j].axis_child - ac).norm(), 0.0, 1e-12) << model.segments[c].name;
        EXPECT_GT((defs[j].axis_parent - body[j].axis_parent_segment).norm(), 1e-3) << "not the segment axis";
    }
    EXPECT_TRUE(fusion::ChainEstimator::check(model.size(), defs).empty());

    // [fusion] axis = "estimate": the hinges learn theirs even with a calibration.
    skeleton::FusionOptions estimate{};
    estimate.estimate_axes = true;
    defs = body_chain_joints(model, estimate, &cal);
    for (const fusion::JointDef& d : defs) {
        EXPECT_EQ(d.estimate_axes, d.type == fusion::JointType::kHinge);
        if (d.type == fusion::JointType::kHinge) {
            EXPECT_TRUE(d.axes_known) << "the calibration's as the start";
        }
    }
}

/// One sensor turning about a tilted axis at 1 rad/s with a constant gyro bias, in a clean
/// field: its readings at 100 Hz.
std::vector<ImuSample> turning_sensor(const math::Vec3& bias_rad_s, bool with_mag,
                                      std::vector<math::Quat>* truth = nullptr) {
    const math::Vec3 w = math::Vec3(0.3, -0.2, 1.0).normalized();  // rad/s, sensor frame
    const math::Vec3 g(0.0, 0.0, 9.81), m(0.0, 50.0 * std::cos(60.0 * kDeg), -50.0 * std::sin(60.0 * kDeg));
    std::vector<ImuSample> out;
    math::Quat q = math::Quat(Eigen::AngleAxisd(0.4, math::Vec3::UnitX()));
    for (int k = 0; k < 1500; ++k) {
        ImuSample s;
        s.t_us = 5'000'000 + 10'000 * static_cast<std::int64_t>(k);
        const math::Vec3 f = math::rotate(q.conjugate(), g), b = math::rotate(q.conjugate(), m);
        const math::Vec3 rate = (k < 300 ? 0.0 : 1.0) * w + bias_rad_s;  // 3 s still, then turning
        s.gyro_rad_s = {rate.x(), rate.y(), rate.z()};
        s.accel_m_s2 = {f.x(), f.y(), f.z()};
        s.mag_ut = {b.x(), b.y(), b.z()};
        if (!with_mag) s.flags |= kImuNoMag;
        out.push_back(s);
        if (truth) truth->push_back(q);
        if (k >= 300) q = (q * math::quat_from_rotvec(w * 0.01)).normalized();
    }
    return out;
}

TEST(OfflineSegmentInputs, SixDFrameRateWithoutBiasAndTheFieldsHeading) {
    const math::Vec3 bias(0.02, -0.015, 0.01);
    std::vector<math::Quat> truth;
    const std::vector<ImuSample> samples = turning_sensor(bias, true, &truth);
    std::string error;
    auto f = filter::make_filter("mocap", {}, &error);
    ASSERT_TRUE(f) << error;
    const filter::OfflineSmoother smoother;
    const std::vector<fusion::SegmentInput> in = offline_segment_inputs(smoother, *f, samples);
    ASSERT_EQ(in.size(), samples.size());
    // The re-solve with the field, as the smoother gives it (a fresh filter: bit-identical).
    auto f9 = filter::make_filter("mocap", {}, &error);
    ASSERT_TRUE(f9) << error;
    const filter::OfflineResult r9 = smoother.smooth(*f9, samples);
    math::Vec3 removed = math::Vec3::Zero(), residual = math::Vec3::Zero();
    double worst_q9_deg = 0.0;
    std::size_t trusted = 0;
    for (std::size_t k = 0; k < in.size(); ++k) {
        const fusion::SegmentInput& x = in[k];
        ASSERT_TRUE(x.fresh);
        ASSERT_TRUE(x.mag_available);
        trusted += x.mag_trusted ? 1 : 0;
        EXPECT_EQ(x.accel_m_s2, math::to_vec3(samples[k].accel_m_s2));
        const math::Vec3 raw = math::to_vec3(samples[k].gyro_rad_s);
        removed += raw - x.gyro_rad_s;
        if (k > 0) {
            // The rate left is the 6D frame's own motion, on average exactly.
            const math::Vec3 w6 = math::rotvec_from_quat(in[k - 1].q6.conjugate() * x.q6) / 0.01;
            residual += x.gyro_rad_s - w6;
        }
        // Rz(d) ⊗ q6 is the re-solve with the field; the two solves' inclinations differ a
        // little (measured 0.21° at most on this sensor).
        const math::Quat q9 =
            (math::Quat(std::cos(0.5 * x.mag_heading_rad), 0.0, 0.0, std::sin(0.5 * x.mag_heading_rad)) * x.q6)
                .normalized();
        worst_q9_deg = std::max(worst_q9_deg, math::error_total_rad(q9 * r9.orientation[k].conjugate()) / kDeg);
    }
    removed /= static_cast<double>(in.size());
    residual /= static_cast<double>(in.size() - 1);
    EXPECT_LT(residual.norm(), 1e-9) << "one constant bias: what the raw rate has beyond the 6D motion";
    // That is the bias the 6D re-solve learned, which sees the vertical part only while the
    // sensor rests (the first 3 s): within 0.015 rad/s of the true 0.027 (measured 0.011).
    EXPECT_LT((removed - bias).norm(), 0.015) << removed.transpose();
    EXPECT_LT(worst_q9_deg, 0.5);
    EXPECT_GT(trusted, in.size() * 9 / 10);
    // The field through its 0.5 s low-pass: exact at rest; turning at 1 rad/s the sensor-frame
    // low-pass shortens and tilts it (measured 49.6 µT, 62.3°).
    EXPECT_NEAR(in[299].field_norm_ut, 50.0, 0.1);
    EXPECT_NEAR(in[299].field_dip_rad / kDeg, 60.0, 0.1);
    EXPECT_NEAR(in.back().field_norm_ut, 50.0, 1.0);
    EXPECT_NEAR(in.back().field_dip_rad / kDeg, 60.0, 3.0);

    // Without a field: no magnetometer heading, the same 6D frame's rates.
    const std::vector<ImuSample> no_mag = turning_sensor(bias, false);
    const std::vector<fusion::SegmentInput> in6 = offline_segment_inputs(smoother, *f, no_mag);
    ASSERT_EQ(in6.size(), no_mag.size());
    for (const fusion::SegmentInput& x : in6) {
        EXPECT_FALSE(x.mag_available);
        EXPECT_EQ(x.field_norm_ut, 0.0);
    }
}

}  // namespace
}  // namespace mocap::pipeline
