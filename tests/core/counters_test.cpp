#include "core/counters.hpp"

#include <gtest/gtest.h>

#include <thread>

namespace mocap {
namespace {

TEST(Counter, OnlyGoesUp) {
    Counter c;
    EXPECT_EQ(c.value(), 0u);
    c.add();
    c.add(41);
    EXPECT_EQ(c.value(), 42u);
}

TEST(CounterGroup, NamesEntriesAndSumsParts) {
    Counter a, b, c;
    CounterGroup group("worker_pool");
    group.add("processed", a);
    group.add("dropped", c);
    group.add("processed", b);  // second part of the same entry
    a.add(3);
    b.add(4);
    c.add(1);
    EXPECT_EQ(group.component(), "worker_pool");
    const auto snap = group.snapshot();
    ASSERT_EQ(snap.size(), 2u);
    EXPECT_EQ(snap[0].name, "processed");
    EXPECT_EQ(snap[0].value, 7u);
    EXPECT_EQ(snap[1].name, "dropped");
    EXPECT_EQ(snap[1].value, 1u);
    EXPECT_EQ(group.value("processed"), 7u);
    EXPECT_FALSE(group.value("unknown").has_value());
}

TEST(CounterGroup, ReaderSeesConcurrentWriters) {
    Counter a, b;
    CounterGroup group("test");
    group.add("events", a);
    group.add("events", b);
    constexpr int kAdds = 50'000;
    std::uint64_t last = 0;
    bool monotonic = true;
    std::thread ta([&] {
        for (int i = 0; i < kAdds; ++i)
            a.add();
    });
    std::thread tb([&] {
        for (int i = 0; i < kAdds; ++i)
            b.add();
    });
    for (int i = 0; i < 1000; ++i) {
        const std::uint64_t v = *group.value("events");
        if (v < last) monotonic = false;
        last = v;
    }
    ta.join();
    tb.join();
    EXPECT_TRUE(monotonic);
    EXPECT_EQ(*group.value("events"), 2u * kAdds);
}

}  // namespace
}  // namespace mocap
