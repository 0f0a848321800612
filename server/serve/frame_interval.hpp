// frame_interval.hpp — the interval at which one subject is actually sampled, measured from
// its frames: (sample instant of the latest frame − of the first) / (SYNCs between them),
// over the current run of frames. A run restarts when the SYNC counter does not advance
// (the sink reconnected and counts from 0 again) or the sink clock jumps (more than 1 s per
// SYNC, or backwards), so a restart never mixes two clocks.
//
// Used for BVH "Frame Time:" (serve/bvh_server.hpp, serve/bvh_recorder.hpp), which was a
// config constant and so wrong at any sink rate but the one configured.
// Thread-safety: none; one owner thread (or the owner's lock).
#pragma once

#include <cstdint>
#include <optional>

namespace mocap::serve {

class FrameInterval {
public:
    /// seconds() answers once the run spans at least `min_intervals` SYNC intervals.
    explicit FrameInterval(std::uint64_t min_intervals = 1) : min_intervals_(min_intervals) {}

    void add(std::uint64_t sync, std::int64_t sample_us) {
        const bool restart = !started_ || sync <= last_sync_ || sample_us <= last_us_ ||
                             static_cast<std::uint64_t>(sample_us - last_us_) > (sync - last_sync_) * kMaxIntervalUs;
        if (restart) {
            started_ = true;
            first_sync_ = sync;
            first_us_ = sample_us;
        }
        last_sync_ = sync;
        last_us_ = sample_us;
    }

    /// Mean seconds per SYNC over the current run, or nothing yet.
    [[nodiscard]] std::optional<double> seconds() const {
        if (!started_ || last_sync_ - first_sync_ < min_intervals_) return std::nullopt;
        return static_cast<double>(last_us_ - first_us_) * 1e-6 / static_cast<double>(last_sync_ - first_sync_);
    }

private:
    static constexpr std::uint64_t kMaxIntervalUs = 1'000'000;
    std::uint64_t min_intervals_;
    bool started_ = false;
    std::uint64_t first_sync_ = 0, last_sync_ = 0;
    std::int64_t first_us_ = 0, last_us_ = 0;
};

}  // namespace mocap::serve
