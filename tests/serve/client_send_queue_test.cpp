// ClientSendQueue: capacity, drop-oldest order, drop counting, clear, batching.
#include "serve/client_send_queue.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace mocap::serve {
namespace {

using Texts = std::vector<std::string>;

// The frame's text is its number.
ClientSendQueue::Bytes frame(int i) {
    return std::make_shared<const std::string>(std::to_string(i));
}

void push_range(ClientSendQueue& q, int first, int end) {
    for (int i = first; i < end; ++i)
        q.push(frame(i));
}

Texts drain(ClientSendQueue& q) {
    Texts out;
    while (!q.empty())
        out.push_back(*q.pop());
    return out;
}

class ClientSendQueueTest : public testing::Test {
protected:
    Counter dropped_;  // the server's shared counter
};

TEST_F(ClientSendQueueTest, KeepsOrderBelowCapacityAndCountsNothing) {
    ClientSendQueue q(4, dropped_);
    EXPECT_EQ(q.capacity(), 4u);
    EXPECT_TRUE(q.empty());
    push_range(q, 0, 4);
    EXPECT_EQ(q.size(), 4u);
    EXPECT_EQ(drain(q), (Texts{"0", "1", "2", "3"}));
    EXPECT_EQ(dropped_.value(), 0u);
    EXPECT_EQ(q.dropped_total(), 0u);
    EXPECT_EQ(q.take_unreported_drops(), 0u);
}

TEST_F(ClientSendQueueTest, FullQueueDropsTheOldestAndCountsIt) {
    ClientSendQueue q(3, dropped_);
    push_range(q, 0, 5);
    EXPECT_EQ(q.size(), 3u);
    EXPECT_EQ(dropped_.value(), 2u);
    EXPECT_EQ(q.dropped_total(), 2u);
    EXPECT_EQ(drain(q), (Texts{"2", "3", "4"}));
}

TEST_F(ClientSendQueueTest, DroppedFrameIsReleased) {
    ClientSendQueue q(1, dropped_);
    auto first = frame(0);
    const std::weak_ptr<const std::string> watch = first;
    q.push(std::move(first));
    q.push(frame(1));
    EXPECT_TRUE(watch.expired());
    EXPECT_EQ(*q.pop(), "1");
}

TEST_F(ClientSendQueueTest, UnreportedDropsResetButTotalStays) {
    ClientSendQueue q(2, dropped_);
    push_range(q, 0, 5);
    EXPECT_EQ(q.take_unreported_drops(), 3u);
    EXPECT_EQ(q.take_unreported_drops(), 0u);
    q.push(frame(5));
    EXPECT_EQ(q.take_unreported_drops(), 1u);
    EXPECT_EQ(q.dropped_total(), 4u);
    EXPECT_EQ(dropped_.value(), 4u);
}

TEST_F(ClientSendQueueTest, SharedCounterSumsOverQueues) {
    ClientSendQueue a(1, dropped_);
    ClientSendQueue b(2, dropped_);
    push_range(a, 0, 3);  // 2 dropped
    push_range(b, 0, 3);  // 1 dropped
    EXPECT_EQ(a.dropped_total(), 2u);
    EXPECT_EQ(b.dropped_total(), 1u);
    EXPECT_EQ(dropped_.value(), 3u);
}

TEST_F(ClientSendQueueTest, ZeroCapacityIsOne) {
    ClientSendQueue q(0, dropped_);
    EXPECT_EQ(q.capacity(), 1u);
    push_range(q, 0, 2);
    EXPECT_EQ(dropped_.value(), 1u);
    EXPECT_EQ(drain(q), (Texts{"1"}));
}

TEST_F(ClientSendQueueTest, ClearDiscardsWithoutCounting) {
    ClientSendQueue q(3, dropped_);
    push_range(q, 0, 3);
    q.clear();
    EXPECT_TRUE(q.empty());
    EXPECT_EQ(dropped_.value(), 0u);
    EXPECT_EQ(q.take_unreported_drops(), 0u);
    // Usable again at full capacity, no drop until it overflows.
    push_range(q, 3, 6);
    EXPECT_EQ(dropped_.value(), 0u);
    EXPECT_EQ(drain(q), (Texts{"3", "4", "5"}));
}

TEST_F(ClientSendQueueTest, MoveIntoFillsUpToTheBatchSizeOldestFirst) {
    ClientSendQueue q(8, dropped_);
    push_range(q, 0, 6);
    std::vector<ClientSendQueue::Bytes> batch{frame(100)};  // e.g. a reply already in the batch
    EXPECT_EQ(q.move_into(batch, 4), 3u);
    ASSERT_EQ(batch.size(), 4u);
    EXPECT_EQ(*batch[1], "0");
    EXPECT_EQ(*batch[3], "2");
    EXPECT_EQ(q.size(), 3u);
    batch.clear();
    EXPECT_EQ(q.move_into(batch, 10), 3u);
    EXPECT_EQ(*batch[0], "3");
    EXPECT_TRUE(q.empty());
    EXPECT_EQ(q.move_into(batch, 10), 0u);
}

TEST_F(ClientSendQueueTest, OrderSurvivesManyWrapArounds) {
    ClientSendQueue q(5, dropped_);
    int next_expected = 0;
    for (int i = 0; i < 1000; ++i) {
        q.push(frame(i));
        if (i % 3 == 0) {  // the reader takes one frame per three written: it lags
            const int n = std::stoi(*q.pop());
            EXPECT_GE(n, next_expected);  // never older than one already seen
            next_expected = n + 1;
        }
    }
    // 334 frames read (the last at i = 999), 4 still queued, the rest dropped.
    EXPECT_EQ(q.size(), 4u);
    EXPECT_EQ(dropped_.value(), 1000u - 334u - 4u);
    EXPECT_EQ(drain(q), (Texts{"996", "997", "998", "999"}));
}

}  // namespace
}  // namespace mocap::serve
