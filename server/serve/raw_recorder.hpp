// raw_recorder.hpp — append-only recording of every decoded sample (proto/mocap/v1/
// recording.proto), and the reader that replay uses.
//
// Writing. push() is called by the ingest thread (the ONE producer) for every sample it
// routes; it copies the sample into a bounded SPSC ring (core/spsc_ring.hpp) and returns:
// no lock, no allocation, no I/O on the pipeline. When the ring is full the sample is
// dropped and counted (samples_dropped). A writer thread owned by the recorder drains the
// ring, encodes each sample as a length-delimited RawRecord into a buffer and write()s the
// buffer every flush_interval_s. What write() returned is in the kernel's page cache, so a
// killed daemon loses at most the last flush interval (plus what was still in the ring);
// a power cut additionally loses what the kernel had not written back (fsync_on_rotate
// syncs only at rotation).
// A file only ever ends on a whole record (serve/record_file.hpp): a write that fails, in
// part or in whole, is cut back to the last whole record.
// Write failures (a full disk, a record directory that was removed so the next rotation
// cannot create its file): the recorder pauses, logs the reason ONCE (the errno text), keeps
// encoding into its buffer up to max_buffer_bytes and counts every sample beyond that as
// lost (samples_lost), then retries on a back-off (retry_min_s doubling to retry_max_s):
// the same file after a failed write, a new file after a failed open. When a retry succeeds
// it writes the buffer, logs that it resumed and how many samples were lost, and goes on.
// Memory stays bounded by ring_capacity samples + max_buffer_bytes whatever the disk does.
// Rotation: a new file when the current one reaches rotate_bytes or has been open
// rotate_s (0 = never). Files are named <directory>/raw-YYYYmmdd-HHMMSS-<index>.mocapraw
// (UTC time of the recording's start, index 0, 1, 2... per rotation).
//
// Reading. RawRecordingReader reads one file record by record; a truncated last record
// (the file of a killed daemon) ends the file cleanly (truncated() tells). The same reader
// reads the records of a JetStream raw message from memory (open_records).
//
// Threads: push() on the producer thread; start()/stop() on the owner's thread (the
// daemon, before ingest starts / after it stopped); counters() on any thread.
// Memory: ring_capacity × sizeof(SegmentSample) (~200 B) allocated at construction.
#pragma once

#include <atomic>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "core/clock.hpp"
#include "core/counters.hpp"
#include "core/frame.hpp"
#include "core/metrics_registry.hpp"
#include "core/spsc_ring.hpp"
#include "serve/record_file.hpp"

namespace mocap::serve {

/// Encoded records the raw recorder holds while its file cannot take them (~100 s of one
/// 15-node subject at 100 Hz); beyond it samples are counted as lost.
inline constexpr std::size_t kRawMaxBufferBytes = 16u << 20;

struct RawRecorderConfig {
    std::string directory = ".";
    double flush_interval_s = 1.0;                      ///< write() at least this often
    std::uint64_t rotate_bytes = 256u << 20;            ///< start a new file beyond this size; 0 = never
    double rotate_s = 3600.0;                           ///< start a new file after this long; 0 = never
    std::size_t ring_capacity = 16384;                  ///< samples between ingest and the writer (power of 2)
    bool fsync_on_rotate = true;                        ///< fsync a file when it is closed
    std::size_t max_buffer_bytes = kRawMaxBufferBytes;  ///< encoded samples held while writes fail
    double retry_min_s = 0.25;                          ///< first retry after a failed write or open
    double retry_max_s = 5.0;                           ///< the back-off doubles up to this
};

class RawRecorder {
public:
    /// `clock`: wall clock for file names and the flush/rotation/retry timers (not owned);
    /// `writer`: how the file is written (tests inject failures; not owned).
    RawRecorder(RawRecorderConfig config, const Clock& clock, FileWriter& writer = system_file_writer());
    ~RawRecorder();
    RawRecorder(const RawRecorder&) = delete;
    RawRecorder& operator=(const RawRecorder&) = delete;

    /// Opens the first file and starts the writer thread. False + error if the directory
    /// is not writable.
    [[nodiscard]] bool start(std::string* error);
    /// Writes everything pushed so far, closes the file, joins the thread. Idempotent.
    void stop();

    /// Producer thread only. Never blocks; false when the ring was full (counted).
    bool push(const SegmentSample& sample) noexcept;

    /// Path of the file being written ("" before start / after stop). Writer-thread value,
    /// read under a lock.
    [[nodiscard]] std::string current_path() const;
    /// The first write failure of this recorder, as logged ("write FILE failed: No space
    /// left on device"); "" if none. Read after stop() (the writer thread sets it).
    [[nodiscard]] const std::string& first_failure() const { return first_failure_; }
    /// Component "raw_record": samples_recorded (written to a file), samples_dropped (ring
    /// full), samples_lost (the file could not take them and the buffer was full, or still
    /// unwritten at stop), bytes_written, files_opened, write_errors (failed writes and
    /// opens, retries included), disk_full (times a write found the disk full),
    /// write_pauses (times writing paused on an error).
    [[nodiscard]] const CounterGroup& counters() const { return group_; }
    /// Set-up: the counters above.
    void register_metrics(MetricsRegistry& registry) const { registry.add(group_); }
    /// True while writing is paused on an error (writer-thread value, any thread).
    [[nodiscard]] bool paused() const { return paused_.load(std::memory_order_relaxed); }

private:
    /// 0, or the errno of the failure (described in *error).
    int open_next(std::string* error);
    void close_file();
    void writer_loop();
    bool flush_buffer();
    void buffer_sample(const SegmentSample& s);
    void retry();
    /// Counts a failed write/open; the first of an episode pauses writing and logs `what`.
    void on_failure(int err, const std::string& what);

    RawRecorderConfig config_;
    const Clock& clock_;
    FileWriter& file_writer_;
    SpscRing<SegmentSample> ring_;
    std::thread writer_;
    std::atomic<bool> stop_{false};

    // Writer thread (and start/stop before/after it runs).
    int fd_ = -1;
    std::uint32_t file_index_ = 0;
    std::string series_stamp_;
    std::string first_failure_;  // writer thread, then whoever called stop()
    std::uint64_t file_bytes_ = 0;
    std::int64_t file_opened_us_ = 0;
    std::string buffer_;  // whole encoded records not yet written
    std::uint64_t buffer_samples_ = 0;
    std::int64_t retry_at_us_ = 0;  // while paused
    std::int64_t retry_delay_us_ = 0;
    std::uint64_t lost_in_pause_ = 0;
    std::atomic<bool> paused_{false};
    mutable std::mutex path_mutex_;
    std::string path_;

    Counter recorded_, dropped_, lost_, bytes_, files_, write_errors_, disk_full_, pauses_;
    CounterGroup group_{"raw_record"};
};

/// Encodes one sample as a length-delimited RawRecord, appended to `out`.
void append_raw_sample_record(const SegmentSample& sample, std::string& out);

/// Reads a raw recording file record by record. Not thread-safe; one per file.
class RawRecordingReader {
public:
    /// Opens and checks the magic. False + error otherwise.
    bool open(const std::string& path, std::string* error);
    /// Reads records from memory instead: the records of a file without its magic and header,
    /// as one JetStream raw message carries them (cluster/raw_stream.hpp). Replaces what was
    /// open (truncation included); samples_read() goes on counting. False + error if `records` is empty.
    bool open_records(std::string records, std::string* error);
    /// Next sample: 1 = got one, 0 = end of file, -1 = corrupt record (error set).
    /// A truncated final record (what a crash or a full disk can leave) counts as the end of
    /// the file: truncated() = true, truncation() says what was skipped.
    int next(SegmentSample& out, std::string* error);
    [[nodiscard]] bool truncated() const { return truncated_; }
    /// "" or what was skipped at the end, e.g. "a cut record (37 of 90 bytes) after sample
    /// 1200, skipped".
    [[nodiscard]] const std::string& truncation() const { return truncation_; }
    [[nodiscard]] std::uint64_t samples_read() const { return samples_; }

private:
    void cut_tail(const std::string& what);

    std::string memory_;  // open_records(): what file_ reads (declared first: closed after it)
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> file_{nullptr, &std::fclose};
    std::string record_;
    bool truncated_ = false;
    std::string truncation_;
    std::uint64_t samples_ = 0;
};

inline constexpr char kRawMagic[8] = {'M', 'O', 'C', 'A', 'P', 'R', 'A', 'W'};

}  // namespace mocap::serve
