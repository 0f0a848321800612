// client_send_queue.cpp — a ring over a vector sized once, so a lagging client costs
// no allocation however long it lags.
#include "serve/client_send_queue.hpp"

#include <algorithm>
#include <cassert>
#include <utility>

namespace mocap::serve {

ClientSendQueue::ClientSendQueue(std::size_t capacity, Counter& dropped_counter)
    : ring_(std::max<std::size_t>(capacity, 1)), dropped_counter_(dropped_counter) {}

void ClientSendQueue::push(Bytes frame) {
    if (size_ == ring_.size()) {
        static_cast<void>(pop());  // the oldest frame: counted, then released
        ++dropped_total_;
        ++dropped_unreported_;
        dropped_counter_.add();
    }
    ring_[(head_ + size_) % ring_.size()] = std::move(frame);
    ++size_;
}

ClientSendQueue::Bytes ClientSendQueue::pop() {
    assert(size_ > 0);
    Bytes out = std::move(ring_[head_]);
    head_ = (head_ + 1) % ring_.size();
    --size_;
    return out;
}

std::size_t ClientSendQueue::move_into(std::vector<Bytes>& out, std::size_t max_size) {
    std::size_t moved = 0;
    while (size_ > 0 && out.size() < max_size) {
        out.push_back(pop());
        ++moved;
    }
    return moved;
}

void ClientSendQueue::clear() {
    while (size_ > 0)
        static_cast<void>(pop());
    head_ = 0;
}

std::uint64_t ClientSendQueue::take_unreported_drops() {
    return std::exchange(dropped_unreported_, 0);
}

}  // namespace mocap::serve
