// latency_histogram.cpp — snapshot and percentile math; recording is inline in the header
// because it runs on every sample.
#include "core/latency_histogram.hpp"

#include <algorithm>
#include <cmath>

namespace mocap {

template <bool SingleWriter>
LatencySnapshot BasicLatencyHistogram<SingleWriter>::snapshot() const noexcept {
    LatencySnapshot s;
    for (std::size_t i = 0; i < kLatencyBuckets; ++i) {
        s.buckets[i] = buckets_[i].load(std::memory_order_relaxed);
        s.count += s.buckets[i];
    }
    s.sum_us = sum_us_.load(std::memory_order_relaxed);
    s.max_us = max_us_.load(std::memory_order_relaxed);
    s.negative = negative_.load(std::memory_order_relaxed);
    return s;
}

template class BasicLatencyHistogram<false>;
template class BasicLatencyHistogram<true>;

std::uint64_t LatencySnapshot::percentile_us(double p) const noexcept {
    if (count == 0) return 0;
    p = std::clamp(p, 0.0, 100.0);
    // Rank of the wanted order statistic, 1-based; ceil so that p50 of {1,2} is 1.
    auto rank = static_cast<std::uint64_t>(std::ceil(p / 100.0 * static_cast<double>(count)));
    rank = std::clamp<std::uint64_t>(rank, 1, count);
    std::uint64_t seen = 0;
    for (std::size_t i = 0; i < kLatencyBuckets; ++i) {
        seen += buckets[i];
        if (seen >= rank) return std::min(latency_bucket_upper_us(i), max_us);
    }
    return max_us;  // unreachable when count == sum of buckets
}

double LatencySnapshot::mean_us() const noexcept {
    return count == 0 ? 0.0 : static_cast<double>(sum_us) / static_cast<double>(count);
}

void LatencySnapshot::merge(const LatencySnapshot& other) noexcept {
    for (std::size_t i = 0; i < kLatencyBuckets; ++i)
        buckets[i] += other.buckets[i];
    count += other.count;
    sum_us += other.sum_us;
    max_us = std::max(max_us, other.max_us);
    negative += other.negative;
}

LatencySnapshot LatencySnapshot::since(const LatencySnapshot& earlier) const noexcept {
    LatencySnapshot d;
    std::size_t highest = 0;
    for (std::size_t i = 0; i < kLatencyBuckets; ++i) {
        d.buckets[i] = buckets[i] - earlier.buckets[i];
        d.count += d.buckets[i];
        if (d.buckets[i] != 0) highest = i;
    }
    d.sum_us = sum_us - earlier.sum_us;
    d.negative = negative - earlier.negative;
    d.max_us = d.count == 0 ? 0 : std::min(max_us, latency_bucket_upper_us(highest));
    return d;
}

}  // namespace mocap
