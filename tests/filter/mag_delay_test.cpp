#include "filter/mag_delay.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "seed_filter_fixture.hpp"

namespace mocap::filter {
namespace {

std::vector<ImuSample> lagged_turning(int lag_ms, double duration_s) {
    std::vector<ImuSample> out;
    for (const sim::ScenarioRow& r : testing::turning_with_late_field(lag_ms, duration_s))
        out.push_back(r.sample);
    return out;
}

MagDelayTracker track(const std::vector<ImuSample>& samples) {
    MagDelayTracker tracker;
    const double forgetting = std::exp(-0.01 / 60.0);
    for (std::size_t i = 0; i < samples.size(); ++i) {
        const double dt_s = i == 0 ? 0.0 : static_cast<double>(samples[i].t_us - samples[i - 1].t_us) * 1e-6;
        tracker.update(math::to_vec3(samples[i].gyro_rad_s), math::to_vec3(samples[i].mag_ut), true, dt_s, true,
                       forgetting);
    }
    return tracker;
}

TEST(MagDelayTracker, LearnsAKnownLagOnline) {
    const MagDelayTracker t = track(lagged_turning(20, 30.0));
    ASSERT_TRUE(t.converged()) << t.std_error_s();
    // Measured 20.02 ms (noiseless readings; the linearisation in the lag and the 20 ms wide
    // central differences leave a little).
    EXPECT_NEAR(t.estimate_s(), 0.020, 0.001);
    EXPECT_DOUBLE_EQ(t.delay_s(0.05), t.estimate_s());
    EXPECT_DOUBLE_EQ(t.delay_s(0.015), 0.015);  // clamped to the bound
}

TEST(MagDelayTracker, LearnsNoLagWhereThereIsNone) {
    const MagDelayTracker t = track(lagged_turning(0, 30.0));
    ASSERT_TRUE(t.converged());
    EXPECT_NEAR(t.estimate_s(), 0.0, 0.001);
    EXPECT_LT(t.delay_s(0.05), 0.001);
}

TEST(MagDelayTracker, TakesNothingOutBeforeItConverges) {
    // A still sensor says nothing about the lag.
    std::vector<ImuSample> still;
    for (const auto& r : testing::constant_rate(math::Quat::Identity(), math::Vec3::Zero(), 100.0, 10.0))
        still.push_back(r.sample);
    const MagDelayTracker t = track(still);
    EXPECT_FALSE(t.converged());
    EXPECT_EQ(t.std_error_s(), std::numeric_limits<double>::infinity());
    EXPECT_EQ(t.delay_s(0.05), 0.0);
    // A third of a second of turning is not enough either, although it already has an estimate.
    const MagDelayTracker early = track(lagged_turning(20, 0.35));
    EXPECT_FALSE(early.converged()) << early.std_error_s();
    EXPECT_EQ(early.delay_s(0.05), 0.0);
    // Samples declared unusable (a disturbed field) never enter.
    MagDelayTracker gated;
    const std::vector<ImuSample> s = lagged_turning(20, 10.0);
    for (std::size_t i = 1; i < s.size(); ++i)
        gated.update(math::to_vec3(s[i].gyro_rad_s), math::to_vec3(s[i].mag_ut), true, 0.01, false, 1.0);
    EXPECT_EQ(gated.estimate_s(), 0.0);
    EXPECT_FALSE(gated.converged());
}

TEST(MagDelay, MagAheadTurnsTheReadingWithTheSensor) {
    // A sensor turning at a constant rate: the reading 20 ms ahead is the truth 20 ms later.
    const math::Vec3 w(0.5, -1.0, 3.0);
    const auto rows = testing::constant_rate(math::from_euler_zyx({0.3, 0.1, -0.2}), w, 100.0, 1.0);
    const math::Vec3 ahead = mag_ahead(math::to_vec3(rows[10].sample.mag_ut), w, 0.02);
    EXPECT_LT((ahead - math::to_vec3(rows[12].sample.mag_ut)).norm(), 1e-9);
    EXPECT_EQ(mag_ahead(math::to_vec3(rows[10].sample.mag_ut), w, 0.0), math::to_vec3(rows[10].sample.mag_ut));
}

}  // namespace
}  // namespace mocap::filter
