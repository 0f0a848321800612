// endpoint.hpp — "host:port" as the configuration writes it: the listeners' addresses and the
// outputs' destinations ([vmc] destinations), split and checked. Pure functions: thread-safe,
// no I/O but the interface lookup of an IPv6 "%interface" suffix.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace mocap::daemon {

/// "host:port" split and checked (port 1..65535; host an IPv4/IPv6 literal: the listeners do
/// not resolve names).
struct Endpoint {
    std::string host;
    std::uint16_t port = 0;
    [[nodiscard]] std::string str() const;
    bool operator==(const Endpoint&) const = default;
};

/// Parses "host:port" or "[v6]:port" (host an address literal).
std::optional<Endpoint> parse_endpoint(std::string_view text, std::string* error);
/// The same split for a destination whose host may be a name (not resolved here).
std::optional<Endpoint> parse_destination(std::string_view text, std::string* error);

}  // namespace mocap::daemon
