// filter_processor.hpp — one segment's orientation filter behind the pipeline's
// SegmentProcessor seam (core/segment_processor.hpp).
//
// Raw samples go through the segment's OrientationFilter; samples that carry the node's
// own quaternion (on-node attitude mode) pass through, flagged kSegmentFromNode.
// A sample with non-finite values is rejected (returns false: the pool counts it) and never
// reaches the filter, so one bad frame cannot poison a segment's state.
// Threading: called only from the segment's worker thread.
// Cost: the filter's update; no allocation.
#pragma once

#include <memory>

#include "core/segment_processor.hpp"
#include "filter/orientation_filter.hpp"

namespace mocap::pipeline {

class FilterProcessor final : public SegmentProcessor {
public:
    explicit FilterProcessor(std::unique_ptr<filter::OrientationFilter> filter) : filter_(std::move(filter)) {}

    bool process(const SegmentSample& in, SegmentPose& out) override;

    /// Whether a filter may be given these readings: all finite (the field only when present).
    /// What process() rejects otherwise; the offline replay (daemon/replay.hpp) asks the same.
    [[nodiscard]] static bool accepts(const ImuSample& s);

    [[nodiscard]] const filter::OrientationFilter& filter() const { return *filter_; }

private:
    std::unique_ptr<filter::OrientationFilter> filter_;
};

}  // namespace mocap::pipeline
