// calibration.hpp — sensor-to-segment calibration from a known still pose, heading
// alignment, stillness detection, and the saved text form.
//
// Model (Li et al.): q_gr = q_gs ⊗ q_rs', i.e. the segment's orientation is the sensor's
// orientation times a constant mounting rotation. Here
//     q_earth_segment = q_earth_sensor ⊗ q_sensor_segment
// and the output ("world") frame is q_world_segment = q_world_earth ⊗ q_earth_segment.
//
// Calibration. The subject stands still in a known pose facing a known heading ψ (the
// angle of the subject's forward direction from earth +x toward +y, about up; in ENU
// 0 = facing east, π/2 = facing north). The expected segment orientation is then
//     q_earth_segment* = Rz(ψ) ⊗ q_body_segment(pose)
// and with the averaged sensor orientation q̄_earth_sensor (Markley average over the still
// period, math/markley_average.hpp)
//     q_sensor_segment = conj(q̄_earth_sensor) ⊗ q_earth_segment*.
//
// Poses (segment frames: body_model.hpp; x forward, y left, z up, identity in the T-pose):
//   T-pose: every segment identity (arms horizontal, palms down, feet forward).
//   N-pose: standing, arms hanging at the sides, palms facing the thighs: every segment in
//           the subtree of "left_upper_arm" is Rx(-90°) (its +y long axis turned to -z),
//           in the subtree of "right_upper_arm" Rx(+90°); the rest identity.
//   Custom: the caller supplies q_body_segment for every segment.
//
// Heading (CalibrationOptions::heading_mode):
//   kAlignToForward (default): q_world_earth = Rz(-ψ): the output skeleton faces world +x
//     in the calibration pose, wherever the subject faced; later turns still show.
//   kKeepEarth: q_world_earth = identity: output in the earth frame (ENU), true heading.
// ψ comes from CalibrationOptions::facing_source: kGiven (facing_heading_rad, e.g. from
// config or the simulator), or kFromSensorAxis (the horizontal projection of a chosen
// sensor axis of a chosen segment, e.g. the pelvis sensor's axis that points forward when
// mounted on the sacrum: ψ = atan2(y, x) of q̄_earth_sensor · axis).
//
// Segments without a calibration (no sensor, node_id = -1, or no samples when allowed)
// move rigidly with their parent in their T-pose relation (the root: identity).
//
// Nothing here allocates after construction; all are plain values (not thread-safe to
// share while writing).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "core/frame.hpp"
#include "math/markley_average.hpp"
#include "skeleton/body_model.hpp"

namespace mocap::skeleton {

using math::Quat;
using math::Vec3;

enum class CalibrationPose : std::uint8_t { kTPose, kNPose, kCustom };
enum class HeadingMode : std::uint8_t { kAlignToForward, kKeepEarth };
enum class FacingSource : std::uint8_t { kGiven, kFromSensorAxis };

std::string_view to_string(CalibrationPose p);  ///< "t-pose", "n-pose", "custom"
std::string_view to_string(HeadingMode m);      ///< "align", "earth"

/// q_body_segment for every model segment in a T- or N-pose (see the file comment).
/// For kCustom returns all identity.
std::array<Quat, kMaxSegments> pose_orientations(const BodyModel& model, CalibrationPose pose);

struct CalibrationOptions {
    CalibrationPose pose = CalibrationPose::kTPose;
    /// Used when pose == kCustom: q_body_segment per segment index.
    std::array<Quat, kMaxSegments> custom_pose = identity_quats();
    HeadingMode heading_mode = HeadingMode::kAlignToForward;
    FacingSource facing_source = FacingSource::kGiven;
    double facing_heading_rad = 0.0;          ///< ψ for kGiven
    int facing_segment = 0;                   ///< segment whose sensor gives ψ for kFromSensorAxis
    Vec3 facing_sensor_axis = Vec3::UnitX();  ///< that sensor's forward-pointing axis
    std::size_t min_samples = 10;             ///< per calibrated segment
    double max_spread_rad = 0.035;            ///< RMS angular spread over the still period (~2°)
    bool allow_missing = false;               ///< segments with a sensor but no samples: uncalibrated
};

/// Collects q_earth_sensor samples of a still period per segment (Markley accumulator: the
/// sign of each quaternion does not matter). O(1) per sample, no allocation.
class CalibrationCollector {
public:
    void reset();
    void add(std::size_t segment, const Quat& q_earth_sensor);
    std::size_t samples(std::size_t segment) const { return count_[segment]; }
    /// Markley average of the segment's samples (identity if none).
    Quat mean(std::size_t segment) const;
    /// RMS angle of the samples about their mean, rad (from the largest eigenvalue λ of
    /// M = Σ q qᵀ: λ/n = mean cos²(θ/2), so θ_rms ≈ 2·asin(√(1 − λ/n))).
    double spread_rad(std::size_t segment) const;

private:
    std::array<math::QuatAccumulator, kMaxSegments> acc_{};
    std::array<std::size_t, kMaxSegments> count_{};
};

struct Calibration {
    std::size_t segment_count = 0;
    std::array<Quat, kMaxSegments> q_sensor_segment = identity_quats();
    std::array<bool, kMaxSegments> calibrated{};
    Quat q_world_earth = Quat::Identity();
    CalibrationPose pose = CalibrationPose::kTPose;
    HeadingMode heading_mode = HeadingMode::kAlignToForward;
    double facing_heading_rad = 0.0;
};

struct CalibrationResult {
    std::optional<Calibration> calibration;
    std::string error;  ///< names the segment and the problem when calibration is empty
    explicit operator bool() const { return calibration.has_value(); }
};

/// Calibrates from the averaged still-period orientations (see the file comment). Errors:
/// too few samples or too much spread on a segment with a sensor (the subject moved),
/// facing segment without samples, model larger than kMaxSegments.
CalibrationResult calibrate(const BodyModel& model, const CalibrationCollector& still,
                            const CalibrationOptions& options);

/// Same from one mean orientation per segment (q_earth_sensor_mean[i]; has_sample[i] false
/// for a segment without data). No spread check.
CalibrationResult calibrate_from_means(const BodyModel& model, std::span<const Quat> q_earth_sensor_mean,
                                       std::span<const bool> has_sample, const CalibrationOptions& options);

/// World segment orientations from sensor orientations: for each segment i,
/// q_world_segment[i] = q_world_earth ⊗ q_earth_sensor[i] ⊗ q_sensor_segment[i];
/// uncalibrated segments follow their parent rigidly. O(segments), no allocation.
void apply_calibration(const BodyModel& model, const Calibration& cal, std::span<const Quat> q_earth_sensor,
                       std::span<Quat> q_world_segment);

/// Saved form: TOML-compatible text, one line per calibrated segment:
///   format = "mocapd-calibration"
///   version = 1
///   pose = "t-pose"
///   heading = "align"
///   facing_heading_rad = 0.5
///   q_world_earth = [w, x, y, z]
///   [q_sensor_segment]
///   pelvis = [w, x, y, z]
/// Numbers are written with 17 significant digits, so a reload is exact.
std::string serialize_calibration(const BodyModel& model, const Calibration& cal);

/// Parses the saved form against a model. Errors ("line N: ...") for syntax, unknown keys,
/// unknown segment names, duplicate entries, non-finite numbers, quaternions whose norm is
/// not 1 ± 1e-6. Never throws.
CalibrationResult parse_calibration(const BodyModel& model, std::string_view text);

/// Detects a still period from one sensor's samples: still once, for at least window_us,
/// the orientation stayed within orientation_threshold_rad of the orientation at the start
/// of the period and the gyro norm (if given) below gyro_threshold_rad_s. Timestamps come
/// from the samples; a timestamp going backwards restarts the period. O(1), no allocation.
struct StillnessParams {
    double gyro_threshold_rad_s = 0.1;
    double orientation_threshold_rad = 0.035;  ///< ~2°
    std::int64_t window_us = 1'000'000;
};

class StillnessDetector {
public:
    explicit StillnessDetector(const StillnessParams& params = {}) : params_(params) {}
    /// Returns still(). Pass gyro_norm_rad_s = 0 when only orientations are known.
    bool update(std::int64_t t_us, const Quat& q_earth_sensor, double gyro_norm_rad_s = 0.0);
    bool still() const { return started_ && last_us_ - since_us_ >= params_.window_us; }
    void reset() { started_ = false; }

private:
    StillnessParams params_;
    bool started_ = false;
    Quat anchor_ = Quat::Identity();
    std::int64_t since_us_ = 0;
    std::int64_t last_us_ = 0;
};

}  // namespace mocap::skeleton
