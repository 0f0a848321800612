// control_access.cpp — the control rules, their counters and the refusal log line.
#include "serve/control_access.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "serve/serve_counters.hpp"

namespace mocap::serve {

bool token_equal(std::string_view expected, std::string_view given) {
    const std::size_t n = std::max(expected.size(), given.size());
    unsigned diff = expected.size() == given.size() ? 0u : 1u;
    for (std::size_t i = 0; i < n; ++i) {
        const auto a = static_cast<unsigned char>(i < expected.size() ? expected[i] : 0);
        const auto b = static_cast<unsigned char>(i < given.size() ? given[i] : 0);
        diff |= static_cast<unsigned>(a ^ b);
    }
    return diff == 0;
}

bool is_loopback(const asio::ip::address& address) {
    if (address.is_loopback()) return true;
    // A dual-stack listener sees IPv4 peers as ::ffff:a.b.c.d, which is_loopback() rejects.
    if (address.is_v6() && address.to_v6().is_v4_mapped()) {
        return asio::ip::make_address_v4(asio::ip::v4_mapped, address.to_v6()).is_loopback();
    }
    return false;
}

bool peer_on_loopback(const asio::ip::tcp::socket& socket) {
    boost::system::error_code ec;
    const auto peer = socket.remote_endpoint(ec);
    return !ec && is_loopback(peer.address());
}

std::optional<asio::ip::address> remote_address(const asio::ip::tcp::socket& socket) {
    boost::system::error_code ec;
    const auto peer = socket.remote_endpoint(ec);
    if (ec) return std::nullopt;
    return peer.address();
}

ControlAttemptLimiter::ControlAttemptLimiter(const ControlAttemptLimits& limits, std::function<std::int64_t()> now_us)
    : limits_(limits),
      per_address_(rate(limits.per_address_burst, limits.per_address_per_s)),
      global_rate_(rate(limits.global_burst, limits.global_per_s)),
      now_us_(std::move(now_us)) {
    if (!now_us_) {
        now_us_ = [] {
            return std::chrono::duration_cast<std::chrono::microseconds>(
                       std::chrono::steady_clock::now().time_since_epoch())
                .count();
        };
    }
    limits_.max_addresses = std::max<std::size_t>(limits_.max_addresses, 1);
    table_.reserve(limits_.max_addresses);
}

ControlAttemptLimiter::Rate ControlAttemptLimiter::rate(double burst, double per_s) {
    const auto interval =
        std::max<std::int64_t>(static_cast<std::int64_t>(std::llround(1e6 / std::max(per_s, 1e-6))), 1);
    const auto window = static_cast<std::int64_t>(std::llround(std::max(burst, 1.0) * static_cast<double>(interval)));
    return {interval, window};
}

bool ControlAttemptLimiter::in_hand(const Bucket& bucket, const Rate& rate, std::int64_t now_us) {
    return std::max(bucket.full_at_us, now_us) + rate.interval_us - now_us <= rate.window_us;
}

ControlAttemptLimiter::Key ControlAttemptLimiter::key_of(const asio::ip::address& peer) {
    // IPv4 (also when mapped into IPv6) by address; IPv6 by its /64, the block one host
    // usually holds, so stepping through its addresses gains nothing.
    Key key{};
    if (peer.is_v4() || peer.to_v6().is_v4_mapped()) {
        const auto v4 = peer.is_v4() ? peer.to_v4() : asio::ip::make_address_v4(asio::ip::v4_mapped, peer.to_v6());
        const auto bytes = v4.to_bytes();
        key[10] = key[11] = 0xff;
        std::copy(bytes.begin(), bytes.end(), key.begin() + 12);
    } else {
        const auto bytes = peer.to_v6().to_bytes();
        std::copy(bytes.begin(), bytes.begin() + 8, key.begin());
    }
    return key;
}

ControlAttemptLimiter::Bucket* ControlAttemptLimiter::lookup(const Key& key) {
    for (auto& [k, bucket] : table_) {
        if (k == key) return &bucket;
    }
    return nullptr;
}

ControlAttemptLimiter::Bucket& ControlAttemptLimiter::insert(const Key& key, std::int64_t now_us) {
    if (table_.size() >= limits_.max_addresses) {
        // The entry that will be full soonest has the most failures in hand: the least suspect.
        auto least_suspect = std::min_element(table_.begin(), table_.end(), [](const auto& a, const auto& b) {
            return a.second.full_at_us < b.second.full_at_us;
        });
        *least_suspect = table_.back();
        table_.pop_back();
    }
    table_.push_back({key, Bucket{now_us}});
    return table_.back().second;
}

bool ControlAttemptLimiter::try_begin(const asio::ip::address& peer) {
    std::lock_guard lock(mutex_);
    const std::int64_t now = now_us_();
    if (!in_hand(global_, global_rate_, now)) return false;
    const Key key = key_of(peer);
    Bucket* bucket = lookup(key);
    if (bucket == nullptr) {
        bucket = &insert(key, now);
    } else if (!in_hand(*bucket, per_address_, now)) {
        return false;
    }
    bucket->full_at_us = std::max(bucket->full_at_us, now) + per_address_.interval_us;
    global_.full_at_us = std::max(global_.full_at_us, now) + global_rate_.interval_us;
    return true;
}

void ControlAttemptLimiter::succeeded(const asio::ip::address& peer) {
    std::lock_guard lock(mutex_);
    global_.full_at_us -= global_rate_.interval_us;
    if (Bucket* bucket = lookup(key_of(peer))) bucket->full_at_us -= per_address_.interval_us;
}

std::size_t ControlAttemptLimiter::tracked_addresses() const {
    std::lock_guard lock(mutex_);
    return table_.size();
}

void ControlCounters::register_in(CounterGroup& group) const {
    group.add("control_ok", ok);
    group.add("control_failed", failed);
    group.add("control_refused_disabled", refused_disabled);
    group.add("control_refused_not_loopback", refused_not_loopback);
    group.add("control_refused_no_token", refused_no_token);
    group.add("control_refused_bad_token", refused_bad_token);
    group.add("control_refused_throttled", refused_throttled);
}

void ControlCounters::count_result(const ControlResult& result) {
    (result.ok ? ok : failed).add();
}

std::optional<ControlRefusal> authorize_control(const ControlPolicy& policy,
                                                const std::optional<asio::ip::address>& peer,
                                                std::string_view given_token, ControlCounters& counters,
                                                LogLimiter& log, std::string_view who) {
    const asio::ip::address address = peer.value_or(asio::ip::address_v6::any());
    std::optional<ControlRefusal> refusal;
    if (policy.token.empty()) {
        refusal = ControlRefusal{ControlRefusal::kDisabled, "control disabled (no token configured)"};
    } else if (policy.loopback_only && !(peer && is_loopback(*peer))) {
        refusal = ControlRefusal{ControlRefusal::kNotLoopback, "control only from loopback"};
    } else if (given_token.empty()) {
        refusal = ControlRefusal{ControlRefusal::kNoToken, "token required"};
    } else if (policy.attempts != nullptr && !policy.attempts->try_begin(address)) {
        // Not compared: a guess made now tells the guesser nothing, right or wrong.
        refusal = ControlRefusal{ControlRefusal::kThrottled, "too many failed control attempts, try again later"};
    } else if (!token_equal(policy.token, given_token)) {
        refusal = ControlRefusal{ControlRefusal::kBadToken, "bad token"};  // the reservation stays spent
    } else if (policy.attempts != nullptr) {
        policy.attempts->succeeded(address);
    }
    if (!refusal) return refusal;
    Counter* counter[] = {&counters.refused_disabled, &counters.refused_not_loopback, &counters.refused_no_token,
                          &counters.refused_bad_token, &counters.refused_throttled};
    counter[refusal->kind]->add();
    // Throttled refusals have their own line per interval, so a guessing run shows up even
    // while bad-token lines are being suppressed.
    const LogLimiter::Kind kind =
        refusal->kind == ControlRefusal::kThrottled ? LogLimiter::kControlThrottled : LogLimiter::kControlRefused;
    std::uint64_t suppressed = 0;
    if (log.allow(kind, suppressed)) {
        spdlog::warn("{} refused: {} ({} suppressed)", who, refusal->reason, suppressed);
    }
    return refusal;
}

}  // namespace mocap::serve
