#include "core/saturating.hpp"

#include <gtest/gtest.h>

#include "core/latency_histogram.hpp"

namespace mocap {
namespace {

TEST(Saturating, AddAndSubClampInsteadOfWrapping) {
    EXPECT_EQ(saturating_add(1, 2), 3);
    EXPECT_EQ(saturating_add(kInt64Max, 1), kInt64Max);
    EXPECT_EQ(saturating_add(kInt64Max - 5, 65535), kInt64Max) << "a huge stamp plus a frame offset";
    EXPECT_EQ(saturating_add(kInt64Min, -1), kInt64Min);
    EXPECT_EQ(saturating_sub(5, 7), -2);
    // received - sent with a hostile "sent" far in the past or future.
    EXPECT_EQ(saturating_sub(1'764'633'600'000'000, kInt64Min), kInt64Max);
    EXPECT_EQ(saturating_sub(1'764'633'600'000'000, kInt64Min + 1), kInt64Max);
    EXPECT_EQ(saturating_sub(-10, kInt64Max), kInt64Min);
    EXPECT_EQ(saturating_sub(0, kInt64Max), -kInt64Max);
}

TEST(Saturating, WireStampsAboveInt64MaxDoNotTurnNegative) {
    EXPECT_EQ(saturating_int64(0), 0);
    EXPECT_EQ(saturating_int64(1'000'000), 1'000'000);
    EXPECT_EQ(saturating_int64(static_cast<std::uint64_t>(kInt64Max)), kInt64Max);
    EXPECT_EQ(saturating_int64(static_cast<std::uint64_t>(kInt64Max) + 1), kInt64Max);
    EXPECT_EQ(saturating_int64(UINT64_MAX), kInt64Max) << "a plain cast gives -1";
}

TEST(Saturating, ASaturatedLatencyStaysInTheLastBucket) {
    // What the pipeline records for a stamp that got past every check: one value in the
    // open last bucket, not a wrapped negative or a sum that overflows.
    SingleWriterLatencyHistogram h;
    h.record(saturating_sub(1'000'000, kInt64Min));
    const auto s = h.snapshot();
    EXPECT_EQ(s.count, 1u);
    EXPECT_EQ(s.negative, 0u);
    EXPECT_EQ(s.buckets[kLatencyBuckets - 1], 1u);
}

}  // namespace
}  // namespace mocap
