// chain_offline.hpp — the inputs of the non-causal chain stage (fusion/chain_smoother.hpp)
// prepared from whole takes, for its two callers: `mocap-filter --chain --offline`
// (clients/filter_tool/chain_run.cpp) and `mocapd --replay --offline` with [fusion] heading
// other than "magnetometer" (daemon/replay.cpp).
//
//   offline_segment_inputs  one segment's samples -> one SegmentInput per sample: the offline
//                           smoother (filter/offline_smoother.hpp) once with every magnetometer
//                           reading removed (q6: one heading frame for the whole take) and once
//                           with the field (q9); d = heading of q9 ⊗ conj(q6) = 2·atan2(z, w);
//                           mag_trusted where either pass used the field; one constant gyro
//                           bias, what the raw rates have that the re-solved 6D motion does
//                           not; the field's norm and dip through a 0.5 s low-pass; the
//                           accelerometer as specific force. Every input is fresh.
//   chain_rows              the segments' inputs on one time line: one row per SYNC instant
//                           any segment has; a segment without a sample at an instant holds
//                           its previous input (fresh = false), one without any sample yet
//                           holds the default input (never fresh).
//   body_chain_joints       the joints of a body model (skeleton/body_chain.hpp) with their
//                           axes in the sensor frames from a calibration's mountings,
//                           j_sensor = q_sensor_segment ⊗ j_segment; hinges without them (or
//                           every hinge with [fusion] axis = "estimate") learn theirs from the
//                           take, every joint learns its centre.
//
// Pure functions of their arguments (the filter is reset and reused), no I/O. Memory O(samples);
// allocates. Not for the live pipeline: they need the whole take. Cost: two offline re-solves
// per segment (~2 µs per sample with the default filter), the rest O(samples).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/imu_sample.hpp"
#include "filter/offline_smoother.hpp"
#include "filter/orientation_filter.hpp"
#include "fusion/chain_estimator.hpp"
#include "skeleton/body_chain.hpp"
#include "skeleton/body_model.hpp"
#include "skeleton/calibration.hpp"

namespace mocap::pipeline {

/// One sensor's take (strictly increasing t_us, as OfflineSmoother::smooth requires) as the
/// chain smoother takes it; `filter` configured as the online one, reset and reused.
std::vector<fusion::SegmentInput> offline_segment_inputs(const filter::OfflineSmoother& smoother,
                                                         filter::OrientationFilter& filter,
                                                         std::span<const ImuSample> samples);

/// One segment's samples: their SYNC instants (increasing; of samples at one instant the last
/// counts), times and inputs (equal sizes; empty: the segment sent nothing).
struct ChainTrack {
    std::span<const std::uint64_t> sync;
    std::span<const std::int64_t> t_us;
    std::span<const fusion::SegmentInput> in;
};

struct ChainRows {
    std::vector<std::uint64_t> sync;               ///< the instants, increasing
    std::vector<std::int64_t> t_us;                ///< per instant, never decreasing
    std::vector<fusion::SegmentInput> in;          ///< instants × segments, row-major
    std::vector<std::vector<std::size_t>> row_of;  ///< per track, per sample: its instant
};

/// Track i is segment i. An instant's time is that of its first segment's sample (in track
/// order), held at the previous instant's where that would run backwards.
ChainRows chain_rows(std::span<const ChainTrack> tracks);

/// The joints of `model` (skeleton::body_joints) for fusion::smooth_chain, axes in the sensor
/// frames from `calibration` (nullptr: none) where both segments are calibrated and the joint
/// is not a ball; a hinge learns its axes when it has none or options.estimate_axes is set.
std::vector<fusion::JointDef> body_chain_joints(const skeleton::BodyModel& model,
                                                const skeleton::FusionOptions& options,
                                                const skeleton::Calibration* calibration);

}  // namespace mocap::pipeline
