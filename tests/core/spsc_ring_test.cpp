#include "core/spsc_ring.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <stdexcept>
#include <thread>

namespace mocap {
namespace {

TEST(SpscRing, RejectsCapacityThatIsNotAPowerOfTwo) {
    EXPECT_THROW(SpscRing<int>(0), std::invalid_argument);
    EXPECT_THROW(SpscRing<int>(1), std::invalid_argument);
    EXPECT_THROW(SpscRing<int>(6), std::invalid_argument);
    EXPECT_NO_THROW(SpscRing<int>(8));
}

TEST(SpscRing, PopsInPushOrder) {
    SpscRing<int> ring(16);
    for (int i = 0; i < 10; ++i)
        ASSERT_TRUE(ring.try_push(i));
    EXPECT_EQ(ring.size_approx(), 10u);
    for (int i = 0; i < 10; ++i) {
        int v = -1;
        ASSERT_TRUE(ring.try_pop(v));
        EXPECT_EQ(v, i);
    }
    int v = -1;
    EXPECT_FALSE(ring.try_pop(v));
    EXPECT_TRUE(ring.empty());
}

TEST(SpscRing, FullRejectsPushUntilOneIsPopped) {
    SpscRing<int> ring(4);
    EXPECT_EQ(ring.capacity(), 4u);
    for (int i = 0; i < 4; ++i)
        ASSERT_TRUE(ring.try_push(i));
    EXPECT_FALSE(ring.try_push(99));
    EXPECT_EQ(ring.size_approx(), 4u);
    int v = -1;
    ASSERT_TRUE(ring.try_pop(v));
    EXPECT_EQ(v, 0);
    EXPECT_TRUE(ring.try_push(4));
    EXPECT_FALSE(ring.try_push(5));
    for (int expect = 1; expect <= 4; ++expect) {
        ASSERT_TRUE(ring.try_pop(v));
        EXPECT_EQ(v, expect);
    }
    EXPECT_FALSE(ring.try_pop(v));
}

TEST(SpscRing, WrapsAroundManyTimes) {
    SpscRing<std::uint64_t> ring(8);
    std::uint64_t next_in = 0;
    std::uint64_t next_out = 0;
    for (int round = 0; round < 100; ++round) {
        for (int i = 0; i < 5; ++i)
            ASSERT_TRUE(ring.try_push(next_in++));
        for (int i = 0; i < 5; ++i) {
            const std::uint64_t* front = ring.front();
            ASSERT_NE(front, nullptr);
            EXPECT_EQ(*front, next_out++);
            ring.pop();
        }
    }
    EXPECT_EQ(ring.front(), nullptr);
    EXPECT_EQ(next_out, 500u);
}

struct Pair {
    std::uint64_t seq = 0;
    std::uint64_t check = 0;  // a torn copy would break seq * k == check
};

TEST(SpscRing, TwoThreadStressKeepsOrderAndContent) {
    constexpr std::uint64_t kCount = 200'000;
    constexpr std::uint64_t kMul = 0x9E3779B97F4A7C15ull;
    SpscRing<Pair> ring(64);
    std::uint64_t producer_sum = 0;
    std::thread producer([&] {
        for (std::uint64_t i = 1; i <= kCount; ++i) {
            const Pair p{i, i * kMul};
            while (!ring.try_push(p))
                std::this_thread::yield();
            producer_sum += p.check;
        }
    });
    std::uint64_t consumer_sum = 0;
    std::uint64_t expected = 1;
    std::uint64_t bad = 0;
    while (expected <= kCount) {
        Pair p;
        if (!ring.try_pop(p)) {
            std::this_thread::yield();
            continue;
        }
        if (p.seq != expected || p.check != p.seq * kMul) ++bad;
        consumer_sum += p.check;
        ++expected;
    }
    producer.join();
    EXPECT_EQ(bad, 0u);
    EXPECT_EQ(consumer_sum, producer_sum);
    EXPECT_TRUE(ring.empty());
}

}  // namespace
}  // namespace mocap
