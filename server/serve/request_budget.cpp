// request_budget.cpp — the per-lane request budget: admit, wait, end the turn.
#include "serve/request_budget.hpp"

#include <algorithm>
#include <utility>

namespace mocap::serve {

RequestBudget::RequestBudget(asio::io_context& io, std::size_t per_turn)
    : io_(io), per_turn_(std::max<std::size_t>(per_turn, 1)) {}

bool RequestBudget::try_take() {
    // Others waiting go first, so a client cannot overtake the ones the turn stopped.
    if (!waiting_.empty() || used_ >= per_turn_) return false;
    ++used_;
    ensure_marker();
    return true;
}

void RequestBudget::wait(std::function<void()> resume) {
    waiting_.push_back(std::move(resume));
    ensure_marker();
}

void RequestBudget::ensure_marker() {
    if (marker_posted_) return;
    marker_posted_ = true;
    asio::post(io_, [this] { end_turn(); });
}

void RequestBudget::end_turn() {
    marker_posted_ = false;
    used_ = 0;
    while (!waiting_.empty() && used_ < per_turn_) {
        std::function<void()> resume = std::move(waiting_.front());
        waiting_.pop_front();
        ++used_;
        resume();  // may wait() again: it then queues behind the others
    }
    if (used_ > 0 || !waiting_.empty()) ensure_marker();
}

}  // namespace mocap::serve
