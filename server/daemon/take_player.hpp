// take_player.hpp — `mocapd --play FILE...`: a recorded take served as if it were live.
//
// The player stands in for the ingest sources (the sink listener and the SocketCAN readers
// are not opened): it reads raw recordings (serve/raw_recorder.hpp) in order and hands each
// sample to the daemon's router at the pace it was received when recorded, so the pose
// service, live BVH, the viewer and VMC serve it exactly as they serve sinks. The cluster is
// off while a take is played (daemon.cpp): the take is not the venue's. A client developer can work without a suit on.
//
// Times: every sample keeps its spacing but is moved to now. The sample instant (t_us) and the
// sink's send time are shifted by one offset per pass, and each subject's SYNC counter by its
// own span, so each segment's times and SYNCs keep increasing; received_us is the real time the player handed the
// sample on, as an ingest source stamps it. With `loop`, the take starts again after its last sample (one SYNC period
// later), shifted by the length of the take, forever.
//
// Errors: a file that cannot be opened is refused at start; a corrupt record later ends the
// pass with a logged error and a counted `errors` (a loop then starts again from the first
// file); a truncated final record ends that file, as in a replay.
//
// Threads: runs on the ingest io_context (a steady timer); route() is called on that thread,
// as the ingest sources call it. Counters, component "play": samples, passes, errors.
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
#include "serve/raw_recorder.hpp"

namespace mocap {
class MetricsRegistry;
}

namespace mocap::daemon {

struct PlayOptions {
    std::vector<std::string> files;  ///< raw recordings, played in this order as one take
    bool loop = false;               ///< start again after the last sample, forever
};

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

private:
    /// Reads the next sample of the take into next_; false at the end of a pass.
    bool read_next();
    /// Starts a pass at file 0; false if it cannot.
    bool begin_pass(std::string* error);
    void schedule();
    void play_due();
    [[nodiscard]] std::int64_t due_us(const SegmentSample& s) const;

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
    std::int64_t first_received_us_ = 0;
    std::int64_t last_received_us_ = 0;
    std::unordered_map<std::uint32_t, SyncExtent> syncs_;

    // This pass: the shifts it applies (a sample is due at its received_us + time_shift_us_).
    std::int64_t time_shift_us_ = 0;
    std::unordered_map<std::uint32_t, std::uint64_t> sync_shift_;

    Counter samples_, passes_, errors_;
    CounterGroup group_{"play"};
};

}  // namespace mocap::daemon
