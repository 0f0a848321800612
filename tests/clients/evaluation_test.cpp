// Error metrics against hand-computed values, the JSON line, and run_filter's bookkeeping.
#include "filter_tool/evaluation.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "filter_tool/filter_run.hpp"

namespace mocap::tools {
namespace {

using math::Vec3;

constexpr double kDeg = std::numbers::pi / 180.0;

Quat about(const Vec3& axis, double deg) {
    return Quat(Eigen::AngleAxisd(deg * kDeg, axis.normalized()));
}

EvalSample sample(double t_s, const Quat& est, const Quat& ref, bool evaluated = true) {
    EvalSample s;
    s.t_s = t_s;
    s.q_est = est;
    s.q_ref = ref;
    s.evaluated = evaluated;
    return s;
}

TEST(Evaluation, PureHeadingError) {
    // 10° about the vertical: all of it is heading and yaw, none inclination/roll/pitch.
    const Quat ref = math::from_euler_zyx({0.0, 0.0, 30.0 * kDeg});
    const Quat est = about(Vec3::UnitZ(), 10.0) * ref;
    const std::vector<EvalSample> s = {sample(0.0, est, ref)};
    const EvalResult r = evaluate(s);
    EXPECT_EQ(r.samples, 1u);
    EXPECT_NEAR(r.rmse_total_deg, 10.0, 1e-9);
    EXPECT_NEAR(r.rmse_heading_deg, 10.0, 1e-9);
    EXPECT_NEAR(r.rmse_inclination_deg, 0.0, 1e-6);
    EXPECT_NEAR(r.rmse_yaw_deg, 10.0, 1e-9);
    EXPECT_NEAR(r.rmse_roll_deg, 0.0, 1e-9);
    EXPECT_NEAR(r.rmse_pitch_deg, 0.0, 1e-9);
}

TEST(Evaluation, PureInclinationErrorAndRms) {
    // Errors of 3° and 4° about the earth x axis: RMSE = sqrt((9 + 16) / 2) = 3.5355339°.
    const Quat ref = Quat::Identity();
    const std::vector<EvalSample> s = {sample(0.0, about(Vec3::UnitX(), 3.0), ref),
                                       sample(0.01, about(Vec3::UnitX(), -4.0), ref)};
    const EvalResult r = evaluate(s);
    EXPECT_EQ(r.samples, 2u);
    EXPECT_NEAR(r.rmse_total_deg, 3.5355339059, 1e-8);
    EXPECT_NEAR(r.rmse_inclination_deg, 3.5355339059, 1e-8);
    EXPECT_NEAR(r.rmse_heading_deg, 0.0, 1e-9);
    EXPECT_NEAR(r.rmse_roll_deg, 3.5355339059, 1e-8);
    EXPECT_NEAR(r.max_total_deg, 4.0, 1e-9);
}

TEST(Evaluation, CombinedErrorSplitsIntoHeadingAndInclination) {
    // q_err = Rz(20°) ⊗ Rx(15°): w = cos10·cos7.5, z = sin10·cos7.5.
    const Quat err = about(Vec3::UnitZ(), 20.0) * about(Vec3::UnitX(), 15.0);
    const std::vector<EvalSample> s = {sample(0.0, err, Quat::Identity())};
    const EvalResult r = evaluate(s);
    const double w = std::cos(10 * kDeg) * std::cos(7.5 * kDeg);
    const double z = std::sin(10 * kDeg) * std::cos(7.5 * kDeg);
    EXPECT_NEAR(r.rmse_total_deg, 2.0 * std::acos(w) / kDeg, 1e-9);
    EXPECT_NEAR(r.rmse_heading_deg, 20.0, 1e-9);  // 2·atan(|z/w|) = 2·10°
    EXPECT_NEAR(r.rmse_inclination_deg, 2.0 * std::acos(std::sqrt(w * w + z * z)) / kDeg, 1e-9);
    EXPECT_NEAR(r.rmse_inclination_deg, 15.0, 1e-9);
}

TEST(Evaluation, YawErrorIsWrapped) {
    const Quat ref = math::from_euler_zyx({0.0, 0.0, -179.0 * kDeg});
    const Quat est = math::from_euler_zyx({0.0, 0.0, 179.0 * kDeg});
    const std::vector<EvalSample> s = {sample(0.0, est, ref)};
    EXPECT_NEAR(evaluate(s).rmse_yaw_deg, 2.0, 1e-9);
}

TEST(Evaluation, SignOfQuaternionDoesNotMatter) {
    const Quat ref = about(Vec3(1, 2, 3), 50.0);
    Quat est = about(Vec3::UnitY(), 5.0) * ref;
    est.coeffs() = -est.coeffs();
    const std::vector<EvalSample> s = {sample(0.0, est, ref)};
    const EvalResult r = evaluate(s);
    EXPECT_NEAR(r.rmse_total_deg, 5.0, 1e-9);
    EXPECT_NEAR(r.rmse_inclination_deg, 5.0, 1e-9);
}

TEST(Evaluation, MaskAndMissingReferenceAreExcluded) {
    const Quat ref = Quat::Identity();
    std::vector<EvalSample> s = {sample(0.0, about(Vec3::UnitX(), 90.0), ref, false),
                                 sample(1.0, about(Vec3::UnitX(), 2.0), ref, true),
                                 sample(2.0, about(Vec3::UnitX(), 80.0), ref, true)};
    s[2].has_reference = false;
    const EvalResult r = evaluate(s);
    EXPECT_EQ(r.samples, 1u);
    EXPECT_NEAR(r.rmse_total_deg, 2.0, 1e-9);
    const EvalResult none = evaluate(std::vector<EvalSample>{sample(0.0, ref, ref, false)});
    EXPECT_EQ(none.samples, 0u);
    EXPECT_EQ(none.rmse_total_deg, 0.0);
}

TEST(Evaluation, ConvergenceTimeIsAfterTheLastExcursion) {
    const Quat ref = Quat::Identity();
    const double errs[] = {30.0, 20.0, 5.0, 15.0, 5.0, 5.0};
    std::vector<EvalSample> s;
    for (int i = 0; i < 6; ++i)
        s.push_back(sample(10.0 + i, about(Vec3::UnitZ(), errs[i]), ref, false));
    const EvalResult r = evaluate(s);
    ASSERT_TRUE(r.convergence_time_s.has_value());
    EXPECT_DOUBLE_EQ(*r.convergence_time_s, 4.0);  // relative to the first sample (t = 10)
    ASSERT_TRUE(r.first_below_s.has_value());
    EXPECT_DOUBLE_EQ(*r.first_below_s, 2.0);
    // Still above at the end: never converged.
    s.back().q_est = about(Vec3::UnitZ(), 11.0);
    EXPECT_FALSE(evaluate(s).convergence_time_s.has_value());
    EXPECT_DOUBLE_EQ(evaluate(s).first_below_s.value(), 2.0);
    EXPECT_FALSE(evaluate(s, 4.0).first_below_s.has_value());
    // Always below: converged from the start.
    for (auto& x : s)
        x.q_est = ref;
    EXPECT_DOUBLE_EQ(evaluate(s).convergence_time_s.value(), 0.0);
    // A custom threshold.
    for (int i = 0; i < 6; ++i)
        s[static_cast<std::size_t>(i)].q_est = about(Vec3::UnitZ(), errs[i]);
    EXPECT_DOUBLE_EQ(evaluate(s, 25.0).convergence_time_s.value(), 1.0);
}

TEST(Evaluation, JsonHasTheContractKeys) {
    EvalResult r;
    r.samples = 42;
    r.rmse_total_deg = 1.5;
    r.rmse_heading_deg = 1.25;
    r.convergence_time_s = 3.5;
    r.first_below_s = 0.25;
    const std::string j = eval_json(r, "ma\"d");
    for (const char* key : {"\"rmse_total_deg\":1.5", "\"rmse_heading_deg\":1.25", "\"rmse_inclination_deg\":0",
                            "\"rmse_roll_deg\":0", "\"rmse_pitch_deg\":0", "\"rmse_yaw_deg\":0", "\"samples\":42",
                            "\"convergence_time_s\":3.5", "\"first_below_s\":0.25", "\"filter\":\"ma\\\"d\""}) {
        EXPECT_NE(j.find(key), std::string::npos) << key << " in " << j;
    }
    EXPECT_EQ(j.front(), '{');
    EXPECT_EQ(j.back(), '}');
    r.convergence_time_s.reset();
    r.first_below_s.reset();
    EXPECT_NE(eval_json(r, "x").find("\"convergence_time_s\":null"), std::string::npos);
    EXPECT_NE(eval_json(r, "x").find("\"first_below_s\":null"), std::string::npos);
}

// A filter that reports a fixed orientation, to check run_filter's frame and masks.
class FixedFilter final : public filter::OrientationFilter {
public:
    explicit FixedFilter(const Quat& q) : q_(q) {}
    void update(const ImuSample&) override { ++updates_; }
    [[nodiscard]] Quat orientation() const override { return q_; }
    void reset() override { updates_ = 0; }
    [[nodiscard]] std::string_view name() const override { return "fixed"; }
    int updates_ = 0;

private:
    Quat q_;
};

TEST(FilterRun, SkipWindowMovementMaskAndNedOutput) {
    Recording rec;
    rec.has_reference = true;
    rec.has_movement = true;
    for (int i = 0; i < 10; ++i) {
        RecordingRow row;
        row.sample.t_us = 2'000'000 + i * 1'000'000;  // t = 2 .. 11 s
        row.q_ref = math::q_enu_ned();                // NED reference of an ENU-identity sensor
        row.ref_valid = true;
        row.movement = i != 7;
        rec.rows.push_back(row);
    }
    FixedFilter f(Quat::Identity());
    const RunOutput enu = run_filter(f, rec, {EarthFrame::enu, 3.0});
    EXPECT_EQ(f.updates_, 10);
    ASSERT_EQ(enu.estimates.size(), 10u);
    EXPECT_EQ(enu.estimates[4].t_us, 6'000'000);
    // Evaluated: t - 2 >= 3 (i >= 3) and movement (i != 7): 6 samples.
    EXPECT_EQ(evaluate(enu.compared).samples, 6u);
    // In ENU the identity estimate is 180° from the q_enu_ned reference; in NED it is exact.
    EXPECT_NEAR(evaluate(enu.compared).rmse_total_deg, 180.0, 1e-6);
    const RunOutput ned = run_filter(f, rec, {EarthFrame::ned, 0.0});
    EXPECT_NEAR(evaluate(ned.compared).rmse_total_deg, 0.0, 1e-6);
    EXPECT_NEAR(math::angle_rad(ned.estimates[0].q * math::conj(math::q_enu_ned())), 0.0, 1e-12);
    EXPECT_EQ(evaluate(ned.compared).samples, 9u);
}

TEST(FilterRun, FrameNames) {
    EXPECT_EQ(parse_earth_frame("enu"), EarthFrame::enu);
    EXPECT_EQ(parse_earth_frame("ned"), EarthFrame::ned);
    EXPECT_FALSE(parse_earth_frame("NED").has_value());
}

}  // namespace
}  // namespace mocap::tools
