#include "load_tally.hpp"

#include <algorithm>
#include <climits>
#include <cmath>

namespace mocap::client {

namespace {

double percentile_ms(std::vector<std::int32_t>& v, double p) {
    const auto n = v.size();
    auto rank = static_cast<std::size_t>(std::ceil(p / 100.0 * static_cast<double>(n)));
    rank = std::clamp<std::size_t>(rank, 1, n) - 1;
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(rank), v.end());
    return v[rank] / 1000.0;
}

}  // namespace

void ClientTally::add(const v1::SkeletonFrame& frame, std::int64_t receive_us, std::uint32_t decimation,
                      std::size_t max_latencies) {
    ++frames;
    if (frame.times().sink_send_us() != 0) {
        const std::int64_t lat = receive_us - frame.times().sink_send_us();
        ++latency_samples;
        if (lat < 0) {
            ++negative_latencies;
        } else if (latencies_us.size() < max_latencies) {
            latencies_us.push_back(static_cast<std::int32_t>(std::min<std::int64_t>(lat, INT32_MAX)));
        }
    }
    auto it =
        std::find_if(last_sync.begin(), last_sync.end(), [&](const auto& p) { return p.first == frame.subject_id(); });
    if (it == last_sync.end()) {
        last_sync.emplace_back(frame.subject_id(), frame.sync());
        return;
    }
    const std::uint64_t jump = frame.sync() - it->second;
    if (frame.sync() > it->second && jump > decimation) {
        ++gaps;
        missing_frames += (jump + decimation - 1) / decimation - 1;
    }
    it->second = frame.sync();
}

void merge_tallies(std::vector<ClientTally>& tallies, const std::vector<bool>& counted, LoadResult& result) {
    std::vector<std::int32_t> latencies;
    bool first = true;
    for (std::size_t i = 0; i < tallies.size(); ++i) {
        ClientTally& t = tallies[i];
        result.frames += t.frames;
        result.gaps += t.gaps;
        result.missing_frames += t.missing_frames;
        result.latency_samples += t.latency_samples;
        result.negative_latencies += t.negative_latencies;
        latencies.insert(latencies.end(), t.latencies_us.begin(), t.latencies_us.end());
        std::vector<std::int32_t>().swap(t.latencies_us);
        if (!counted[i]) continue;
        result.frames_per_client_min = first ? t.frames : std::min(result.frames_per_client_min, t.frames);
        result.frames_per_client_max = std::max(result.frames_per_client_max, t.frames);
        first = false;
    }
    if (latencies.empty()) return;
    result.max_ms = *std::max_element(latencies.begin(), latencies.end()) / 1000.0;
    result.p50_ms = percentile_ms(latencies, 50);
    result.p90_ms = percentile_ms(latencies, 90);
    result.p99_ms = percentile_ms(latencies, 99);
}

}  // namespace mocap::client
