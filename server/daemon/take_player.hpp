// take_player.hpp — `mocapd --play FILE...`: a recorded take served as if it were live.
//
// The player stands in for the ingest sources (the sink listener and the SocketCAN readers
// are not opened): it reads raw recordings (serve/raw_recorder.hpp) in order and hands each
// sample to the daemon's router at the pace it was received when recorded, so the pose
// service, live BVH, the viewer and VMC serve it exactly as they serve sinks. The cluster is
// off while a take is played (daemon.cpp): the take is not the venue's. A client developer can work without a suit on.
//
// Times: a sample is due when the pacer says (daemon/play_pacer.hpp): at its recorded sample
// instant where the SYNC counter bears it out, else by the SYNC counter and the take's own
// SYNC period, never more than max_gap_s after the previous sample of its subject, so a
// receive-time jump of an hour, a clock step backwards or a span that overflows int64 in a
// hostile file costs at most max_gap_s and never a spin. No wait is longer than max_gap_s or
// a pass: a longer one means the host's own clock stepped back, and the take goes on from
// now instead of freezing. The sample instant (t_us)
// becomes the time it is due, the sink's send time keeps its distance before the receive time
// (at most max_gap_s), and each subject's SYNC counter is shifted by its own span per pass, so
// each segment's times and SYNCs keep increasing; received_us is the real time the player
// handed the sample on, as an ingest source stamps it. With `loop`, the take starts again one
// SYNC period after its last sample, and a pass lasts at least kMinPassUs (a take whose
// samples all sit at one instant is served 10 times a second, not as fast as the CPU goes).
// What was not played as recorded is logged once per kind (a gap clamped, a step backwards)
// and counted (play.gaps_clamped, play.steps_back).
//
// Errors: a file that cannot be opened is refused at start; a corrupt record later ends the
// pass with a logged error and a counted `errors` (a loop then starts again from the first
// file); a truncated final record ends that file, as in a replay.
//
// Threads: runs on the ingest io_context (a steady timer); route() is called on that thread,
// as the ingest sources call it. Counters, component "play": samples, passes, errors,
// gaps_clamped, steps_back.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/asio.hpp"
#include "core/clock.hpp"
#include "core/counters.hpp"
#include "core/frame.hpp"
#include "daemon/play_pacer.hpp"
#include "serve/raw_recorder.hpp"

namespace mocap {
class MetricsRegistry;
}

namespace mocap::daemon {

struct PlayOptions {
    std::vector<std::string> files;  ///< raw recordings, played in this order as one take
    bool loop = false;               ///< start again after the last sample, forever
    double max_gap_s = 1.0;          ///< a longer wait between two samples of a subject is played as this
};

/// The shortest pass of a loop, µs.
inline constexpr std::int64_t kMinPassUs = 100'000;

class TakePlayer {
public:
    using Route = std::function<void(const SegmentSample&)>;
    /// route: called on the io_context's thread for every sample, at its time.
    TakePlayer(asio::io_context& io, PlayOptions options, const Clock& clock, Route route);

    /// Opens every file (so a typo is refused before anything is served) and schedules the
    /// first sample. False + error naming the file otherwise.
    bool start(std::string* error);
    void register_metrics(MetricsRegistry& registry) const;

    /// Any thread: samples handed on so far, passes begun.
    [[nodiscard]] std::uint64_t samples() const { return samples_.value(); }
    [[nodiscard]] std::uint64_t passes() const { return passes_.value(); }
    /// Any thread: recorded steps longer than the SYNC allows or than max_gap_s (played as
    /// the SYNC says, at most max_gap_s) and steps backwards (played as the SYNC says, or as
    /// no wait where there is no SYNC).
    [[nodiscard]] std::uint64_t gaps_clamped() const { return gaps_clamped_.value(); }
    [[nodiscard]] std::uint64_t steps_back() const { return steps_back_.value(); }

private:
    /// Reads the next sample of the take into next_; false at the end of a pass.
    bool read_next();
    /// Starts a pass at file 0; false if it cannot.
    bool begin_pass(std::string* error);
    void schedule();
    void play_due();
    /// Counts (and logs, once per kind) what the pacer did not play as recorded.
    void report(const PlayPacer::Due& due);

    asio::io_context& io_;
    PlayOptions options_;
    const Clock& clock_;
    Route route_;
    asio::steady_timer timer_;

    serve::RawRecordingReader reader_;
    std::size_t file_ = 0;
    SegmentSample next_{};
    bool have_next_ = false;
    bool ended_ = false;  // the take ended without `loop` (or a pass could not start)

    // The take's extent, learnt during the first pass. Every sink counts its own SYNCs, so
    // they are kept (and shifted) per subject.
    struct SyncExtent {
        std::uint64_t first = 0;
        std::uint64_t last = 0;
    };
    bool have_first_ = false;
    std::unordered_map<std::uint32_t, SyncExtent> syncs_;

    // This pass: when it started on the clock, and when next_ is due.
    PlayPacer pacer_;
    std::int64_t pass_start_us_ = 0;
    std::int64_t next_due_us_ = 0;
    std::unordered_map<std::uint32_t, std::uint64_t> sync_shift_;
    bool logged_gap_ = false;
    bool logged_back_ = false;

    Counter samples_, passes_, errors_, gaps_clamped_, steps_back_;
    CounterGroup group_{"play"};
};

}  // namespace mocap::daemon
