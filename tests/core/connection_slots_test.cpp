// ConnectionSlots: the admission rules of core/connection_slots.hpp, on a manual clock.
#include "core/connection_slots.hpp"

#include <gtest/gtest.h>

namespace mocap {
namespace {

using Verdict = ConnectionSlots::Verdict;
constexpr std::int64_t kSecond = 1'000'000;

TEST(ConnectionSlots, FreeSlotsAdmitAndReleaseFreesThem) {
    ConnectionSlots slots(SlotPolicy{2, {}});
    const auto a = slots.admit("10.0.0.1", false, 0);
    const auto b = slots.admit("10.0.0.2", false, 0);
    ASSERT_EQ(a.verdict, Verdict::kAdmitted);
    ASSERT_EQ(b.verdict, Verdict::kAdmitted);
    EXPECT_NE(a.slot->id(), b.slot->id());
    EXPECT_NE(a.slot->id(), 0u);
    EXPECT_EQ(slots.size(), 2u);
    slots.release(a.slot->id());
    slots.release(a.slot->id());  // twice: ignored
    EXPECT_EQ(slots.size(), 1u);
    EXPECT_EQ(slots.admit("10.0.0.3", false, 0).verdict, Verdict::kAdmitted);
}

TEST(ConnectionSlots, AFullPortEvictsTheOldestUnprovenConnectionFirst) {
    ConnectionSlots slots(SlotPolicy{3, {}});
    const auto old_idle = slots.admit("10.0.0.1", false, 1 * kSecond);
    const auto young_idle = slots.admit("10.0.0.1", false, 2 * kSecond);
    const auto proven = slots.admit("10.0.0.2", false, 3 * kSecond);
    proven.slot->progress(3 * kSecond);  // long ago by the time the next one comes
    const auto next = slots.admit("10.0.0.3", false, 60 * kSecond);
    EXPECT_EQ(next.verdict, Verdict::kAdmittedEvicting);
    EXPECT_EQ(next.evicted, old_idle.slot->id()) << "unproven before stalled, oldest first";
    EXPECT_EQ(slots.size(), 3u);
    const auto after = slots.admit("10.0.0.4", false, 60 * kSecond);
    EXPECT_EQ(after.evicted, young_idle.slot->id());
}

TEST(ConnectionSlots, AProvenConnectionIsEvictedOnlyAfterStallingLongEnough) {
    ConnectionSlots slots(SlotPolicy{2, {0, false, 5.0}});
    const auto a = slots.admit("10.0.0.1", false, 0);
    const auto b = slots.admit("10.0.0.2", false, 0);
    a.slot->progress(10 * kSecond);
    b.slot->progress(12 * kSecond);
    EXPECT_EQ(slots.admit("10.0.0.3", false, 14 * kSecond).verdict, Verdict::kRefusedFull) << "both made progress";
    const auto c = slots.admit("10.0.0.3", false, 16 * kSecond);
    EXPECT_EQ(c.verdict, Verdict::kAdmittedEvicting);
    EXPECT_EQ(c.evicted, a.slot->id()) << "a stalled longest (6 s)";
    slots.release(a.slot->id());  // the victim's own close: its slot is already gone
    EXPECT_EQ(slots.size(), 2u);
}

TEST(ConnectionSlots, PerAddressLimitRefusesAndLoopbackIsExemptUnlessAsked) {
    ConnectionSlots slots(SlotPolicy{100, {2, false, 5.0}});
    EXPECT_TRUE(slots.admit("10.0.0.1", false, 0).admitted());
    const auto second = slots.admit("10.0.0.1", false, 0);
    EXPECT_TRUE(second.admitted());
    EXPECT_EQ(slots.admit("10.0.0.1", false, 0).verdict, Verdict::kRefusedPerAddress);
    EXPECT_TRUE(slots.admit("10.0.0.2", false, 0).admitted()) << "another address";
    for (int i = 0; i < 10; ++i)
        EXPECT_TRUE(slots.admit("127.0.0.1", true, 0).admitted()) << "loopback exempt by default";
    slots.release(second.slot->id());
    EXPECT_TRUE(slots.admit("10.0.0.1", false, 0).admitted()) << "a released slot counts no more";

    ConnectionSlots strict(SlotPolicy{100, {1, true, 5.0}});
    EXPECT_TRUE(strict.admit("127.0.0.1", true, 0).admitted());
    EXPECT_EQ(strict.admit("127.0.0.1", true, 0).verdict, Verdict::kRefusedPerAddress);
}

}  // namespace
}  // namespace mocap
