// play_pacer.hpp — when each sample of a played take is due (daemon/take_player.hpp), from
// the take's SYNC counter where it has one, and never later than a bound after the last one.
//
// A raw file's receive times are whatever the recording host's clock said, or whatever a
// hostile file says: a jump of an hour (or 31 years) would freeze playback that long, a step
// backwards would play the rest unpaced, and a span that overflows int64 or a take whose
// samples all sit at one instant would loop without ever waiting. So the pacer does not play
// receive times back as they stand. Each subject has its own timeline:
//   - a sample that moves its subject's SYNC on by k instants is due as long after that
//     subject's previous instant as its sample instant (t_us, the sink's time of the SYNC)
//     says, when the SYNC counter bears that out: the step is positive, within max_gap and at
//     most 4 k SYNC periods. Otherwise it is due k SYNC periods later. The period is the
//     take's own: the median of the last few steps (t_us difference / k) that were positive
//     and within max_gap, or 10 ms (100 Hz) while none is known;
//   - another sample of the same instant (another segment), or one whose SYNC is behind (out of
//     order), is due with its instant;
//   - a sample without a SYNC (0) is due its receive-time step after the subject's previous
//     sample, the step clamped to [0, max_gap];
//   - no step is ever longer than max_gap (a dropout of the take is played as max_gap);
//   - a subject's first sample is due with the latest sample due so far.
// What was not played as recorded is reported per sample (kGap, kBackward): a step of the
// sample instant longer than the SYNC allows or backwards, or a receive-time step longer than
// max_gap either way (without a SYNC: any receive-time step backwards, since the pacing then
// rests on it).
// All arithmetic on the file's values saturates; offsets never decrease per subject.
//
// Threads: one (the player's). No I/O, no clock. Memory: a few dozen bytes per subject.
#pragma once

#include <array>
#include <cstdint>
#include <unordered_map>

#include "core/frame.hpp"

namespace mocap::daemon {

/// SYNC period assumed while a subject's own is not known (the suit's 100 Hz).
inline constexpr std::int64_t kDefaultSyncPeriodUs = 10'000;

class PlayPacer {
public:
    enum class Clamp : std::uint8_t { kNone, kGap, kBackward };
    struct Due {
        std::int64_t offset_us = 0;  ///< from the start of the pass
        Clamp clamp = Clamp::kNone;  ///< what about this sample was not played as recorded
        std::int64_t step_us = 0;    ///< the recorded step that was not played (kGap, kBackward)
    };

    /// max_gap_us: the longest wait between two samples of a subject (> 0).
    explicit PlayPacer(std::int64_t max_gap_us);

    /// When `s` is due; call for every sample of a pass in the file's order.
    Due next(const SegmentSample& s);
    /// Starts a new pass at offset 0 (learnt periods are kept).
    void restart();

    /// The latest offset handed out in this pass.
    [[nodiscard]] std::int64_t end_us() const { return end_us_; }
    /// The longest SYNC period of a subject seen in this pass (kDefaultSyncPeriodUs if none).
    [[nodiscard]] std::int64_t period_us() const;
    [[nodiscard]] std::int64_t max_gap_us() const { return max_gap_us_; }

private:
    static constexpr std::size_t kPeriods = 9;
    struct Subject {
        std::uint64_t sync = 0;                        // latest SYNC instant
        std::int64_t t_us = 0;                         // its sample instant
        std::int64_t received_us = 0;                  // the previous sample's receive time
        std::int64_t offset_us = 0;                    // the latest instant's offset
        std::array<std::int64_t, kPeriods> periods{};  // recent period candidates (ring)
        std::size_t n_periods = 0;
        std::size_t next_period = 0;
        bool placed = false;  // seen in this pass
    };
    [[nodiscard]] std::int64_t period_of(const Subject& p) const;

    std::int64_t max_gap_us_;
    std::int64_t end_us_ = 0;
    std::unordered_map<std::uint32_t, Subject> subjects_;
};

}  // namespace mocap::daemon
