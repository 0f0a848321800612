// SyncOrder (daemon/sync_order.hpp): a replay's out-of-order samples put back in SYNC order.
#include "daemon/sync_order.hpp"

#include <gtest/gtest.h>

#include <utility>
#include <vector>

namespace mocap::daemon {
namespace {

SegmentSample sample(std::uint32_t subject, std::uint16_t segment, std::uint64_t sync) {
    SegmentSample s;
    s.subject_id = subject;
    s.segment_index = segment;
    s.sync = sync;
    return s;
}

using Seen = std::vector<std::pair<std::uint16_t, std::uint64_t>>;  // (segment, sync) in emitted order

struct Recorder {
    Seen seen;
    SyncOrder order;
    explicit Recorder(std::size_t window = SyncOrder::kDefaultWindow)
        : order([this](const SegmentSample& s) { seen.emplace_back(s.segment_index, s.sync); }, window) {}
};

TEST(SyncOrder, PassesARecordingInSyncOrderThroughUnchanged) {
    Recorder r;
    // Segments interleave freely within a SYNC, and a segment may miss a SYNC.
    const Seen in{{0, 1}, {1, 1}, {1, 2}, {0, 2}, {0, 3}, {1, 4}, {0, 4}};
    for (const auto& [seg, sync] : in)
        r.order.push(sample(1, seg, sync));
    r.order.flush();
    EXPECT_EQ(r.seen, in);
    EXPECT_EQ(r.order.reordered(), 0u);
    EXPECT_EQ(r.order.too_late(), 0u);
}

TEST(SyncOrder, AFrozenHostsLateSamplesGoBackIntoTheHole) {
    Recorder r;
    // Host A served SYNCs 1-2, froze; host B served 6-7; A woke and stored 3-4 after them.
    for (std::uint64_t sync : {1, 2, 6, 7, 3, 4}) {
        r.order.push(sample(1, 0, sync));
        r.order.push(sample(1, 1, sync));
    }
    r.order.push(sample(2, 0, 5));  // another subject is not held back by this one's hole
    r.order.flush();
    const Seen want{{0, 1}, {1, 1}, {0, 2}, {1, 2}, {0, 3}, {1, 3}, {0, 4},
                    {1, 4}, {0, 6}, {1, 6}, {0, 7}, {1, 7}, {0, 5}};
    EXPECT_EQ(r.seen, want);
    EXPECT_EQ(r.order.reordered(), 4u);
    EXPECT_EQ(r.order.too_late(), 0u);
}

TEST(SyncOrder, AMovedSampleTakesTheReceivedTimeOfItsNewPlace) {
    std::vector<std::int64_t> received;
    SyncOrder order([&](const SegmentSample& s) { received.push_back(s.times.received_us); });
    for (std::uint64_t sync : {1, 2, 6, 7}) {
        SegmentSample s = sample(1, 0, sync);
        s.times.received_us = static_cast<std::int64_t>(sync) * 10'000;
        order.push(s);
    }
    SegmentSample late = sample(1, 0, 3);
    late.times.received_us = 5'000'000;  // stamped when the frozen host woke up
    order.push(late);
    order.flush();
    EXPECT_EQ(received, (std::vector<std::int64_t>{10'000, 20'000, 60'000, 60'000, 70'000}))
        << "the replay's clock keeps to the take's time";
}

TEST(SyncOrder, ASampleLaterThanTheWindowIsDroppedAndCounted) {
    Recorder r(2);
    r.order.push(sample(1, 0, 10));
    r.order.push(sample(1, 0, 11));
    r.order.push(sample(1, 0, 12));  // SYNC 10 leaves the window: passed on
    r.order.push(sample(1, 0, 9));   // behind what was passed on: a filter cannot go back
    r.order.push(sample(1, 0, 10));  // the same SYNC again: a duplicate
    r.order.flush();
    EXPECT_EQ(r.seen, (Seen{{0, 10}, {0, 11}, {0, 12}}));
    EXPECT_EQ(r.order.too_late(), 2u);
    EXPECT_EQ(r.order.reordered(), 0u);
}

}  // namespace
}  // namespace mocap::daemon
