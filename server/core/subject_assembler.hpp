// subject_assembler.hpp — joins the segments of one SYNC instant of one subject into one
// SubjectFrame, in SYNC order, and never waits forever for a missing segment.
//
// Threads: everything here runs on ONE thread, the assembler thread (the one that drains the
// WorkerPool), except stats(), counters() and assembly_snapshot(), which any thread may read.
// Time is injected: every call takes now_us (the caller's clock, µs; the same clock as the
// stage stamps).
//
// The assembler thread's loop (the daemon owns it; `clock` is its Clock):
//     while (running) {
//         pool.drain([&](const PoseUpdate& u) { set.on_pose(u, clock.now_us()); });
//         set.advance(clock.now_us());                 // deadlines, even with no input
//         const std::int64_t next = set.next_deadline_us();
//         pool.wait_for_output(next == kNoDeadline ? idle_us : next - clock.now_us());
//     }
//     // shutdown: pool.stop(); drain until drain() returns 0; set.flush(clock.now_us());
//
// Rules for one subject
// - An instant (SYNC value) opens when its first segment pose arrives; now_us of that arrival
//   starts its deadline.
// - The oldest open instant is emitted as soon as it is resolved: every segment has either
//   delivered a pose for it, delivered a pose for a LATER instant (segments reach the assembler
//   in order, so this one will not come), or is "dead" (see below); otherwise it is emitted
//   when now_us >= first arrival + deadline_us. Newer instants wait behind older ones, so
//   frames go out in strictly increasing SYNC order (gaps in SYNC are simply skipped).
// - A segment missing from an emitted frame is flagged kSegmentStale and holds its last good
//   pose (the newest pose received for it, with its own sample_us); a segment never received
//   is kSegmentStale | kSegmentNeverSeen with identity orientation.
// - Dead segments (skip_dead_segments): a segment that was missing when a frame had to be
//   emitted (deadline or window overflow) and had delivered nothing newer is not waited for
//   again until it delivers a pose. One dead node thus costs one deadline, not one per frame;
//   when it returns it is waited for again (recovery).
// - A pose for an instant at or below the last emitted SYNC is late: counted
//   (segments_late), dropped, but it still updates the held pose.
// - At most `window` instants are open; a pose that would open one more forces the oldest out
//   (frames_forced, emitted with whatever it has).
//
// Memory: window × sizeof(SubjectFrame) (~1.6 KiB) per subject, allocated at construction.
// The hot path (on_pose/advance) never allocates. Cost: O(1) per pose, plus per emitted frame
// a scan of the window (32 slots by default) and the frame copy (measured in
// docs/performance.md).
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "core/counters.hpp"
#include "core/frame.hpp"
#include "core/latency_histogram.hpp"
#include "core/metrics_registry.hpp"
#include "core/segment_processor.hpp"

namespace mocap {

inline constexpr std::int64_t kNoDeadline = std::numeric_limits<std::int64_t>::max();

struct AssemblerConfig {
    std::int64_t deadline_us = 20'000;  ///< wait after the first segment of an instant, µs
    std::size_t window = 32;            ///< open SYNC instants per subject (>= 1)
    bool skip_dead_segments = true;     ///< see "Dead segments" above
};

/// Receives emitted frames, on the assembler thread. The frame is valid only during the call
/// (copy or encode it there). Must not block.
class FrameSink {
public:
    virtual ~FrameSink() = default;
    virtual void on_frame(const SubjectFrame& frame) = 0;
};

/// Counters of one subject; AssemblerSet sums them across subjects.
struct AssemblerCounters {
    Counter frames_complete;     ///< every segment delivered for the instant
    Counter frames_partial;      ///< emitted with >= 1 stale segment
    Counter frames_forced;       ///< emitted early because the window was full
    Counter segments_late;       ///< pose for an instant already emitted (or outside the window)
    Counter segments_stale;      ///< stale segments in emitted frames
    Counter segments_duplicate;  ///< second pose of a segment for one instant (first kept)
    Counter segments_invalid;    ///< wrong subject or segment index out of range
    /// Adds every counter to `group` under its field name.
    void add_to(CounterGroup& group) const;
};

class SubjectAssembler {
public:
    /// @param sink not owned, must outlive this. @param assembly optional histogram of
    ///        filtered_us -> assembled_us per frame (not owned).
    /// @throws std::invalid_argument if segment_count is 0 or > kMaxSegments, or window is 0.
    SubjectAssembler(std::uint32_t subject_id, std::uint16_t segment_count, const AssemblerConfig& config,
                     FrameSink& sink, LatencyHistogram* assembly = nullptr);

    SubjectAssembler(const SubjectAssembler&) = delete;
    SubjectAssembler& operator=(const SubjectAssembler&) = delete;

    /// Adds one segment pose; may emit frames (those it resolves and those past deadline).
    void on_pose(const PoseUpdate& update, std::int64_t now_us);
    /// Emits every frame that is resolved or past its deadline at now_us.
    void advance(std::int64_t now_us);
    /// Emits every open instant now, in order (shutdown).
    void flush(std::int64_t now_us);
    /// When advance() must next be called (the oldest open instant's deadline), or kNoDeadline.
    [[nodiscard]] std::int64_t next_deadline_us() const noexcept;
    /// Changes the deadline (config reload); applies to open instants too. deadline_us >= 0.
    void set_deadline_us(std::int64_t deadline_us) noexcept { config_.deadline_us = deadline_us; }

    [[nodiscard]] std::uint32_t subject_id() const noexcept { return subject_id_; }
    [[nodiscard]] std::uint16_t segment_count() const noexcept { return segment_count_; }
    [[nodiscard]] std::size_t open_instants() const noexcept { return open_count_; }
    /// Any thread.
    [[nodiscard]] const AssemblerCounters& stats() const noexcept { return stats_; }

private:
    struct Instant {
        bool open = false;
        std::int64_t first_us = 0;  // now_us when its first segment arrived
        std::uint32_t have_mask = 0;
        SubjectFrame frame{};  // sync, sample_us, times and the delivered segments
    };

    static constexpr std::size_t kNoSlot = static_cast<std::size_t>(-1);
    [[nodiscard]] std::size_t oldest_index() const noexcept;
    [[nodiscard]] Instant* oldest() noexcept;
    [[nodiscard]] bool resolved(const Instant& in) const noexcept;
    void emit(Instant& in, std::int64_t now_us);
    void emit_due(std::int64_t now_us, bool all);

    std::uint32_t subject_id_;
    std::uint16_t segment_count_;
    std::uint32_t all_mask_;
    AssemblerConfig config_;
    FrameSink& sink_;
    LatencyHistogram* assembly_;

    std::vector<Instant> instants_;  // slot = sync % window
    std::size_t open_count_ = 0;
    mutable std::size_t oldest_index_ = kNoSlot;  // cache of oldest_index(); kNoSlot = rescan
    bool emitted_any_ = false;
    std::uint64_t last_emitted_sync_ = 0;

    std::uint32_t seen_mask_ = 0;  // segments that delivered at least once
    std::uint32_t dead_mask_ = 0;  // segments not waited for (see header)
    std::array<std::uint64_t, kMaxSegments> newest_sync_{};
    std::array<SegmentPose, kMaxSegments> last_good_{};
    SubjectFrame out_{};  // emission scratch: the sink sees this

    AssemblerCounters stats_;
};

/// Routes poses to the SubjectAssembler of their subject. Same threading as SubjectAssembler;
/// add_subject() is set-up only (before the assembler thread and any stats reader start).
class AssemblerSet {
public:
    /// @param sink not owned, must outlive this; receives the frames of every subject.
    AssemblerSet(const AssemblerConfig& config, FrameSink& sink);

    /// Set-up only. @throws std::logic_error for a duplicate subject, std::invalid_argument
    /// as SubjectAssembler.
    SubjectAssembler& add_subject(std::uint32_t subject_id, std::uint16_t segment_count);

    /// Assembler thread. Unknown subjects are counted (poses_unknown_subject) and dropped.
    void on_pose(const PoseUpdate& update, std::int64_t now_us);
    void advance(std::int64_t now_us);
    void flush(std::int64_t now_us);
    /// Earliest deadline over all subjects, or kNoDeadline. O(subjects).
    [[nodiscard]] std::int64_t next_deadline_us() const noexcept;
    /// Assembler thread: new deadline for every subject (config reload).
    void set_deadline_us(std::int64_t deadline_us) noexcept;

    [[nodiscard]] const SubjectAssembler* find(std::uint32_t subject_id) const noexcept;
    [[nodiscard]] std::size_t subject_count() const noexcept { return subjects_.size(); }

    /// Any thread (after set-up). Component "assembler": the AssemblerCounters fields summed
    /// over subjects, plus poses_unknown_subject.
    [[nodiscard]] const CounterGroup& counters() const noexcept { return counters_; }
    /// Any thread. filtered_us -> assembled_us of every emitted frame.
    [[nodiscard]] LatencySnapshot assembly_snapshot() const noexcept { return assembly_.snapshot(); }
    /// Set-up, after every add_subject(): the counters, stage latency "assembly" and gauge
    /// "subjects_configured".
    void register_metrics(MetricsRegistry& registry) const;

private:
    [[nodiscard]] SubjectAssembler* lookup(std::uint32_t subject_id) const noexcept;

    AssemblerConfig config_;
    FrameSink& sink_;
    std::vector<std::unique_ptr<SubjectAssembler>> subjects_;  // sorted by subject id
    LatencyHistogram assembly_;
    Counter unknown_subject_;
    CounterGroup counters_{"assembler"};
};

}  // namespace mocap
