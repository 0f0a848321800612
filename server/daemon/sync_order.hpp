// sync_order.hpp — a replay's samples in SYNC order where a recording holds them out of order.
//
// One host records a segment's samples in SYNC order. A take that two hosts wrote (a failover,
// docs/cluster.md) can hold some out of order: a host that froze receives the packets its sink
// sent before moving on only when it wakes, and publishes them after the next host's first
// samples. Replayed as stored, those samples would hand each filter a time that runs backwards.
//
// SyncOrder holds the last `window` samples in the order they were read and passes them on
// unchanged, except a sample whose SYNC is behind a SYNC already read for the same segment
// (subject, segment): that one is put in front of the first held sample of its subject with a
// later SYNC, where it belongs, and takes that sample's received time if its own is later
// (the replay's assembler clock is the received time, which must not jump ahead). A recording without such a sample
// passes through unchanged (the same order, so the same frames). A sample too late for that (its segment has passed its
// SYNC already) is dropped and counted: a filter cannot go back in time.
//
// Threads: one (the replay's). Memory: at most `window` samples (~180 B each).
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <unordered_map>

#include "core/frame.hpp"

namespace mocap::daemon {

class SyncOrder {
public:
    using Emit = std::function<void(const SegmentSample&)>;
    /// Samples held back (the default holds about a minute of 15 segments at 100 Hz).
    static constexpr std::size_t kDefaultWindow = 1u << 17;

    SyncOrder(Emit emit, std::size_t window = kDefaultWindow);

    void push(const SegmentSample& s);
    /// Passes on every held sample (the end of the recording).
    void flush();

    /// Samples moved back to their SYNC's place, and samples dropped as too late.
    [[nodiscard]] std::uint64_t reordered() const { return reordered_; }
    [[nodiscard]] std::uint64_t too_late() const { return too_late_; }

private:
    static std::uint64_t key(const SegmentSample& s) { return (std::uint64_t{s.subject_id} << 16) | s.segment_index; }
    void emit_front();

    Emit emit_;
    std::size_t window_;
    std::deque<SegmentSample> held_;
    std::unordered_map<std::uint64_t, std::uint64_t> newest_read_;  // per segment: highest SYNC read
    std::unordered_map<std::uint64_t, std::uint64_t> newest_sent_;  // per segment: highest SYNC passed on
    std::uint64_t reordered_ = 0;
    std::uint64_t too_late_ = 0;
};

}  // namespace mocap::daemon
