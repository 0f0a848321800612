#include "core/latency_histogram.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <thread>
#include <vector>

namespace mocap {
namespace {

TEST(LatencyBuckets, AreContiguousAndNarrow) {
    EXPECT_EQ(latency_bucket_lower_us(0), 0u);
    for (std::size_t i = 0; i + 1 < kLatencyBuckets; ++i) {
        const std::uint64_t lo = latency_bucket_lower_us(i);
        const std::uint64_t hi = latency_bucket_upper_us(i);
        ASSERT_EQ(latency_bucket_index(lo), i);
        ASSERT_EQ(latency_bucket_index(hi), i);
        ASSERT_EQ(latency_bucket_lower_us(i + 1), hi + 1);
        // Width at most 1/32 of the bucket's lower bound (exact below 32 µs).
        ASSERT_LE((hi - lo + 1) * kLatencySubBuckets, std::max<std::uint64_t>(lo, kLatencySubBuckets));
    }
    EXPECT_EQ(latency_bucket_index(UINT64_MAX), kLatencyBuckets - 1);
    EXPECT_EQ(latency_bucket_index(std::uint64_t{1} << 40), kLatencyBuckets - 1);
}

TEST(LatencyHistogram, EmptySnapshotIsZero) {
    LatencyHistogram h;
    const auto s = h.snapshot();
    EXPECT_EQ(s.count, 0u);
    EXPECT_EQ(s.percentile_us(50), 0u);
    EXPECT_EQ(s.percentile_us(99), 0u);
    EXPECT_EQ(s.mean_us(), 0.0);
}

TEST(LatencyHistogram, SmallValuesAreExact) {
    LatencyHistogram h;
    for (int v = 1; v <= 20; ++v)
        h.record(v);
    const auto s = h.snapshot();
    EXPECT_EQ(s.count, 20u);
    EXPECT_EQ(s.percentile_us(50), 10u);
    EXPECT_EQ(s.percentile_us(90), 18u);
    EXPECT_EQ(s.percentile_us(100), 20u);
    EXPECT_EQ(s.max_us, 20u);
    EXPECT_DOUBLE_EQ(s.mean_us(), 10.5);
}

TEST(LatencyHistogram, PercentilesMatchSortedReferenceWithinOneBucket) {
    std::mt19937_64 rng(7);
    std::lognormal_distribution<double> dist(std::log(300.0), 1.2);  // µs, long tail
    LatencyHistogram h;
    std::vector<std::uint64_t> ref;
    for (int i = 0; i < 20'000; ++i) {
        const auto v = static_cast<std::int64_t>(dist(rng));
        h.record(v);
        ref.push_back(static_cast<std::uint64_t>(v));
    }
    std::sort(ref.begin(), ref.end());
    const auto s = h.snapshot();
    ASSERT_EQ(s.count, ref.size());
    EXPECT_EQ(s.max_us, ref.back());
    for (double p : {1.0, 10.0, 50.0, 90.0, 99.0, 99.9, 100.0}) {
        const auto rank = static_cast<std::size_t>(std::ceil(p / 100.0 * static_cast<double>(ref.size())));
        const std::uint64_t truth = ref[std::max<std::size_t>(rank, 1) - 1];
        const std::uint64_t got = s.percentile_us(p);
        EXPECT_GE(got, truth) << "p" << p;
        EXPECT_LE(got, truth + truth / 32) << "p" << p;
    }
}

TEST(LatencyHistogram, NegativeValuesAreCountedNotBucketed) {
    LatencyHistogram h;
    h.record(-5);
    h.record(100);
    const auto s = h.snapshot();
    EXPECT_EQ(s.negative, 1u);
    EXPECT_EQ(s.count, 1u);
    EXPECT_EQ(s.percentile_us(0), 100u);
}

TEST(LatencyHistogram, MergeAndSince) {
    LatencyHistogram a, b;
    for (int i = 0; i < 100; ++i)
        a.record(10);
    const auto before = a.snapshot();
    for (int i = 0; i < 100; ++i)
        a.record(1000);
    b.record(5000);
    const auto interval = a.snapshot().since(before);
    EXPECT_EQ(interval.count, 100u);
    EXPECT_EQ(interval.percentile_us(1), 1000u);
    EXPECT_EQ(interval.max_us, 1000u);
    auto merged = a.snapshot();
    merged.merge(b.snapshot());
    EXPECT_EQ(merged.count, 201u);
    EXPECT_EQ(merged.max_us, 5000u);
    // 1000 is not a bucket boundary: the median reports its bucket's upper bound.
    EXPECT_EQ(merged.percentile_us(50), latency_bucket_upper_us(latency_bucket_index(1000)));
    EXPECT_LE(merged.percentile_us(50), 1000u + 1000u / 32);
}

TEST(LatencyHistogram, ConcurrentRecordsAreAllCounted) {
    LatencyHistogram h;
    constexpr int kPerThread = 50'000;
    auto writer = [&](int base) {
        for (int i = 0; i < kPerThread; ++i)
            h.record(base + i % 100);
    };
    std::thread t1(writer, 0);
    std::thread t2(writer, 1000);
    std::uint64_t last = 0;
    bool monotonic = true;
    for (int i = 0; i < 200; ++i) {
        const auto c = h.snapshot().count;
        if (c < last) monotonic = false;
        last = c;
    }
    t1.join();
    t2.join();
    const auto s = h.snapshot();
    EXPECT_TRUE(monotonic);
    EXPECT_EQ(s.count, 2u * kPerThread);
    EXPECT_EQ(s.max_us, 1099u);
}

// The single-writer form records exactly what the any-thread form records.
TEST(SingleWriterLatencyHistogram, SameSnapshotAsLatencyHistogram) {
    LatencyHistogram shared;
    SingleWriterLatencyHistogram own;
    std::mt19937_64 rng(5);
    std::uniform_int_distribution<std::int64_t> small(-50, 5000);
    std::uniform_int_distribution<std::int64_t> large(0, std::int64_t{1} << 40);
    for (int i = 0; i < 20'000; ++i) {
        const std::int64_t v = i % 10 == 0 ? large(rng) : small(rng);
        shared.record(v);
        own.record(v);
    }
    const LatencySnapshot a = shared.snapshot();
    const LatencySnapshot b = own.snapshot();
    EXPECT_EQ(a.buckets, b.buckets);
    EXPECT_EQ(a.count, b.count);
    EXPECT_EQ(a.sum_us, b.sum_us);
    EXPECT_EQ(a.max_us, b.max_us);
    EXPECT_EQ(a.negative, b.negative);
    EXPECT_GT(b.negative, 0u);
    EXPECT_EQ(b.percentile_us(99), a.percentile_us(99));
}

// One writer, a snapshotting reader meanwhile: counts only go up, the snapshot's count is the
// sum of its buckets, and the end result is exact (TSan-clean: all accesses are atomic).
TEST(SingleWriterLatencyHistogram, ReaderSeesItsOneWriter) {
    SingleWriterLatencyHistogram h;
    constexpr int kValues = 200'000;
    std::thread writer([&] {
        for (int i = 0; i < kValues; ++i)
            h.record(i % 3000);
    });
    std::uint64_t last = 0;
    bool monotonic = true;
    for (int i = 0; i < 200; ++i) {
        const LatencySnapshot s = h.snapshot();
        if (s.count < last) monotonic = false;
        last = s.count;
        ASSERT_LE(s.max_us, 2999u);
    }
    writer.join();
    const LatencySnapshot s = h.snapshot();
    EXPECT_TRUE(monotonic);
    EXPECT_EQ(s.count, std::uint64_t{kValues});
    EXPECT_EQ(s.max_us, 2999u);
    std::uint64_t sum = 0;
    for (int i = 0; i < kValues; ++i)
        sum += static_cast<std::uint64_t>(i % 3000);
    EXPECT_EQ(s.sum_us, sum);
}

}  // namespace
}  // namespace mocap
