#include "core/counters.hpp"

#include <gtest/gtest.h>

#include <thread>

namespace mocap {
namespace {

template <class C>
void expect_only_goes_up() {
    C c;
    EXPECT_EQ(c.value(), 0u);
    c.add();
    c.add(41);
    EXPECT_EQ(c.value(), 42u);
}

TEST(Counter, OnlyGoesUp) {
    expect_only_goes_up<Counter>();
}
TEST(SingleWriterCounter, OnlyGoesUp) {
    expect_only_goes_up<SingleWriterCounter>();
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

// Two writer threads, one counter each (Counter or SingleWriterCounter), summed under one
// entry; a reader on this thread meanwhile. Nothing is lost and the reader never sees the sum
// go down (tests/sanitize.sh runs this under TSan: every access is atomic, no race).
template <class C>
void expect_reader_sees_two_writers(int adds) {
    C a, b;
    CounterGroup group("test");
    group.add("events", a);
    group.add("events", b);
    std::uint64_t last = 0;
    bool monotonic = true;
    std::thread ta([&] {
        for (int i = 0; i < adds; ++i)
            a.add();
    });
    std::thread tb([&] {
        for (int i = 0; i < adds; ++i)
            b.add(3);
    });
    for (int i = 0; i < 1000; ++i) {
        const std::uint64_t v = *group.value("events");
        if (v < last) monotonic = false;
        last = v;
    }
    ta.join();
    tb.join();
    EXPECT_TRUE(monotonic);
    EXPECT_EQ(a.value(), static_cast<std::uint64_t>(adds));
    EXPECT_EQ(*group.value("events"), 4u * static_cast<std::uint64_t>(adds));
}

TEST(CounterGroup, ReaderSeesConcurrentWriters) {
    expect_reader_sees_two_writers<Counter>(50'000);
}

// Both kinds can be parts of one entry (e.g. a per-thread single-writer part per thread).
TEST(CounterGroup, SumsSingleWriterAndSharedParts) {
    Counter shared;
    SingleWriterCounter own;
    CounterGroup group("mixed");
    group.add("events", shared);
    group.add("events", own);
    group.add("own", own);
    shared.add(5);
    own.add(2);
    EXPECT_EQ(group.value("events"), 7u);
    EXPECT_EQ(group.value("own"), 2u);
}

// One writer thread per SingleWriterCounter, as the rule requires.
TEST(SingleWriterCounter, ReaderSeesItsOneWriter) {
    expect_reader_sees_two_writers<SingleWriterCounter>(200'000);
}

// Writing is handed from one thread to another with a happens-before edge (join): allowed by
// the rule, nothing is lost.
TEST(SingleWriterCounter, WriterHandedOverByJoin) {
    SingleWriterCounter c;
    std::thread first([&] {
        for (int i = 0; i < 1000; ++i)
            c.add();
    });
    first.join();
    std::thread second([&] {
        for (int i = 0; i < 1000; ++i)
            c.add();
    });
    second.join();
    c.add();
    EXPECT_EQ(c.value(), 2001u);
}

}  // namespace
}  // namespace mocap
