// segment_processor.hpp — the seam between the pipeline (core) and whatever turns one
// segment's samples into an orientation (filters live outside core and plug in here).
//
// Ownership: the caller owns every SegmentProcessor (one instance per segment, holding that
// segment's filter state) and keeps it alive until the WorkerPool using it has stopped.
// Thread-safety: process() is called only from the segment's worker thread, one sample at a
// time, in submission order; an instance is never called concurrently.
#pragma once

#include <cstdint>

#include "core/frame.hpp"

namespace mocap {

class SegmentProcessor {
public:
    virtual ~SegmentProcessor() = default;

    /// Consumes one sample. On entry `out` holds identity, sample_us = in.imu.t_us and
    /// flags = 0. Writes out.q_earth_sensor_wxyz and may OR in flags (kSegmentFromNode,
    /// kSegmentCalibrated). Returns false when this sample yields no pose (invalid input,
    /// filter still initialising): the pool counts it and emits nothing for it.
    /// Must not block; should not allocate (it runs on the hot path).
    virtual bool process(const SegmentSample& in, SegmentPose& out) = 0;
};

/// One segment's filtered pose on its way from a worker to the subject assembler.
struct PoseUpdate {
    std::uint32_t subject_id = 0;
    std::uint16_t segment_index = 0;
    std::uint64_t sync = 0;  ///< extended SYNC counter of the sample
    SegmentPose pose{};
    StageTimes times{};  ///< the sample's stamps plus dequeued_us and filtered_us
};

}  // namespace mocap
