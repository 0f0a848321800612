#include "daemon/endpoint.hpp"

#include <arpa/inet.h>
#include <net/if.h>

#include <array>
#include <charconv>

namespace mocap::daemon {
namespace {

// An IPv4 or IPv6 literal, as make_address accepts it (an IPv6 link-local address may carry
// "%interface", which must name an interface of this host).
bool is_address_literal(const std::string& host) {
    std::array<unsigned char, sizeof(in6_addr)> buf{};
    if (inet_pton(AF_INET, host.c_str(), buf.data()) == 1) return true;
    const auto percent = host.find('%');
    const std::string addr = host.substr(0, percent);
    if (inet_pton(AF_INET6, addr.c_str(), buf.data()) != 1) return false;
    return percent == std::string::npos || if_nametoindex(host.substr(percent + 1).c_str()) != 0;
}

}  // namespace

std::string Endpoint::str() const {
    return (host.find(':') != std::string::npos ? "[" + host + "]" : host) + ":" + std::to_string(port);
}

std::optional<Endpoint> parse_destination(std::string_view text, std::string* error) {
    Endpoint ep;
    std::string_view port_part;
    if (!text.empty() && text.front() == '[') {
        const auto close = text.find(']');
        if (close == std::string_view::npos || close + 1 >= text.size() || text[close + 1] != ':') {
            *error = "expected \"[v6-address]:port\"";
            return std::nullopt;
        }
        ep.host = std::string(text.substr(1, close - 1));
        port_part = text.substr(close + 2);
    } else {
        const auto colon = text.rfind(':');
        if (colon == std::string_view::npos || colon == 0) {
            *error = "expected \"host:port\"";
            return std::nullopt;
        }
        ep.host = std::string(text.substr(0, colon));
        port_part = text.substr(colon + 1);
    }
    unsigned port = 0;
    const auto [end, ec] = std::from_chars(port_part.data(), port_part.data() + port_part.size(), port);
    if (ec != std::errc{} || end != port_part.data() + port_part.size() || port == 0 || port > 65535) {
        *error = "port must be 1..65535";
        return std::nullopt;
    }
    ep.port = static_cast<std::uint16_t>(port);
    return ep;
}

std::optional<Endpoint> parse_endpoint(std::string_view text, std::string* error) {
    auto ep = parse_destination(text, error);
    // The listeners bind with asio::ip::make_address, which takes address literals only: a
    // host name would pass here and fail at start-up, so it is refused here.
    if (ep && !is_address_literal(ep->host)) {
        *error = "host \"" + ep->host + "\" must be an IPv4 or IPv6 address (names are not resolved)";
        return std::nullopt;
    }
    return ep;
}

}  // namespace mocap::daemon
