// address_budget.cpp — token buckets per peer address, bounded table (address_budget.hpp).
#include "serve/address_budget.hpp"

#include <algorithm>

namespace mocap::serve {

AddressBudget::AddressBudget(const AddressBudgetLimits& limits) : limits_(limits) {
    limits_.burst = std::max(limits_.burst, 1.0);
    limits_.max_addresses = std::max<std::size_t>(limits_.max_addresses, 1);
}

AddressBudget::Key AddressBudget::key_of(const asio::ip::address& peer) {
    // The same keys as the control-attempt limiter: a host is one key however it connects.
    return ControlAttemptLimiter::key_of(peer);
}

AddressBudget::Bucket& AddressBudget::bucket(const Key& key, std::int64_t now_us) {
    auto it = table_.find(key);
    if (it == table_.end()) {
        if (table_.size() >= limits_.max_addresses) {
            // The address seen least recently makes room (every lookup refills, so
            // refilled_us is when it was last seen).
            table_.erase(std::min_element(table_.begin(), table_.end(), [](const auto& a, const auto& b) {
                return a.second.refilled_us < b.second.refilled_us;
            }));
        }
        it = table_.emplace(key, Bucket{limits_.burst, now_us}).first;
    }
    Bucket& b = it->second;
    const double dt_s = static_cast<double>(std::max<std::int64_t>(now_us - b.refilled_us, 0)) * 1e-6;
    b.tokens = std::min(limits_.burst, b.tokens + dt_s * limits_.per_s);
    b.refilled_us = std::max(b.refilled_us, now_us);
    return b;
}

bool AddressBudget::take(const asio::ip::address& peer, std::int64_t now_us) {
    std::lock_guard lock(mutex_);
    Bucket& b = bucket(key_of(peer), now_us);
    if (b.tokens < 1.0) return false;
    b.tokens -= 1.0;
    return true;
}

bool AddressBudget::in_hand(const asio::ip::address& peer, std::int64_t now_us) {
    std::lock_guard lock(mutex_);
    return bucket(key_of(peer), now_us).tokens >= 1.0;
}

std::size_t AddressBudget::tracked_addresses() const {
    std::lock_guard lock(mutex_);
    return table_.size();
}

}  // namespace mocap::serve
