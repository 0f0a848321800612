// AddressBudget: a token bucket per peer address that reconnecting does not refill, and a
// bounded table (serve/address_budget.hpp). Time is handed in: no clock, no sleep.
#include "serve/address_budget.hpp"

#include <gtest/gtest.h>

namespace mocap::serve {
namespace {

asio::ip::address ip(const char* text) {
    return asio::ip::make_address(text);
}

TEST(AddressBudget, ABurstThenTheSustainedRateWhateverTheConnection) {
    AddressBudget budget({10.0, 5.0, 16});
    const auto a = ip("127.0.0.1");
    for (int i = 0; i < 10; ++i)
        EXPECT_TRUE(budget.take(a, 0)) << i;
    EXPECT_FALSE(budget.take(a, 0)) << "the burst is used up; a new connection changes nothing";
    EXPECT_FALSE(budget.in_hand(a, 0));
    EXPECT_TRUE(budget.in_hand(ip("127.0.0.2"), 0)) << "another address has its own";
    EXPECT_FALSE(budget.take(a, 199'999)) << "one request back per 200 ms";
    EXPECT_TRUE(budget.take(a, 200'000));
    EXPECT_FALSE(budget.take(a, 200'000));
    // A long pause refills up to the burst, never beyond it.
    int taken = 0;
    while (budget.take(a, 100'000'000))
        ++taken;
    EXPECT_EQ(taken, 10);
}

TEST(AddressBudget, OneHostIsOneAddressHoweverItConnects) {
    AddressBudget budget({2.0, 1.0, 16});
    EXPECT_TRUE(budget.take(ip("10.0.0.7"), 0));
    EXPECT_TRUE(budget.take(ip("::ffff:10.0.0.7"), 0)) << "IPv4 mapped into IPv6";
    EXPECT_FALSE(budget.take(ip("10.0.0.7"), 0));
    EXPECT_TRUE(budget.take(ip("2001:db8::1"), 0));
    EXPECT_TRUE(budget.take(ip("2001:db8::2"), 0)) << "the same /64";
    EXPECT_FALSE(budget.take(ip("2001:db8::ffff"), 0));
    EXPECT_TRUE(budget.take(ip("2001:db8:0:1::1"), 0)) << "another /64";
    EXPECT_EQ(budget.tracked_addresses(), 3u);
}

TEST(AddressBudget, AFullTableForgetsTheAddressSeenLeastRecently) {
    AddressBudget budget({1.0, 0.001, 2});
    EXPECT_TRUE(budget.take(ip("10.0.0.1"), 0));
    EXPECT_TRUE(budget.take(ip("10.0.0.2"), 10));
    EXPECT_FALSE(budget.take(ip("10.0.0.1"), 20));  // seen again: now the most recent
    EXPECT_TRUE(budget.take(ip("10.0.0.3"), 30));   // 10.0.0.2 makes room
    EXPECT_EQ(budget.tracked_addresses(), 2u);
    EXPECT_FALSE(budget.take(ip("10.0.0.1"), 40)) << "still remembered, still empty";
    EXPECT_TRUE(budget.take(ip("10.0.0.2"), 50)) << "forgotten: starts again with a full bucket";
}

}  // namespace
}  // namespace mocap::serve
