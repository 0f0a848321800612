// origin_check.cpp — Host against the allowed names, Origin against Host and the allow-list
// (origin_check.hpp).
#include "serve/origin_check.hpp"

#include <arpa/inet.h>

#include <algorithm>
#include <cctype>
#include <optional>

namespace mocap::serve {

namespace {

std::string lower(std::string_view s) {
    std::string out(s);
    std::transform(out.begin(), out.end(), out.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return out;
}

std::string_view trim(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t'))
        s.remove_prefix(1);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t'))
        s.remove_suffix(1);
    return s;
}

// "host[:port]" (IPv6 in brackets) -> "host:port", lower case, with `default_port` when the
// text names none; nullopt when it is not of that form.
std::optional<std::string> host_port(std::string_view text, std::string_view default_port) {
    if (text.empty()) return std::nullopt;
    std::string_view host, port;
    if (text.front() == '[') {
        const auto close = text.find(']');
        if (close == std::string_view::npos) return std::nullopt;
        host = text.substr(0, close + 1);
        const std::string_view rest = text.substr(close + 1);
        if (!rest.empty() && rest.front() != ':') return std::nullopt;
        port = rest.empty() ? std::string_view() : rest.substr(1);
    } else {
        const auto colon = text.find(':');
        host = text.substr(0, colon);
        port = colon == std::string_view::npos ? std::string_view() : text.substr(colon + 1);
        if (port.find(':') != std::string_view::npos) return std::nullopt;
    }
    if (host.empty() || host.find_first_of("/?#@ ") != std::string_view::npos) return std::nullopt;
    if (port.empty()) port = default_port;
    if (!std::all_of(port.begin(), port.end(), [](unsigned char c) { return std::isdigit(c) != 0; })) {
        return std::nullopt;
    }
    return lower(host) + ":" + std::string(port);
}

// The host of a Host header without its port and a trailing dot, lower case; nullopt when
// the text is not "host[:port]".
std::optional<std::string> host_name(std::string_view text) {
    const auto hp = host_port(text, "0");
    if (!hp) return std::nullopt;
    std::string name = hp->substr(0, hp->rfind(':'));
    if (name.size() > 1 && name.back() == '.') name.pop_back();
    return name;
}

bool is_ip_literal(const std::string& name) {
    if (name.front() == '[') return true;  // host_port() admits brackets only around the whole host
    in_addr a{};
    return ::inet_pton(AF_INET, name.c_str(), &a) == 1;
}

}  // namespace

bool http_host_allowed(std::string_view host, const std::vector<std::string>& names) {
    host = trim(host);
    if (host.empty()) return true;
    const auto name = host_name(host);
    if (!name) return false;
    if (is_ip_literal(*name)) return true;
    return std::any_of(names.begin(), names.end(), [&](const std::string& allowed) {
        std::string a = lower(allowed);
        if (a.size() > 1 && a.back() == '.') a.pop_back();
        return a == *name;
    });
}

bool websocket_origin_allowed(std::string_view origin, std::string_view host, const std::vector<std::string>& allowed) {
    origin = trim(origin);
    if (origin.empty()) return true;
    std::string wanted = lower(origin);
    if (wanted.size() > 1 && wanted.back() == '/') wanted.pop_back();
    for (const std::string& a : allowed) {
        std::string entry = lower(a);
        if (entry.size() > 1 && entry.back() == '/') entry.pop_back();
        if (entry == wanted) return true;
    }
    std::string_view rest = wanted;
    std::string_view default_port;
    if (rest.substr(0, 7) == "http://") {
        rest.remove_prefix(7);
        default_port = "80";
    } else if (rest.substr(0, 8) == "https://") {
        rest.remove_prefix(8);
        default_port = "443";
    } else {
        return false;  // "null", other schemes
    }
    const auto from_origin = host_port(rest, default_port);
    const auto served = host_port(trim(host), default_port);
    return from_origin && served && *from_origin == *served;
}

}  // namespace mocap::serve
