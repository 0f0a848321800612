// address_budget.hpp — the pose service's request budget per peer address, kept across
// connections (issue 24, item 8; docs/security.md, "Reconnect storms").
//
// Why: the per-connection rate limit (client_message_burst, max_client_messages_per_s)
// starts full on every connection, so a client that reconnects after each burst sends as
// fast as it can connect: four loopback threads reconnecting ~500 times a second, each
// pipelining 40 Stats requests, queued thousands of connections and their requests ahead
// of a new client, whose Hello took 7–16 s. A token bucket per address (IPv4 address;
// IPv6 /64, the block one host holds) makes a reconnect gain nothing: beyond
// `burst` requests at once and `per_s` sustained the address's requests close their
// connection with Goodbye(RATE_LIMITED), and a connection from an address with no request
// in hand is refused at accept, before it costs a session.
//
// Every address counts, loopback too: the limits are far above what legitimate clients of
// one host send (a viewer sends one Subscribe; `mocap-client load` with 100 clients, 100),
// and a storm from the host itself is the case measured above.
//
// The table is bounded (`max_addresses`): a new address when it is full takes the place of
// the address seen least recently; a forgotten address starts again with a full bucket.
// Thread-safety: every member may be called from any thread (one mutex, held for a lookup).
// Cost: a map lookup per request; a scan of the table when a new address finds it full.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <mutex>

#include "core/asio.hpp"
#include "serve/control_access.hpp"

namespace mocap::serve {

struct AddressBudgetLimits {
    double burst = 1000.0;             ///< requests at once ([serve] address_message_burst)
    double per_s = 500.0;              ///< sustained ([serve] max_address_messages_per_s)
    std::size_t max_addresses = 4096;  ///< addresses remembered
};

class AddressBudget {
public:
    explicit AddressBudget(const AddressBudgetLimits& limits);

    /// Takes one request from `peer`'s bucket at `now_us` (any monotonic µs); false = none
    /// in hand: the request must be refused.
    bool take(const asio::ip::address& peer, std::int64_t now_us);
    /// True when `peer` has at least one request in hand (a new connection may be served).
    bool in_hand(const asio::ip::address& peer, std::int64_t now_us);
    [[nodiscard]] std::size_t tracked_addresses() const;

private:
    using Key = ControlAttemptLimiter::Key;
    struct Bucket {
        double tokens = 0;
        std::int64_t refilled_us = 0;
    };
    static Key key_of(const asio::ip::address& peer);
    Bucket& bucket(const Key& key, std::int64_t now_us);  // mutex held; refilled to now_us

    AddressBudgetLimits limits_;
    mutable std::mutex mutex_;
    std::map<Key, Bucket> table_;  // guarded
};

}  // namespace mocap::serve
