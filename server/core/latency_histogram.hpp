// latency_histogram.hpp — fixed-bucket log-linear histogram of microsecond latencies,
// recorded on pipeline threads and snapshotted by a stats thread.
//
// Buckets (HdrHistogram-like, 5 sub-bucket bits): values 0..31 µs are exact; above that each
// power-of-two octave [2^m, 2^(m+1)) is split into 32 equal buckets, so a bucket is at most
// 1/32 (3.1 %) of its values wide. 1024 buckets cover 0 .. 2^36 µs (19 h); larger values land
// in the last bucket (max_us stays exact). Negative values (e.g. a sink clock ahead of the
// host) are not bucketed: they are counted in `negative`.
//
// Contract
// - LatencyHistogram::record(): any thread, lock-free, never allocates (relaxed fetch_add on
//   the bucket and the sum, a CAS loop on max). Cost ~5–10 ns uncontended; threads recording
//   into the same histogram bounce its lines, so give each thread its own and merge snapshots.
// - SingleWriterLatencyHistogram::record(): the same buckets and snapshot, but every update
//   is a relaxed load + relaxed store (no locked instruction). SINGLE-WRITER RULE (as for
//   SingleWriterCounter, core/counters.hpp): all record() calls of one histogram happen on
//   one thread, or on threads handed over with a happens-before edge; a second concurrent
//   writer loses values silently. snapshot() stays correct on any thread.
// - snapshot(): any thread. Reads every bucket once (relaxed): concurrent records may or
//   may not be included, the snapshot's count is always the sum of its buckets.
// - LatencySnapshot is a plain value (8 KiB); percentile math runs on it, off the hot path.
//   Values only go up; a reader computes an interval with since().
#pragma once

#include <array>
#include <atomic>
#include <bit>
#include <cstddef>
#include <cstdint>

#include "core/counters.hpp"

namespace mocap {

inline constexpr unsigned kLatencySubBucketBits = 5;
inline constexpr std::size_t kLatencySubBuckets = std::size_t{1} << kLatencySubBucketBits;
inline constexpr unsigned kLatencyMaxOctave = 36;  ///< values >= 2^36 µs share the last bucket
inline constexpr std::size_t kLatencyBuckets =
    kLatencySubBuckets + (kLatencyMaxOctave - kLatencySubBucketBits) * kLatencySubBuckets;

/// Bucket holding value_us (clamped to the last bucket).
constexpr std::size_t latency_bucket_index(std::uint64_t value_us) noexcept {
    if (value_us < kLatencySubBuckets) return static_cast<std::size_t>(value_us);
    const unsigned octave = static_cast<unsigned>(std::bit_width(value_us)) - 1;  // >= 5
    if (octave >= kLatencyMaxOctave) return kLatencyBuckets - 1;
    const unsigned shift = octave - kLatencySubBucketBits;
    const std::size_t sub = static_cast<std::size_t>(value_us >> shift) - kLatencySubBuckets;
    return kLatencySubBuckets + shift * kLatencySubBuckets + sub;
}

/// Smallest value that maps to bucket `index`.
constexpr std::uint64_t latency_bucket_lower_us(std::size_t index) noexcept {
    if (index < kLatencySubBuckets) return index;
    const std::size_t shift = (index - kLatencySubBuckets) / kLatencySubBuckets;
    const std::size_t sub = (index - kLatencySubBuckets) % kLatencySubBuckets;
    return static_cast<std::uint64_t>(kLatencySubBuckets + sub) << shift;
}

/// Largest value that maps to bucket `index` (the last bucket's is open-ended: UINT64_MAX).
constexpr std::uint64_t latency_bucket_upper_us(std::size_t index) noexcept {
    if (index + 1 >= kLatencyBuckets) return UINT64_MAX;
    return latency_bucket_lower_us(index + 1) - 1;
}

struct LatencySnapshot {
    std::array<std::uint64_t, kLatencyBuckets> buckets{};
    std::uint64_t count = 0;     ///< values bucketed (= sum of buckets)
    std::uint64_t sum_us = 0;    ///< sum of bucketed values
    std::uint64_t max_us = 0;    ///< largest bucketed value (exact)
    std::uint64_t negative = 0;  ///< values < 0 seen (not bucketed)

    /// Value at percentile p (0..100): the upper bound of the bucket holding the
    /// ceil(p·count/100)-th smallest value, capped at max_us. It is never below the true
    /// order statistic and at most 1/32 above it (exact below 32 µs). 0 when empty.
    [[nodiscard]] std::uint64_t percentile_us(double p) const noexcept;
    [[nodiscard]] double mean_us() const noexcept;
    /// Adds another snapshot (e.g. one per worker thread) into this one.
    void merge(const LatencySnapshot& other) noexcept;
    /// What was recorded after `earlier` (a previous snapshot of the same histogram).
    /// max_us of the interval is bounded by its highest non-empty bucket.
    [[nodiscard]] LatencySnapshot since(const LatencySnapshot& earlier) const noexcept;
};

/// SingleWriter = false: LatencyHistogram (any thread records); true:
/// SingleWriterLatencyHistogram (one writer thread, see the contract above).
template <bool SingleWriter>
class BasicLatencyHistogram {
public:
    BasicLatencyHistogram() = default;
    BasicLatencyHistogram(const BasicLatencyHistogram&) = delete;
    BasicLatencyHistogram& operator=(const BasicLatencyHistogram&) = delete;

    /// Lock-free, no allocation. LatencyHistogram: any thread; SingleWriterLatencyHistogram:
    /// its one writer thread only.
    void record(std::int64_t value_us) noexcept {
        if (value_us < 0) {
            add(negative_, 1);
            return;
        }
        const auto v = static_cast<std::uint64_t>(value_us);
        add(buckets_[latency_bucket_index(v)], 1);
        add(sum_us_, v);
        std::uint64_t seen = max_us_.load(std::memory_order_relaxed);
        if constexpr (SingleWriter) {
            if (v > seen) max_us_.store(v, std::memory_order_relaxed);
        } else {
            while (v > seen && !max_us_.compare_exchange_weak(seen, v, std::memory_order_relaxed)) {
            }
        }
    }

    /// Any thread.
    [[nodiscard]] LatencySnapshot snapshot() const noexcept;

private:
    static void add(std::atomic<std::uint64_t>& cell, std::uint64_t n) noexcept {
        if constexpr (SingleWriter) {
            single_writer_add(cell, n);
        } else {
            cell.fetch_add(n, std::memory_order_relaxed);
        }
    }

    std::array<std::atomic<std::uint64_t>, kLatencyBuckets> buckets_{};
    std::atomic<std::uint64_t> sum_us_{0};
    std::atomic<std::uint64_t> max_us_{0};
    std::atomic<std::uint64_t> negative_{0};
};

using LatencyHistogram = BasicLatencyHistogram<false>;
using SingleWriterLatencyHistogram = BasicLatencyHistogram<true>;
extern template class BasicLatencyHistogram<false>;
extern template class BasicLatencyHistogram<true>;

}  // namespace mocap
