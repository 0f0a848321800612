// http_query.hpp — the query string of a request target: one value by key, and
// application/x-www-form-urlencoded decoding for values a client may escape (take names and
// notes). Pure functions; no allocation but the decoded string.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "core/parse_number.hpp"

namespace mocap::serve {

/// "a=1&b=x" -> the raw (still escaped) value of `key`; "" for "a", nullopt when absent.
inline std::optional<std::string_view> query_value(std::string_view query, std::string_view key) {
    while (!query.empty()) {
        const std::size_t amp = query.find('&');
        const std::string_view pair = query.substr(0, amp);
        const std::size_t eq = pair.find('=');
        if (pair.substr(0, eq) == key) return eq == std::string_view::npos ? "" : pair.substr(eq + 1);
        if (amp == std::string_view::npos) break;
        query.remove_prefix(amp + 1);
    }
    return std::nullopt;
}

/// A decimal uint32, nothing else.
inline std::optional<std::uint32_t> parse_u32(std::string_view s) {
    std::uint32_t v = 0;
    if (!core::parse_number(s, v)) return std::nullopt;
    return v;
}

/// "%41+b" -> "A b"; nullopt for a '%' not followed by two hex digits.
inline std::optional<std::string> percent_decode(std::string_view s) {
    const auto hex = [](char c) -> int {
        if (c >= '0' && c <= '9') return c - '0';
        if (c >= 'a' && c <= 'f') return c - 'a' + 10;
        if (c >= 'A' && c <= 'F') return c - 'A' + 10;
        return -1;
    };
    std::string out;
    out.reserve(s.size());
    for (std::size_t i = 0; i < s.size(); ++i) {
        if (s[i] == '+') {
            out += ' ';
        } else if (s[i] != '%') {
            out += s[i];
        } else {
            if (i + 2 >= s.size()) return std::nullopt;
            const int hi = hex(s[i + 1]);
            const int lo = hex(s[i + 2]);
            if (hi < 0 || lo < 0) return std::nullopt;
            out += static_cast<char>(hi * 16 + lo);
            i += 2;
        }
    }
    return out;
}

}  // namespace mocap::serve
