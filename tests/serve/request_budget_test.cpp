// RequestBudget on a real io_context run by the test thread (no other thread, no clock):
// at most per_turn requests per turn, waiting sessions resumed first in first out, and a
// handler posted at any moment (a frame hand-over) runs after at most 2 x per_turn
// admitted requests however many sessions keep asking.
#include "serve/request_budget.hpp"

#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

namespace mocap::serve {
namespace {

TEST(RequestBudget, AdmitsPerTurnThenQueuesWaitersInOrder) {
    asio::io_context io;
    RequestBudget budget(io, 2);
    EXPECT_TRUE(budget.try_take());
    EXPECT_TRUE(budget.try_take());
    EXPECT_FALSE(budget.try_take());
    std::vector<std::string> order;
    budget.wait([&] { order.push_back("a"); });
    budget.wait([&] { order.push_back("b"); });
    budget.wait([&] { order.push_back("c"); });
    EXPECT_FALSE(budget.try_take()) << "a newcomer does not overtake the waiting sessions";
    io.run_one();  // the marker: new turn, a and b get one request each
    EXPECT_EQ(order, (std::vector<std::string>{"a", "b"}));
    EXPECT_EQ(budget.waiting(), 1u);
    io.run_one();
    EXPECT_EQ(order, (std::vector<std::string>{"a", "b", "c"}));
    io.run();  // the last marker ends a turn with nothing waiting: the queue empties
    EXPECT_EQ(budget.waiting(), 0u);
    EXPECT_TRUE(budget.try_take());
}

// Sessions that always have another request (the churn attack): each admitted request is
// counted; a "frame" handler is posted after every 7th request from inside the flood. The
// requests handled between a frame's post and its run never exceed 2 x per_turn.
TEST(RequestBudget, AFramePostedDuringAFloodWaitsForAtMostTwoTurns) {
    constexpr std::size_t kPerTurn = 4;
    asio::io_context io;
    RequestBudget budget(io, kPerTurn);
    std::size_t handled = 0, frames = 0, worst = 0;
    struct Flooder {
        RequestBudget& budget;
        std::size_t& handled;
        std::function<void()> on_request;
        void run(bool granted) {
            for (;;) {  // a session's parse loop: every byte holds another request
                if (!granted && !budget.try_take()) {
                    budget.wait([this] { run(true); });
                    return;
                }
                granted = false;
                ++handled;
                on_request();
                if (handled > 5000) return;
            }
        }
    };
    auto post_frame = [&] {
        const std::size_t at_post = handled;
        asio::post(io, [&, at_post] {
            worst = std::max(worst, handled - at_post);
            ++frames;
        });
    };
    std::vector<std::unique_ptr<Flooder>> flooders;
    for (int i = 0; i < 20; ++i) {
        flooders.push_back(std::make_unique<Flooder>(Flooder{budget, handled, [&] {
                                                                 if (handled % 7 == 0) post_frame();
                                                             }}));
        asio::post(io, [f = flooders.back().get()] { f->run(false); });  // each read completion
    }
    io.run();
    EXPECT_GT(handled, 5000u);
    EXPECT_GT(frames, 500u);
    EXPECT_LE(worst, 2 * kPerTurn);
}

}  // namespace
}  // namespace mocap::serve
