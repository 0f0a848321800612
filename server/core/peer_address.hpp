// peer_address.hpp — the address a connection comes from, as the connection-slot rules
// (core/connection_slots.hpp) key it: the IP address without the port, and whether it is
// a loopback peer. Header-only (Asio), for ingest and serve.
#pragma once

#include <string>

#include "core/asio.hpp"

namespace mocap {

struct PeerAddress {
    std::string ip;         ///< "10.0.0.7", "::1"; "?" when the peer is already gone
    bool loopback = false;  ///< 127.0.0.0/8, ::1, or ::ffff:127.x.y.z on a dual-stack socket
};

inline PeerAddress peer_address(const asio::ip::tcp::socket& socket) {
    boost::system::error_code ec;
    const auto peer = socket.remote_endpoint(ec);
    if (ec) return {"?", false};
    asio::ip::address a = peer.address();
    // A dual-stack listener sees IPv4 peers as ::ffff:a.b.c.d: key them as the IPv4 address,
    // so one host is one key whichever way it connects.
    if (a.is_v6() && a.to_v6().is_v4_mapped()) a = asio::ip::make_address_v4(asio::ip::v4_mapped, a.to_v6());
    return {a.to_string(), a.is_loopback()};
}

}  // namespace mocap
