#include "core/subject_assembler.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

namespace mocap {
namespace {

class RecordingSink : public FrameSink {
public:
    void on_frame(const SubjectFrame& frame) override { frames.push_back(frame); }
    std::vector<SubjectFrame> frames;
};

// A pose whose x component encodes (segment, sync) so held poses can be recognised.
PoseUpdate pose(std::uint32_t subject, std::uint16_t segment, std::uint64_t sync) {
    PoseUpdate u;
    u.subject_id = subject;
    u.segment_index = segment;
    u.sync = sync;
    u.pose.q_earth_sensor_wxyz = {1.0, segment * 1000.0 + static_cast<double>(sync), 0.0, 0.0};
    u.pose.sample_us = static_cast<std::int64_t>(sync) * 10'000;
    u.pose.flags = 0;
    return u;
}

double tag(const SegmentPose& p) {
    return p.q_earth_sensor_wxyz[1];
}

constexpr std::int64_t kDeadline = 20'000;

AssemblerConfig config(bool skip_dead = true, std::size_t window = 32) {
    AssemblerConfig c;
    c.deadline_us = kDeadline;
    c.window = window;
    c.skip_dead_segments = skip_dead;
    return c;
}

void feed(SubjectAssembler& a, std::uint64_t sync, std::vector<std::uint16_t> segments, std::int64_t now_us) {
    for (std::uint16_t k : segments)
        a.on_pose(pose(1, k, sync), now_us);
}

TEST(SubjectAssembler, EmitsACompleteFrameAtOnce) {
    RecordingSink sink;
    LatencyHistogram assembly;
    SubjectAssembler a(1, 3, config(), sink, &assembly);
    PoseUpdate u0 = pose(1, 0, 10), u1 = pose(1, 1, 10), u2 = pose(1, 2, 10);
    u0.times = {.sink_send_us = 100, .received_us = 200, .filtered_us = 300, .dequeued_us = 250};
    u1.times = {.sink_send_us = 90, .received_us = 210, .filtered_us = 330, .dequeued_us = 260};
    u2.times = {.sink_send_us = 95, .received_us = 205, .filtered_us = 310, .dequeued_us = 270};
    a.on_pose(u0, 1000);
    a.on_pose(u1, 1001);
    EXPECT_TRUE(sink.frames.empty());
    EXPECT_EQ(a.next_deadline_us(), 1000 + kDeadline);
    a.on_pose(u2, 1002);
    ASSERT_EQ(sink.frames.size(), 1u);
    const SubjectFrame& f = sink.frames[0];
    EXPECT_EQ(f.subject_id, 1u);
    EXPECT_EQ(f.sync, 10u);
    EXPECT_EQ(f.sample_us, 100'000);
    EXPECT_EQ(f.segment_count, 3u);
    for (std::uint16_t k = 0; k < 3; ++k) {
        EXPECT_EQ(f.segments[k].flags, 0u);
        EXPECT_EQ(tag(f.segments[k]), k * 1000.0 + 10);
    }
    EXPECT_EQ(f.times.sink_send_us, 90);    // earliest
    EXPECT_EQ(f.times.received_us, 200);    // earliest
    EXPECT_EQ(f.times.dequeued_us, 270);    // latest
    EXPECT_EQ(f.times.filtered_us, 330);    // latest
    EXPECT_EQ(f.times.assembled_us, 1002);  // injected now
    EXPECT_EQ(a.stats().frames_complete.value(), 1u);
    EXPECT_EQ(a.stats().frames_partial.value(), 0u);
    EXPECT_EQ(a.next_deadline_us(), kNoDeadline);
    EXPECT_EQ(assembly.snapshot().max_us, 1002u - 330u);
}

TEST(SubjectAssembler, DeadlineEmitsWithMissingSegmentsFlagged) {
    RecordingSink sink;
    SubjectAssembler a(1, 3, config(), sink);
    feed(a, 1, {0, 1}, 0);
    a.advance(kDeadline - 1);
    EXPECT_TRUE(sink.frames.empty());
    a.advance(kDeadline);
    ASSERT_EQ(sink.frames.size(), 1u);
    const SegmentPose& never = sink.frames[0].segments[2];
    EXPECT_EQ(never.flags, kSegmentStale | kSegmentNeverSeen);
    EXPECT_EQ(never.q_earth_sensor_wxyz, (std::array<double, 4>{1, 0, 0, 0}));
    EXPECT_EQ(a.stats().frames_partial.value(), 1u);
    EXPECT_EQ(a.stats().segments_stale.value(), 1u);
}

TEST(SubjectAssembler, StaleSegmentHoldsLastGoodPoseThenRecovers) {
    RecordingSink sink;
    SubjectAssembler a(1, 3, config(), sink);
    feed(a, 1, {0, 1, 2}, 0);    // complete: segment 2 known
    feed(a, 2, {0, 1}, 10'000);  // segment 2's node dies
    a.advance(10'000 + kDeadline);
    ASSERT_EQ(sink.frames.size(), 2u);
    const SegmentPose& held = sink.frames[1].segments[2];
    EXPECT_EQ(held.flags, kSegmentStale);
    EXPECT_EQ(tag(held), 2001.0);       // orientation from sync 1
    EXPECT_EQ(held.sample_us, 10'000);  // with its own age
    // Dead segment is not waited for again: sync 3 goes out as soon as 0 and 1 are in.
    feed(a, 3, {0, 1}, 40'000);
    ASSERT_EQ(sink.frames.size(), 3u);
    EXPECT_EQ(sink.frames[2].segments[2].flags, kSegmentStale);
    // Recovery: the node speaks again at sync 4 and is waited for from then on.
    feed(a, 4, {2}, 50'000);
    EXPECT_EQ(sink.frames.size(), 3u);
    feed(a, 4, {0, 1}, 50'001);
    ASSERT_EQ(sink.frames.size(), 4u);
    EXPECT_EQ(sink.frames[3].segments[2].flags, 0u);
    EXPECT_EQ(tag(sink.frames[3].segments[2]), 2004.0);
    feed(a, 5, {0, 1}, 60'000);
    EXPECT_EQ(sink.frames.size(), 4u);  // waits for segment 2 again
    EXPECT_EQ(a.stats().frames_complete.value(), 2u);
    EXPECT_EQ(a.stats().frames_partial.value(), 2u);
}

TEST(SubjectAssembler, WithoutSkipDeadEveryFrameWaitsForTheDeadline) {
    RecordingSink sink;
    SubjectAssembler a(1, 2, config(/*skip_dead=*/false), sink);
    feed(a, 1, {0}, 0);
    a.advance(kDeadline);
    ASSERT_EQ(sink.frames.size(), 1u);
    feed(a, 2, {0}, 30'000);
    EXPECT_EQ(sink.frames.size(), 1u);
    a.advance(30'000 + kDeadline);
    EXPECT_EQ(sink.frames.size(), 2u);
}

TEST(SubjectAssembler, LateSegmentIsCountedDroppedAndUpdatesTheHold) {
    RecordingSink sink;
    SubjectAssembler a(1, 2, config(), sink);
    feed(a, 1, {0, 1}, 0);
    feed(a, 2, {0}, 10'000);
    a.advance(10'000 + kDeadline);
    ASSERT_EQ(sink.frames.size(), 2u);
    EXPECT_EQ(tag(sink.frames[1].segments[1]), 1001.0);
    a.on_pose(pose(1, 1, 2), 31'000);  // sync 2 already out
    EXPECT_EQ(a.stats().segments_late.value(), 1u);
    EXPECT_EQ(sink.frames.size(), 2u);
    // Segment 1 spoke again, so it is waited for; at the deadline it holds the late pose.
    feed(a, 3, {0}, 40'000);
    a.advance(40'000 + kDeadline);
    ASSERT_EQ(sink.frames.size(), 3u);
    EXPECT_EQ(sink.frames[2].segments[1].flags, kSegmentStale);
    EXPECT_EQ(tag(sink.frames[2].segments[1]), 1002.0);
}

TEST(SubjectAssembler, FramesLeaveInSyncOrder) {
    RecordingSink sink;
    SubjectAssembler a(1, 2, config(), sink);
    feed(a, 6, {0}, 0);
    feed(a, 7, {0}, 1'000);
    EXPECT_TRUE(sink.frames.empty());
    EXPECT_EQ(a.next_deadline_us(), kDeadline);  // the oldest instant's
    // Segment 1 delivers 7, so its 6 will not come (in-order delivery): 6 goes at once,
    // flagged and holding segment 1's newest pose, then the now complete 7.
    feed(a, 7, {1}, 1'001);
    ASSERT_EQ(sink.frames.size(), 2u);
    EXPECT_EQ(sink.frames[0].sync, 6u);
    EXPECT_EQ(sink.frames[0].segments[1].flags, kSegmentStale);
    EXPECT_EQ(tag(sink.frames[0].segments[1]), 1007.0);
    EXPECT_EQ(sink.frames[1].sync, 7u);
    EXPECT_EQ(sink.frames[1].segments[1].flags, 0u);
}

TEST(SubjectAssembler, AnOlderInstantOpeningLaterStillGoesFirst) {
    RecordingSink sink;
    SubjectAssembler a(1, 2, config(), sink);
    feed(a, 7, {0}, 0);
    feed(a, 6, {0}, 1'000);  // segment 0 out of order: 6 is now the oldest open instant
    EXPECT_EQ(a.next_deadline_us(), 1'000 + kDeadline);
    feed(a, 6, {1}, 2'000);
    ASSERT_EQ(sink.frames.size(), 1u);
    EXPECT_EQ(sink.frames[0].sync, 6u);
    EXPECT_EQ(a.next_deadline_us(), kDeadline);
    feed(a, 7, {1}, 3'000);
    ASSERT_EQ(sink.frames.size(), 2u);
    EXPECT_EQ(sink.frames[1].sync, 7u);
    EXPECT_EQ(a.stats().frames_complete.value(), 2u);
}

TEST(SubjectAssembler, OlderInstantBlocksNewerUntilItsDeadline) {
    RecordingSink sink;
    SubjectAssembler a(1, 3, config(), sink);
    feed(a, 1, {0, 1, 2}, 0);
    feed(a, 2, {0, 1}, 10'000);  // 2 still expected for sync 2
    feed(a, 3, {0, 1}, 12'000);
    EXPECT_EQ(sink.frames.size(), 1u);
    a.advance(10'000 + kDeadline - 1);
    EXPECT_EQ(sink.frames.size(), 1u);
    a.advance(10'000 + kDeadline);  // 2 times out; 2 is now dead, so 3 is resolved too
    ASSERT_EQ(sink.frames.size(), 3u);
    EXPECT_EQ(sink.frames[1].sync, 2u);
    EXPECT_EQ(sink.frames[2].sync, 3u);
}

TEST(SubjectAssembler, ExtendedSyncNeedsNoWrapHandling) {
    RecordingSink sink;
    SubjectAssembler a(1, 2, config(true, 4), sink);
    const std::vector<std::uint64_t> syncs = {65534,         65535,          65536,         65537,
                                              0xFFFFFFFFull, 0x100000000ull, 0x100000001ull};
    std::int64_t now = 0;
    for (std::uint64_t s : syncs) {
        for (std::uint16_t k = 0; k < 2; ++k)
            a.on_pose(pose(1, k, s), now);
        now += 10'000;
    }
    ASSERT_EQ(sink.frames.size(), syncs.size());
    for (std::size_t i = 0; i < syncs.size(); ++i)
        EXPECT_EQ(sink.frames[i].sync, syncs[i]);
    EXPECT_EQ(a.stats().frames_complete.value(), syncs.size());
    EXPECT_EQ(a.stats().frames_forced.value(), 0u);
}

TEST(SubjectAssembler, FullWindowForcesTheOldestOut) {
    RecordingSink sink;
    SubjectAssembler a(1, 2, config(/*skip_dead=*/false, /*window=*/4), sink);
    feed(a, 1, {0}, 0);  // segment 1 never comes
    for (std::uint64_t s = 2; s <= 4; ++s)
        feed(a, s, {0}, 100);
    EXPECT_TRUE(sink.frames.empty());
    EXPECT_EQ(a.open_instants(), 4u);
    feed(a, 5, {0}, 200);  // would be a fifth open instant: sync 1 is forced out
    ASSERT_EQ(sink.frames.size(), 1u);
    EXPECT_EQ(sink.frames[0].sync, 1u);
    EXPECT_EQ(a.stats().frames_forced.value(), 1u);
    EXPECT_EQ(a.open_instants(), 4u);
    // A jump forces out everything a window behind, in order.
    feed(a, 13, {0}, 300);
    ASSERT_EQ(sink.frames.size(), 5u);
    for (std::uint64_t i = 0; i < 5; ++i)
        EXPECT_EQ(sink.frames[i].sync, i + 1);
    EXPECT_EQ(a.stats().frames_forced.value(), 5u);
    // Not yet emitted but a whole window behind the open sync 13: counted as late.
    a.on_pose(pose(1, 0, 9), 400);
    EXPECT_EQ(a.stats().segments_late.value(), 1u);
    EXPECT_EQ(a.open_instants(), 1u);
}

TEST(SubjectAssembler, CountsDuplicatesAndInvalidPoses) {
    RecordingSink sink;
    SubjectAssembler a(1, 2, config(), sink);
    a.on_pose(pose(1, 0, 1), 0);
    a.on_pose(pose(1, 0, 1), 1);
    a.on_pose(pose(2, 0, 1), 2);  // other subject
    a.on_pose(pose(1, 2, 1), 3);  // segment out of range
    EXPECT_EQ(a.stats().segments_duplicate.value(), 1u);
    EXPECT_EQ(a.stats().segments_invalid.value(), 2u);
    EXPECT_TRUE(sink.frames.empty());
    EXPECT_THROW(SubjectAssembler(1, 0, config(), sink), std::invalid_argument);
    EXPECT_THROW(SubjectAssembler(1, kMaxSegments + 1, config(), sink), std::invalid_argument);
    EXPECT_THROW(SubjectAssembler(1, 2, config(true, 0), sink), std::invalid_argument);
}

TEST(SubjectAssembler, FlushEmitsEverythingInOrder) {
    RecordingSink sink;
    SubjectAssembler a(1, 2, config(), sink);
    feed(a, 3, {0}, 0);
    feed(a, 4, {0}, 0);
    a.flush(5);
    ASSERT_EQ(sink.frames.size(), 2u);
    EXPECT_EQ(sink.frames[0].sync, 3u);
    EXPECT_EQ(sink.frames[1].sync, 4u);
    EXPECT_EQ(a.open_instants(), 0u);
}

TEST(AssemblerSet, DeadlineCanChangeAtRunTime) {
    RecordingSink sink;
    AssemblerSet set(config(), sink);
    set.add_subject(1, 2);
    set.on_pose(pose(1, 0, 1), 0);
    set.set_deadline_us(5'000);  // applies to the open instant as well
    EXPECT_EQ(set.next_deadline_us(), 5'000);
    set.advance(5'000);
    ASSERT_EQ(sink.frames.size(), 1u);
    set.on_pose(pose(1, 0, 2), 10'000);  // segment 1 is dead now: no wait at all
    EXPECT_EQ(sink.frames.size(), 2u);
    set.on_pose(pose(1, 1, 3), 20'000);  // segment 1 is back and waited for again
    EXPECT_EQ(set.next_deadline_us(), 25'000);
}

TEST(AssemblerSet, RoutesBySubjectAndSumsCounters) {
    RecordingSink sink;
    AssemblerSet set(config(), sink);
    set.add_subject(20, 2);
    set.add_subject(10, 1);
    EXPECT_THROW(set.add_subject(10, 3), std::logic_error);
    EXPECT_EQ(set.subject_count(), 2u);
    ASSERT_NE(set.find(20), nullptr);
    EXPECT_EQ(set.find(20)->segment_count(), 2u);
    EXPECT_EQ(set.find(30), nullptr);

    set.on_pose(pose(20, 0, 1), 5'000);
    set.on_pose(pose(10, 0, 1), 6'000);  // complete at once (one segment)
    set.on_pose(pose(30, 0, 1), 6'000);  // unknown subject
    ASSERT_EQ(sink.frames.size(), 1u);
    EXPECT_EQ(sink.frames[0].subject_id, 10u);
    EXPECT_EQ(set.next_deadline_us(), 5'000 + kDeadline);
    set.advance(5'000 + kDeadline);
    ASSERT_EQ(sink.frames.size(), 2u);
    EXPECT_EQ(sink.frames[1].subject_id, 20u);
    EXPECT_EQ(set.next_deadline_us(), kNoDeadline);

    const CounterGroup& c = set.counters();
    EXPECT_EQ(c.component(), "assembler");
    EXPECT_EQ(c.value("poses_unknown_subject"), 1u);
    EXPECT_EQ(c.value("frames_complete"), 1u);
    EXPECT_EQ(c.value("frames_partial"), 1u);
    EXPECT_EQ(c.value("segments_stale"), 1u);
    EXPECT_EQ(c.value("segments_late"), 0u);
    set.on_pose(pose(20, 1, 1), 40'000);
    EXPECT_EQ(c.value("segments_late"), 1u);
}

}  // namespace
}  // namespace mocap
