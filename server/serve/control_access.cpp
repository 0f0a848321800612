// control_access.cpp — the control rules, their counters and the refusal log line.
#include "serve/control_access.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>

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

void ControlCounters::register_in(CounterGroup& group) const {
    group.add("control_ok", ok);
    group.add("control_failed", failed);
    group.add("control_refused_disabled", refused_disabled);
    group.add("control_refused_not_loopback", refused_not_loopback);
    group.add("control_refused_no_token", refused_no_token);
    group.add("control_refused_bad_token", refused_bad_token);
}

void ControlCounters::count_result(const ControlResult& result) {
    (result.ok ? ok : failed).add();
}

std::optional<ControlRefusal> authorize_control(const ControlPolicy& policy, bool peer_loopback,
                                                std::string_view given_token, ControlCounters& counters,
                                                LogLimiter& log, std::string_view who) {
    std::optional<ControlRefusal> refusal;
    if (policy.token.empty()) {
        refusal = ControlRefusal{ControlRefusal::kDisabled, "control disabled (no token configured)"};
    } else if (policy.loopback_only && !peer_loopback) {
        refusal = ControlRefusal{ControlRefusal::kNotLoopback, "control only from loopback"};
    } else if (given_token.empty()) {
        refusal = ControlRefusal{ControlRefusal::kNoToken, "token required"};
    } else if (!token_equal(policy.token, given_token)) {
        refusal = ControlRefusal{ControlRefusal::kBadToken, "bad token"};
    }
    if (!refusal) return refusal;
    Counter* counter[] = {&counters.refused_disabled, &counters.refused_not_loopback, &counters.refused_no_token,
                          &counters.refused_bad_token};
    counter[refusal->kind]->add();
    std::uint64_t suppressed = 0;
    if (log.allow(LogLimiter::kControlRefused, suppressed)) {
        spdlog::warn("{} refused: {} ({} suppressed)", who, refusal->reason, suppressed);
    }
    return refusal;
}

}  // namespace mocap::serve
