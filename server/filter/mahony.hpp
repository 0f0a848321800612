// mahony.hpp — Mahony's explicit complementary filter (Mahony, Hamel & Pflimlin 2008) with
// proportional-integral feedback, the published formulation, as a baseline.
//
// The correction is the sum of cross products between the measured accelerometer
// (and magnetometer) directions and the directions the estimate predicts; kp feeds it back
// onto the gyro rate, ki integrates it into a gyroscope-bias estimate. Without a
// magnetometer reading only the accelerometer term is used. Like Madgwick's formulation
// it works in a north-west-up earth frame internally and reports ENU.
//
// Thread-safety: none (one instance per worker). Cost: ~100 ns per update, no allocation.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "filter/orientation_filter.hpp"

namespace mocap::filter {

struct MahonyParams {
    double kp = 1.0;                     ///< key "kp": proportional gain, rad/s per unit direction error
    double ki = 0.02;                    ///< key "ki": integral gain, rad/s² per unit direction error (0 disables
                                         ///< the bias estimate)
    double bias_clip_rad_s = 0.035;      ///< key "bias_clip_rad_s": |bias| limit per axis, rad/s (2 °/s)
    bool init_from_first_sample = true;  ///< key "init_from_first_sample": closed-form attitude from the first
                                         ///< sample; false starts at identity (ENU)
    double max_step_s = 0.5;             ///< key "max_step_s": larger timestamp steps restart the time base, s

    /// Empty if every value is usable, else a message naming the first bad key.
    [[nodiscard]] std::string check() const;
};

struct MahonyState {
    math::Quat q_nwu_sensor = math::Quat::Identity();  ///< estimate in the algorithm's north-west-up frame
                                                       ///< (reset() sets the ENU identity)
    math::Vec3 integral_rad_s = math::Vec3::Zero();    ///< integral feedback (= minus the gyro bias estimate)
    bool initialised = false;
    SampleClock clock = SampleClock(0.5);  ///< time base (max step set from Params)
};

class MahonyFilter final : public OrientationFilter {
public:
    explicit MahonyFilter(const MahonyParams& params = {});

    void update(const ImuSample& sample) override;
    [[nodiscard]] math::Quat orientation() const override;
    [[nodiscard]] math::Vec3 gyro_bias_rad_s() const override { return -state_.integral_rad_s; }
    void reset() override;
    [[nodiscard]] std::string_view name() const override { return "mahony"; }
    [[nodiscard]] std::uint64_t gaps() const override { return state_.clock.gaps(); }

    [[nodiscard]] const MahonyParams& params() const { return params_; }
    [[nodiscard]] const MahonyState& state() const { return state_; }

private:
    MahonyParams params_;
    MahonyState state_;
};

}  // namespace mocap::filter
