// take_recorder.hpp — starts and stops takes (serve/take_store.hpp) on control requests and
// records every sample of a running take with a RawRecorder (serve/raw_recorder.hpp).
//
// start(name, notes) creates the take's directory and its sidecar (start time, the
// configured filter, notes), copies the calibration files in use (calibration-subject-*.toml
// of `calibration_dir`) into it, and starts a RawRecorder writing into it without rotation
// (one raw file per take). stop() stops the recorder (everything pushed so far is written,
// the file fsync'ed) and rewrites the sidecar with the stop time, the subjects seen and the
// sample counts. One take at a time.
// Loss bounds are the RawRecorder's: a killed daemon loses at most the last flush interval
// (record_flush_interval_s, 1 s by default) plus the ring; a full disk pauses the recorder
// and the file ends on a whole record; the sidecar is replaced atomically.
//
// Threads: push() on the ingest thread (the one producer); it reads one atomic when no take
// runs, and otherwise takes a mutex that start()/stop() hold only to hand the recorder
// over (never across file I/O), so the ingest thread never waits on a disk. start()/stop()
// from any thread (control requests; they serialise on their own mutex and take
// milliseconds: files are created, a thread started or joined). Memory: a running take
// holds ring_capacity samples (~200 B each) and the RawRecorder's buffer.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>

#include "core/clock.hpp"
#include "core/counters.hpp"
#include "core/frame.hpp"
#include "core/metrics_registry.hpp"
#include "serve/raw_recorder.hpp"
#include "serve/serve_config.hpp"
#include "serve/take_store.hpp"

namespace mocap::serve {

struct TakeRecorderConfig {
    RawRecorderConfig raw;        ///< directory and rotation are set per take
    std::string filter;           ///< the daemon's filter, written into the sidecar
    std::string calibration_dir;  ///< "" = no calibration files to copy
    /// A start is refused while the store's file system has less than this free for an
    /// unprivileged writer (0 = no check): a take started on a nearly full disk would lose
    /// its samples from its first second ([outputs] take_start_min_free_mb).
    std::uint64_t min_free_bytes = std::uint64_t{64} << 20;
};

class TakeRecorder {
public:
    /// `store` and `clock` must outlive the recorder.
    TakeRecorder(TakeStore& store, TakeRecorderConfig config, const Clock& clock);
    ~TakeRecorder();
    TakeRecorder(const TakeRecorder&) = delete;
    TakeRecorder& operator=(const TakeRecorder&) = delete;

    /// Any thread. name "" = "take-YYYYmmdd-HHMMSS" (UTC start; "-2", "-3"... if taken).
    /// Refused while a take runs, for an invalid or existing name, notes over
    /// kMaxTakeNotesBytes, less than config.min_free_bytes free on the store's file system,
    /// or a directory that cannot be written. result.take = the name.
    ControlResult start(const std::string& name, const std::string& notes);
    /// Any thread. Refused when no take runs. result.take = the name.
    ControlResult stop();

    /// Any thread: a take runs.
    [[nodiscard]] bool running() const { return active_.load(std::memory_order_relaxed); }

    /// Ingest thread only. Never blocks on I/O.
    void push(const SegmentSample& sample) noexcept;

    /// Component "take_record": takes_started, takes_stopped, takes_refused (start or stop
    /// refused), takes_refused_disk_full (starts of those refused for want of free space),
    /// samples_recorded, samples_lost (dropped by a full ring or lost to the disk;
    /// added when a take stops).
    [[nodiscard]] const CounterGroup& counters() const { return group_; }
    void register_metrics(MetricsRegistry& registry) const { registry.add(group_); }

private:
    std::string default_name(std::int64_t now_us) const;
    std::vector<std::string> copy_calibrations(const std::string& dir) const;
    /// "" when the store's file system has min_free_bytes free (or cannot be asked), else why not.
    std::string short_of_space() const;

    TakeStore& store_;
    TakeRecorderConfig config_;
    const Clock& clock_;

    std::mutex control_mutex_;  // serialises start/stop
    TakeMeta meta_;             // control_mutex_

    std::atomic<bool> active_{false};
    std::mutex push_mutex_;                     // hands recorder_ between control and ingest
    std::unique_ptr<RawRecorder> recorder_;     // push_mutex_
    std::array<std::uint32_t, 64> subjects_{};  // push_mutex_: subjects seen in the take
    std::size_t subject_count_ = 0;             // push_mutex_

    Counter started_, stopped_, refused_, refused_disk_full_, recorded_, lost_;
    CounterGroup group_{"take_record"};
};

}  // namespace mocap::serve
