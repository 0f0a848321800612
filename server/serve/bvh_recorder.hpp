// bvh_recorder.hpp — daemon-side BVH file recorder, started and stopped by the control
// request (StartRecording / StopRecording), and the repair of a file a crash left behind.
//
// File layout: BvhFrameEncoder::hierarchy(), "MOTION\n", "Frames: NNNNNNNNNN\n" (ten
// digits, zero-padded, so the count can be rewritten in place), "Frame Time: T\n" (the
// configured value, or the recorded subject's measured interval: "%.6f" of a value under
// 10 s, eight characters, rewritten in place with the count; 0.010000 until measured), then
// one MOTION line per frame of ONE subject (the configured `subject`, or with 0 the first
// subject that delivers a frame after start). Every importer reads the zero-padded count
// as a number (checked with assimp, Blender and three.js: docs/outputs.md).
// Crash safety: lines are written by a writer thread every flush_interval_s, and after
// each write the count is patched to the number of whole lines written, so a killed
// daemon leaves a file that loads (up to the last flush). If it was killed between the
// write and the patch, `mocap-bvh-repair FILE` (repair_bvh_file) counts the complete
// MOTION lines, cuts a partial last line and rewrites the count.
// Write failures (a full disk): lines go to a tracked offset and a failed write is cut back
// to the last whole line (serve/record_file.hpp), so the file always holds whole lines and a
// count that matches them. The recording then stops: the writer logs the reason ONCE, counts
// the frames it could not write (frames_lost), and the next stop() answers false with that
// reason and the number of frames the file holds. A new start() works again once there is
// room (a file whose header cannot be written is removed).
//
// Threads: publish() on the assembler thread (cheap when not recording: one atomic load;
// recording: encode one line, append it to a buffer under a short lock, never I/O).
// start()/stop() on any thread (a control request); they open/close the file and start/join
// the writer thread, so they take milliseconds.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>

#include "core/counters.hpp"
#include "core/frame.hpp"
#include "core/metrics_registry.hpp"
#include "serve/bvh_frame_encoder.hpp"
#include "serve/frame_interval.hpp"
#include "serve/record_file.hpp"
#include "skeleton/skeleton_pose.hpp"

namespace mocap::serve {

struct BvhRecorderConfig {
    std::string directory = ".";               ///< where "" paths go: mocap-<n>.bvh
    std::uint32_t subject = 0;                 ///< 0 = first subject with a frame
    double flush_interval_s = 1.0;             ///< write + patch the count this often
    std::size_t max_buffer_bytes = 16u << 20;  ///< beyond this frames are dropped (counted)
};

class BvhRecorder {
public:
    /// `encoder` and `writer` (how the file is written; tests inject failures) must outlive the recorder.
    BvhRecorder(BvhRecorderConfig config, const BvhFrameEncoder& encoder, FileWriter& writer = system_file_writer());
    ~BvhRecorder();
    BvhRecorder(const BvhRecorder&) = delete;
    BvhRecorder& operator=(const BvhRecorder&) = delete;

    /// Any thread. Starts a recording to `requested` ("" = <directory>/mocap-<first free n>.bvh).
    /// Fails if one is running or the file cannot be created (an existing file is not
    /// overwritten). On success *opened_path (if given) is the file.
    bool start(const std::string& requested, std::string* error, std::string* opened_path = nullptr);
    /// Any thread. Starts a recording into an empty file the caller opened for writing (a
    /// take export's memfd, daemon/take_export.hpp); the recorder writes into a dup of `fd`,
    /// closes that dup when it stops, and names the file `name` in its messages.
    bool start_fd(int fd, const std::string& name, std::string* error);
    /// Any thread. Writes the rest, patches the count, closes; *frames = whole frames in the
    /// file. False if none is running, or if the recording had stopped on a write failure
    /// (*error says why and how many frames the file holds; *frames is set as well).
    bool stop(std::string* error, std::uint64_t* frames = nullptr);

    /// Assembler thread.
    void publish(const SubjectFrame& frame, const skeleton::SkeletonPose& pose);

    [[nodiscard]] bool recording() const { return recording_.load(std::memory_order_acquire); }
    /// Any thread. A file is open: recording, or stopped by a write failure and not yet
    /// stop()ped.
    [[nodiscard]] bool has_file() {
        std::lock_guard control(control_mutex_);
        return writer_.joinable();
    }
    /// Component "bvh_record": recordings_started, frames_recorded (written to the file),
    /// frames_dropped (buffer full), frames_lost (the file could not take them),
    /// write_errors, disk_full, recordings_failed (stopped by a write failure).
    [[nodiscard]] const CounterGroup& counters() const { return group_; }
    /// Set-up: the counters above.
    void register_metrics(MetricsRegistry& registry) const { registry.add(group_); }

private:
    void writer_loop();
    /// Writes what is pending; on a failure records it in failure_ and returns false.
    bool write_pending(std::string& scratch);
    /// Stops the writer thread and closes the file (control_mutex_ held).
    void finish();
    /// start()'s second half, on an open fd (control_mutex_ held); `created`: unlink on failure.
    bool start_locked(int fd, const std::string& path, bool created, std::string* error, std::string* opened_path);

    BvhRecorderConfig config_;
    const BvhFrameEncoder& encoder_;
    std::mutex control_mutex_;  // serialises start/stop

    std::atomic<bool> recording_{false};
    std::mutex mutex_;  // guards the fields below
    std::condition_variable wake_;
    std::string pending_;  // whole lines not yet written
    std::uint64_t pending_frames_ = 0;
    std::uint32_t subject_ = 0;  // assembler thread once recording (set at start)
    FrameInterval interval_;     // of the recorded subject's frames
    bool stop_writer_ = false;

    int fd_ = -1;
    std::string path_;
    std::uint64_t count_offset_ = 0;  // file offset of the ten count digits
    std::uint64_t file_end_ = 0;      // end of the last whole line written
    std::uint64_t frames_written_ = 0;
    std::string failure_;  // why the writer stopped early (writer thread, read after join)
    FileWriter& file_writer_;
    std::thread writer_;
    std::string line_;  // assembler thread scratch

    Counter started_, recorded_, dropped_, lost_, write_errors_, disk_full_, failed_;
    CounterGroup group_{"bvh_record"};
};

/// Width of the zero-padded frame count in files this recorder writes.
inline constexpr int kBvhCountDigits = 10;

struct BvhRepairResult {
    bool ok = false;
    std::string error;
    std::uint64_t frames = 0;         ///< complete MOTION lines kept
    std::uint64_t bytes_cut = 0;      ///< partial last line removed
    std::uint64_t frames_before = 0;  ///< the count the header claimed
};

/// Repairs a BVH file in place: the count becomes the number of complete MOTION lines
/// (each must hold the values the HIERARCHY declares; a short/partial LAST line is cut;
/// a bad line elsewhere is an error). Works on any BVH whose "Frames:" field is wide
/// enough for the new count (always true for files this recorder wrote).
BvhRepairResult repair_bvh_file(const std::string& path);

}  // namespace mocap::serve
