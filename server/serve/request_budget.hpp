// request_budget.hpp — how many client requests one serve thread handles before the frames
// queued behind them get their turn (issue 13, item 1: control-plane work must never delay
// frames).
//
// A serve thread (lane) runs every handler of its io_context in order: frame hand-overs
// (PoseBroadcaster's drain), write completions and the read completions that carry client
// requests. Without a budget one read completion handles every request its bytes hold, and
// a few hundred connections re-sending requests keep the frames waiting behind them. With
// it, a lane handles at most `per_turn` requests per turn; a turn ends at a marker handler
// posted to the back of the queue when the turn's first request is admitted, so every
// handler queued before the marker (a frame hand-over among them) runs before the next turn
// starts. A session that finds the turn used up keeps its parsed request, stops reading
// (TCP pushes back on the sender) and waits; the marker resumes waiting sessions first in,
// first out, one request each while the new turn lasts. So between a frame's hand-over and
// its delivery a lane handles at most 2 x per_turn requests, whatever the clients send.
//
// Thread-safety: none; one lane thread. Resume callbacks run on that thread.
#pragma once

#include <cstddef>
#include <deque>
#include <functional>

#include "core/asio.hpp"

namespace mocap::serve {

class RequestBudget {
public:
    /// `io`: the lane's io_context (must outlive this object); per_turn >= 1.
    RequestBudget(asio::io_context& io, std::size_t per_turn);

    /// Admits one request now, or returns false: the turn is used up or others wait first.
    bool try_take();
    /// Queues `resume` for a later turn; it is called with one request already admitted.
    void wait(std::function<void()> resume);

    [[nodiscard]] std::size_t per_turn() const { return per_turn_; }
    [[nodiscard]] std::size_t waiting() const { return waiting_.size(); }

private:
    void end_turn();
    void ensure_marker();

    asio::io_context& io_;
    std::size_t per_turn_;
    std::size_t used_ = 0;  ///< requests admitted in the current turn
    bool marker_posted_ = false;
    std::deque<std::function<void()>> waiting_;
};

}  // namespace mocap::serve
