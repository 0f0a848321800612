// orientation_filter.hpp — the one interface every orientation filter implements.
//
// A filter is Params + State (+ derived coefficients), no I/O, no clock (docs/style.md,
// "Params and State" and "Inject time"): the time step comes from the samples' own
// timestamps. One instance estimates one sensor's q_earth_sensor in ENU (x east, y north,
// z up); callers that want NED convert with q_enu_ned() (quaternion.hpp).
//
// Thread-safety: an instance is not thread-safe; the pipeline pins each instance to
// one worker. Cost: documented per filter (tens of ns to µs per update).
#pragma once

#include <cstdint>
#include <string_view>

#include "core/imu_sample.hpp"
#include "math/quaternion.hpp"

namespace mocap::filter {

/// Why an estimate is what it is, sample by sample (mocap-filter --trace). Filters that do
/// not detect a condition leave its flag false.
struct FilterDiagnostics {
    bool rest = false;                              ///< the sensor is taken to be at rest (bias learning)
    bool mag_field_disturbed = false;               ///< field norm / dip off their learned references
    bool mag_heading_disturbed = false;             ///< field heading disagrees with the gyro-propagated one
    bool mag_rejected = false;                      ///< magnetometer not used, or down-weighted, for heading
    double mag_offset_weight = 0.0;                 ///< share of mag_offset_ut subtracted from readings, 0..1
    math::Vec3 mag_offset_ut = math::Vec3::Zero();  ///< field offset fixed to the sensor, µT
};

/// An estimate split into a 6D part and a heading correction about the vertical, for the
/// body-aware chain stage (fusion/chain_estimator.hpp), which replaces the correction.
struct HeadingSplit {
    math::Quat q6 = math::Quat::Identity();  ///< inclination, and a heading the gyro alone keeps
    double mag_heading_rad = 0.0;            ///< orientation() = Rz(mag_heading_rad) ⊗ q6
    bool has_mag_heading = false;            ///< the filter corrects its heading from the field
    bool mag_trusted = false;                ///< ... uses the field now (not rejected) and, after a
                                             ///< rejection, its heading is back on the field
    double field_norm_ut = 0.0;              ///< the field it sees, filtered (0: unknown)
    double field_heading_rad = 0.0;          ///< the field's own heading in q6's frame, low-passed
                                             ///< briefly: where mag_heading_rad converges to, without
                                             ///< the lag of the filter's heading correction
    bool field_usable = false;               ///< the field keeps its norm and dip (not disturbed), even
                                             ///< where the filter holds its heading on the gyro
    double field_dip_rad = 0.0;              ///< its dip, positive down
    std::uint32_t frame_epoch = 0;           ///< changes when q6's heading frame starts again (the
                                             ///< filter restarted its attitude after a gap)
};

class OrientationFilter {
public:
    virtual ~OrientationFilter() = default;

    /// Feeds one sample. The first sample after construction or reset() only sets the
    /// time base (filters that self-initialise also take their initial attitude from it).
    /// A timestamp that does not advance, or jumps by more than the filter's max gap,
    /// restarts the time base without propagating (counted in gaps()).
    virtual void update(const ImuSample& sample) = 0;

    /// Current estimate q_earth_sensor (ENU), unit norm.
    [[nodiscard]] virtual math::Quat orientation() const = 0;

    /// Current gyroscope bias estimate, rad/s, sensor frame (zero if not estimated).
    [[nodiscard]] virtual math::Vec3 gyro_bias_rad_s() const { return math::Vec3::Zero(); }

    /// Disturbance and rest flags of the last update (all false if the filter has none).
    [[nodiscard]] virtual FilterDiagnostics diagnostics() const { return {}; }

    /// The estimate as a 6D part and a magnetometer heading correction. A filter that does not
    /// separate them reports its whole estimate as q6 (has_mag_heading false).
    [[nodiscard]] virtual HeadingSplit heading_split() const {
        HeadingSplit s;
        s.q6 = orientation();
        return s;
    }

    /// Returns the filter to its freshly constructed state (Params kept).
    virtual void reset() = 0;

    /// Short stable name used on command lines and in config ("csmo", "pf", ...).
    [[nodiscard]] virtual std::string_view name() const = 0;

    /// Number of time-base restarts (non-advancing or too-large timestamp steps).
    [[nodiscard]] virtual std::uint64_t gaps() const { return 0; }
};

/// Turns successive sample timestamps into time steps. Part of each filter's State.
class SampleClock {
public:
    /// max_step_s: a larger step is treated as a gap (no propagation).
    explicit SampleClock(double max_step_s = 0.5) : max_step_s_(max_step_s) {}

    /// Returns dt in seconds, or 0 on the first sample and on a gap.
    double step_s(std::int64_t t_us) {
        if (!started_) {
            started_ = true;
            last_us_ = t_us;
            return 0.0;
        }
        const std::int64_t d_us = t_us - last_us_;
        last_us_ = t_us;
        const double dt = static_cast<double>(d_us) * 1e-6;
        skipped_ = d_us > 0 && dt > max_step_s_;
        if (d_us <= 0 || skipped_) {
            ++gaps_;
            return 0.0;
        }
        return dt;
    }
    void reset() {
        started_ = false;
        skipped_ = false;
        last_us_ = 0;
        gaps_ = 0;
    }
    [[nodiscard]] bool started() const { return started_; }
    /// The last step went forward by more than max_step_s: time the samples do not cover.
    [[nodiscard]] bool skipped() const { return skipped_; }
    [[nodiscard]] std::uint64_t gaps() const { return gaps_; }

private:
    double max_step_s_;
    bool started_ = false;
    bool skipped_ = false;
    std::int64_t last_us_ = 0;
    std::uint64_t gaps_ = 0;
};

}  // namespace mocap::filter
