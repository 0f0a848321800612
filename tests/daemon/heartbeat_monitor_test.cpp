// HeartbeatMonitor: a counter that stops moving for longer than the window names its
// thread; one that moves again clears it (daemon/heartbeat_monitor.hpp). Time handed in.
#include "daemon/heartbeat_monitor.hpp"

#include <gtest/gtest.h>

namespace mocap::daemon {
namespace {

TEST(HeartbeatMonitor, ACounterThatStopsMovingIsNamedUntilItMovesAgain) {
    std::atomic<std::uint64_t> ingest{0}, worker{0};
    HeartbeatMonitor m;
    m.add({"ingest thread", &ingest});
    m.add({"worker 0", &worker});
    constexpr std::int64_t kWindow = 2'000'000;
    EXPECT_EQ(m.stale(0, kWindow), "") << "first look";
    for (std::int64_t t = 250'000; t <= 4'000'000; t += 250'000) {
        ++ingest;  // worker 0 is frozen
        const std::string s = m.stale(t, kWindow);
        EXPECT_EQ(s, t > kWindow ? "worker 0" : "") << t;
    }
    ++worker;
    EXPECT_EQ(m.stale(4'100'000, kWindow), "") << "moved again";
    EXPECT_EQ(m.stale(6'200'000, kWindow), "ingest thread, worker 0") << "both still since 4.1 s";
    EXPECT_EQ(m.stale(1'000'000, kWindow), "") << "a clock that steps back restarts the window";
}

}  // namespace
}  // namespace mocap::daemon
