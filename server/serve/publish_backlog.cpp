// publish_backlog.cpp — swap, not copy: neither vector reallocates after construction.
#include "serve/publish_backlog.hpp"

#include <utility>

namespace mocap::serve {

PublishBacklog::PublishBacklog(asio::io_context& io, std::size_t capacity,
                               std::function<void(const SubjectText&)> deliver)
    : io_(io), capacity_(capacity), deliver_(std::move(deliver)) {
    pending_.reserve(capacity_);
    draining_.reserve(capacity_);
}

bool PublishBacklog::push(SubjectText frame) {
    bool wake = false;
    {
        std::lock_guard lock(mutex_);
        if (pending_.size() >= capacity_) return false;
        wake = pending_.empty();
        pending_.push_back(std::move(frame));
    }
    if (wake) asio::post(io_, [this] { drain(); });
    return true;
}

void PublishBacklog::drain() {
    {
        std::lock_guard lock(mutex_);
        draining_.swap(pending_);
    }
    for (const SubjectText& frame : draining_)
        deliver_(frame);
    draining_.clear();
}

}  // namespace mocap::serve
