// chain_estimator.hpp — body-aware heading: one subject's segments as a tree of joints whose
// kinematics hold the segments' relative headings (docs/fusion.md).
//
// Input per step: every segment's 6D orientation q6 (its filter's inclination, with a heading
// of the sensor's own that only the gyro keeps), its bias-corrected rate, and what its
// magnetometer says of that heading: q9 = Rz(d) ⊗ q6, and whether the filter trusts the field.
// Per joint, a HeadingFilter (heading_filter.hpp) estimates δ, the heading that turns the
// child's 6D frame into the parent's, from the joint's constraints (joint_constraints.hpp):
//   hinge   the axis and the shared perpendicular angular velocity (two vector pairs);
//   2dof    the constant angle between its two axes and the rate constraint (two scalars);
//   ball    nothing per sample: its range of motion bounds δ only through the whole motion;
//           the magnetometer (auto) or the gyro (held) keeps it.
// Output: q_earth_sensor = Rz(ψ) ⊗ q6 with ψ_root from the root's magnetometer heading (the
// filter holds it on the gyro while it rejects the field) and ψ_child = ψ_parent + δ.
//
// Heading source (ChainParams::mode):
//   magnetometer  every segment keeps its own filter's heading (q9; the chain is bypassed);
//   joints        relative headings from the joints only; the magnetometer is used for the
//                 root's absolute heading alone (and nowhere with --no-mag: d = 0);
//   auto          joints, plus each joint's magnetometer difference where both fields keep
//                 their norm and dip, agree with each other, and the difference agrees with
//                 what the joint says. The difference is of the fields' own headings
//                 (SegmentInput::field_heading_rad), not of the filters' corrections d, which
//                 lag a drifting 6D frame by its rate × the correction's time constant (a
//                 pelvis whose vertical gyro bias is 1 °/s off leaves its d 10° behind its
//                 field). Where a joint cannot see δ (vertical hinge axis, a ball joint),
//                 agreeing fields alone carry it.
// Each segment reports where its heading came from (HeadingSource): the magnetometer, the
// joints, or the gyroscope alone (nothing observed it for hold_s).
//
// Joint axes are in the sensors' frames. A joint whose axes are not known (yet) uses the
// magnetometer difference (auto) or holds δ; set_axes() gives them later (calibration, an
// axis estimate).
//
// Fixed capacity (kMaxSegments segments, one joint per non-root segment), nothing allocated
// after construction; not thread-safe (one per subject, on the assembler thread).
// Cost per step: O(joints), ~0.1 µs per joint (docs/performance.md).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/frame.hpp"
#include "fusion/heading_filter.hpp"
#include "fusion/hinge_axis_estimator.hpp"
#include "fusion/joint_constraints.hpp"
#include "fusion/joint_position_estimator.hpp"
#include "math/quaternion.hpp"

namespace mocap::fusion {

using math::Quat;
using math::Vec3;

enum class JointType : std::uint8_t { kHinge, kTwoDof, kBall };
enum class HeadingMode : std::uint8_t { kMagnetometer, kJoints, kAuto };
enum class HeadingSource : std::uint8_t { kNone, kMagnetometer, kJoints, kGyro };

std::string_view to_string(JointType t);      ///< "hinge", "2dof", "ball"
std::string_view to_string(HeadingMode m);    ///< "magnetometer", "joints", "auto"
std::string_view to_string(HeadingSource s);  ///< "none", "magnetometer", "joints", "gyro"
/// "magnetometer" | "joints" | "auto" -> mode; nullopt for anything else.
std::optional<HeadingMode> parse_heading_mode(std::string_view name);

struct JointDef {
    int parent = -1;  ///< segment index
    int child = -1;   ///< segment index; each segment is the child of at most one joint
    JointType type = JointType::kHinge;
    bool axes_known = false;
    bool estimate_axes = false;        ///< hinge: learn the axes from the motion (hinge_axis_estimator.hpp),
                                       ///< replacing the given ones once the estimate is ready
    Vec3 axis_parent = Vec3::UnitX();  ///< unit, parent sensor frame (2dof: the axis fixed in the parent)
    Vec3 axis_child = Vec3::UnitX();   ///< unit, child sensor frame (2dof: the axis fixed in the child)
    double cos_axis_angle = 0.0;       ///< 2dof: cosine of the constant angle between the axes
    bool centre_known = false;         ///< the joint centre's place in both sensor frames is given
    bool estimate_centre = true;       ///< learn it from the motion (joint_position_estimator.hpp)
                                       ///< when not given
    Vec3 r_parent = Vec3::Zero();      ///< joint centre from the parent's sensor, its frame, m
    Vec3 r_child = Vec3::Zero();       ///< joint centre from the child's sensor, its frame, m
};

struct ChainParams {
    HeadingMode mode = HeadingMode::kAuto;
    HeadingFilterParams filter{};
    double correlation_s = 1.0;      ///< time over which one constraint's errors are correlated, s
    double sigma_axis = 0.035;       ///< error of an axis direction in the earth frame (inclination, axis), unit vector
    double sigma_rate_rad_s = 0.02;  ///< error of a shared angular velocity, rad/s ...
    double sigma_rate_rel = 0.05;    ///< ... plus this fraction of its size
    double min_axis_horizontal = 0.2;        ///< a pair whose horizontal part is shorter says nothing
    double min_rate_horizontal_rad_s = 0.3;  ///< same for the shared angular velocity, rad/s
    double still_rate_rad_s = 0.05;          ///< a joint without axes whose segments' rates agree this well
                                             ///< (plus sigma_rate_rel of their size) is taken as still, rad/s
    double still_s = 0.5;                    ///< ... once they have agreed this long without a break, s
    double sigma_two_dof_axis = 0.035;       ///< 2dof axis-angle constraint noise (cosine units)
    double sigma_two_dof_rate_rad_s = 0.05;  ///< 2dof rate constraint noise, rad/s
    double gate_sigma = 5.0;                 ///< innovations beyond this many σ are refused
    double mag_correlation_s = 30.0;         ///< time over which a magnetometer difference's error persists, s
    double sigma_mag_deg = 3.0;              ///< a magnetometer difference's error where fields agree, °
    double mag_agree_deg = 10.0;             ///< ... and how far it may be from the joint's estimate, °
    double field_norm_agree = 0.06;          ///< two fields agree within this relative norm difference
    double field_dip_agree_deg = 4.0;        ///< ... and this dip difference, °
    double hold_s = 5.0;                     ///< no constraint for this long: the source is the gyro
    double search_s = 20.0;                  ///< 2dof: window of the cost that starts δ, s
    double search_margin = 25.0;             ///< ... its runner-up must be this much worse (χ²)
    double noise_tau_s = 30.0;               ///< time over which each constraint's real error is learned, s
    double min_noise_ratio = 0.01;           ///< a constraint counts at most this much better than its model
    double lost_s = 3.0;                     ///< the gate refused every constraint for this long: restart δ
    double restart_sigma_deg = 30.0;         ///< a segment's 6D frame started again (its filter restarted after
                                             ///< a gap): δ starts where the joint's last relative orientation
                                             ///< puts it, with this uncertainty, °
    HingeAxisParams axis{};                  ///< axes learned from the motion
    double axis_sign_sigma_deg = 10.0;       ///< a δ known this well decides a learned hinge axis's sign
                                             ///< where the motion has not yet (pair_contradicts), °
    JointPositionParams centre{};            ///< joint centres learned from the motion
    double sigma_acc_m_s2 = 0.3;             ///< error of the joint centre's specific force, m/s² ...
    double sigma_acc_rel = 0.05;             ///< ... plus this fraction of its horizontal size
    double min_acc_horizontal_m_s2 = 0.5;    ///< its horizontal part must be this long to count, m/s²
};

/// One segment's filter output for this step.
struct SegmentInput {
    bool fresh = false;              ///< a new sample this step (false: hold, stale)
    Quat q6 = Quat::Identity();      ///< 6D orientation: filter inclination, own heading frame
    Vec3 gyro_rad_s = Vec3::Zero();  ///< bias-corrected rate, sensor frame
    Vec3 accel_m_s2 = Vec3::Zero();  ///< specific force, sensor frame (zero: none)
    bool mag_available = false;      ///< the filter has a magnetometer heading
    double mag_heading_rad = 0.0;    ///< d: the filter's own output is Rz(d) ⊗ q6
    bool mag_trusted = false;        ///< the filter uses the field now (not rejected)
    double field_norm_ut = 0.0;      ///< the field the filter sees (0: unknown)
    double field_heading_rad = 0.0;  ///< the field's own heading in q6's frame: d without the lag of
                                     ///< the filter's correction (which a drifting q6 leaves behind)
    bool field_usable = false;       ///< the field keeps its norm and dip, whether or not the filter
                                     ///< uses it for its own heading now
    double field_dip_rad = 0.0;
    std::uint8_t frame_epoch = 0;  ///< changes when q6's heading frame starts again (the filter
                                   ///< restarted after a gap): the joints' δ to it start again
};

/// One joint's relative heading as compose() applies it.
struct JointHeading {
    bool known = false;  ///< false: nothing has seen δ yet
    double delta_rad = 0.0;
    HeadingSource source = HeadingSource::kNone;
};

struct SegmentOutput {
    Quat q_earth_sensor = Quat::Identity();
    HeadingSource source = HeadingSource::kNone;
};

/// What one joint's estimator knows (for tests, stats and the trace).
struct JointStatus {
    double delta_rad = 0.0;
    double sigma_rad = 0.0;
    double rate_rad_s = 0.0;
    bool initialised = false;
    HeadingSource source = HeadingSource::kNone;
    std::uint64_t joint_updates = 0;      ///< constraint measurements taken
    std::uint64_t mag_updates = 0;        ///< magnetometer differences taken
    std::uint64_t mag_disagreements = 0;  ///< differences refused: fields or joint disagree
    std::uint64_t refused = 0;            ///< outliers refused by the filter's gate
    std::uint64_t restarts = 0;           ///< δ restarted (lost, new axes, a segment's frame restarted)
    bool axes_known = false;
    bool axes_estimated = false;  ///< the axes in use were learned from the motion
    Vec3 axis_parent = Vec3::UnitX(), axis_child = Vec3::UnitX();
    bool centre_known = false;
    Vec3 r_parent = Vec3::Zero(), r_child = Vec3::Zero();
};

class ChainEstimator {
public:
    /// segment_count <= kMaxSegments; joints: at most one per child, parent and child in range
    /// and different, no cycles. Returns an error text for a bad chain (empty = valid).
    static std::string check(std::size_t segment_count, std::span<const JointDef> joints);

    /// Requires check() to pass.
    ChainEstimator(std::size_t segment_count, std::span<const JointDef> joints, const ChainParams& params);
    ChainEstimator(ChainEstimator&&) noexcept = default;
    ChainEstimator& operator=(ChainEstimator&&) noexcept = default;

    void reset();
    /// Gives joint j its axes (sensor frames, normalised here); the estimate keeps its δ.
    void set_axes(std::size_t joint, const Vec3& axis_parent, const Vec3& axis_child);

    /// Gives joint j its centre in both sensor frames (a body model's guess); a centre learned
    /// from the motion replaces it once ready (JointDef::estimate_centre).
    void set_centre(std::size_t joint, const Vec3& r_parent, const Vec3& r_child);

    /// Starts joint j's δ from the relative heading the last update() composed (a calibration
    /// taken from that output fixed the mountings against it, so the constraints built from
    /// those mountings agree with it), with standard deviation sigma_rad. No-op before the
    /// first update().
    void anchor(std::size_t joint, double sigma_rad);

    /// One step at t_us (not decreasing). in and out have segment_count entries.
    void update(std::int64_t t_us, std::span<const SegmentInput> in, std::span<SegmentOutput> out);

    /// Turns every segment's q6 by the headings of the joints given (one per joint, in
    /// joint order) instead of the estimator's own: the roots as update() does, the children
    /// by their parent's heading plus δ. For a smoother that blends two passes' δ.
    void compose(std::span<const SegmentInput> in, std::span<const JointHeading> headings,
                 std::span<SegmentOutput> out);

    [[nodiscard]] std::size_t segment_count() const { return segment_count_; }
    [[nodiscard]] std::size_t joint_count() const { return joints_.size(); }
    [[nodiscard]] const JointDef& joint(std::size_t j) const { return joints_[j].def; }
    [[nodiscard]] JointStatus status(std::size_t j) const;
    [[nodiscard]] const ChainParams& params() const { return params_; }

private:
    enum Stream : std::uint8_t { kAxisPair, kRatePair, kTwoDofAxis, kTwoDofRate, kAccPair, kStillPair, kMag, kStreams };
    struct Joint {
        JointDef def;
        HeadingFilter filter;
        std::int64_t last_joint_us = -1;                 // last constraint measurement taken
        std::int64_t last_mag_us = -1;                   // last magnetometer difference taken
        std::int64_t refused_since_us = -1;              // first of the refusals in a row (-1: none)
        std::int64_t still_since_us = -1;                // the rates have agreed since (no axes; -1: they do not)
        std::unique_ptr<HingeAxisEstimator> axis;        // estimate_axes hinges only
        std::unique_ptr<JointPositionEstimator> centre;  // joints whose centre is learned
        // The two previous steps of both segments: the joint centre's specific force needs
        // the angular acceleration, a central difference, so it is measured one step late.
        struct Past {
            std::int64_t t_us = -1;
            SegmentInput p, c;
        };
        std::array<Past, 2> past{};
        TrigQuad search;                             // 2dof: the constraints' cost over δ, last search_s
        std::array<double, kStreams> noise_ratio{};  // learned error variance / model variance
        bool axes_estimated = false;
        JointStatus stats;
    };
    /// Forgets δ and what was measured of it in the segments' old 6D frames.
    static void forget_delta(Joint& j);
    /// What forget_delta clears but the heading filter: the search, the streams' recency, the
    /// previous steps.
    static void forget_tracking(Joint& j);
    /// One of the joint's segments has a new 6D frame: δ again from the relative orientation
    /// the joint had at the last step (a joint turns little about the vertical in a short gap).
    void restart_delta(Joint& j, const SegmentInput& p, const SegmentInput& c);
    /// fields_seen: both segments' filters have trusted their fields at some time.
    void update_joint(Joint& j, std::int64_t t_us, double dt_s, const SegmentInput& p, const SegmentInput& c,
                      bool fields_seen);
    /// Constraint measurements of one step; true if one was taken.
    bool constrain(Joint& j, std::int64_t t_us, double dt_s, const SegmentInput& p, const SegmentInput& c);
    void learn_axes(Joint& j, std::int64_t t_us, const SegmentInput& p, const SegmentInput& c);
    /// The joint centre's specific force of the previous step as a vector pair; false when
    /// the centre is unknown or the step had no neighbours.
    bool centre_pair(Joint& j, std::int64_t t_us, const SegmentInput& p, const SegmentInput& c, Vec3& a, Vec3& b);
    double learn_noise(Joint& j, Stream stream, double innovation_rad, double model_var) const;
    [[nodiscard]] bool fields_agree(const SegmentInput& p, const SegmentInput& c) const;
    [[nodiscard]] HeadingSource source_of(const Joint& j, std::int64_t t_us) const;

    ChainParams params_;
    std::size_t segment_count_ = 0;
    std::vector<Joint> joints_;
    std::array<int, kMaxSegments> joint_of_child_{};  // joint index per segment, -1 = a root
    std::array<int, kMaxSegments> order_{};           // segments, parents before children
    std::array<double, kMaxSegments> psi_{};          // heading applied to each segment's q6
    std::array<bool, kMaxSegments> field_seen_{};     // the segment's filter has trusted its field
    std::array<int, kMaxSegments> epoch_{};           // the segment's last frame_epoch (-1: none yet)
    std::array<Quat, kMaxSegments> last_out_{};       // q_earth_sensor composed at the last step
    std::int64_t last_us_ = -1;
    bool solved_this_step_ = false;  // one axis or centre solve per step at most (their cost)
    struct StepCoefficients {
        double dt_s = -1.0, search_decay = 1.0, noise_gain = 0.0;
    } step_;
};

}  // namespace mocap::fusion
