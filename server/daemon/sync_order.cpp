#include "daemon/sync_order.hpp"

#include <algorithm>
#include <utility>

namespace mocap::daemon {

SyncOrder::SyncOrder(Emit emit, std::size_t window)
    : emit_(std::move(emit)), window_(std::max<std::size_t>(window, 1)) {}

void SyncOrder::push(const SegmentSample& s) {
    const std::uint64_t k = key(s);
    if (const auto sent = newest_sent_.find(k); sent != newest_sent_.end() && s.sync <= sent->second) {
        ++too_late_;
        return;
    }
    auto [read, fresh] = newest_read_.try_emplace(k, s.sync);
    if (!fresh && s.sync < read->second) {
        // Late: in front of the first held sample of its subject with a later SYNC.
        const auto at = std::find_if(held_.begin(), held_.end(), [&](const SegmentSample& h) {
            return h.subject_id == s.subject_id && h.sync > s.sync;
        });
        SegmentSample moved = s;
        // Its received time was late too (the host woke up): in its new place it takes the
        // time of the sample it now precedes, so the replay's clock does not jump ahead and
        // hold every deadline until the late host's wake-up comes round again.
        if (at != held_.end()) moved.times.received_us = std::min(moved.times.received_us, at->times.received_us);
        held_.insert(at, moved);
        ++reordered_;
    } else {
        read->second = s.sync;
        held_.push_back(s);
    }
    while (held_.size() > window_)
        emit_front();
}

void SyncOrder::flush() {
    while (!held_.empty())
        emit_front();
}

void SyncOrder::emit_front() {
    const SegmentSample s = held_.front();
    held_.pop_front();
    auto [sent, fresh] = newest_sent_.try_emplace(key(s), s.sync);
    if (!fresh) sent->second = std::max(sent->second, s.sync);
    emit_(s);
}

}  // namespace mocap::daemon
