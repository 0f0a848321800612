// madgwick.hpp — Madgwick's gradient-descent MARG filter (Madgwick, Harrison & Vaidyanathan
// 2011), the published formulation, as a baseline.
//
// The gyroscope rate is integrated and corrected each sample by one normalised gradient
// step of the accelerometer (and, when the sample has a magnetometer reading, magnetometer)
// alignment error, scaled by beta. Without a magnetometer reading the 6-axis (IMU) form is
// used. The published algorithm works in an earth frame whose x axis is the horizontal
// magnetic field and z is up (north-west-up); the estimate is kept in that frame and
// reported in ENU. It does not estimate gyroscope bias.
//
// Thread-safety: none (one instance per worker). Cost: ~100 ns per update, no allocation.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "filter/orientation_filter.hpp"

namespace mocap::filter {

struct MadgwickParams {
    double beta = 0.041;                 ///< key "beta": gradient step gain, rad/s (the paper's MARG value
                                         ///< sqrt(3/4)·gyro error of 2.7 °/s; larger trusts accel/mag more)
    bool init_from_first_sample = true;  ///< key "init_from_first_sample": take the first sample's attitude in closed
                                         ///< form from accel + mag; false starts at identity (ENU)
    double max_step_s = 0.5;             ///< key "max_step_s": larger timestamp steps restart the time base, s

    /// Empty if every value is usable, else a message naming the first bad key.
    [[nodiscard]] std::string check() const;
};

struct MadgwickState {
    math::Quat q_nwu_sensor = math::Quat::Identity();  ///< estimate in the algorithm's north-west-up frame
                                                       ///< (reset() sets the ENU identity)
    bool initialised = false;                          ///< attitude taken from a first sample
    SampleClock clock = SampleClock(0.5);              ///< time base (max step set from Params)
};

class MadgwickFilter final : public OrientationFilter {
public:
    explicit MadgwickFilter(const MadgwickParams& params = {});

    void update(const ImuSample& sample) override;
    [[nodiscard]] math::Quat orientation() const override;
    void reset() override;
    [[nodiscard]] std::string_view name() const override { return "madgwick"; }
    [[nodiscard]] std::uint64_t gaps() const override { return state_.clock.gaps(); }

    [[nodiscard]] const MadgwickParams& params() const { return params_; }
    [[nodiscard]] const MadgwickState& state() const { return state_; }

private:
    MadgwickParams params_;
    MadgwickState state_;
};

}  // namespace mocap::filter
