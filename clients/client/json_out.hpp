// json_out.hpp — the few JSON helpers mocap-client needs (no dependency for this).
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>

namespace mocap::client {

inline void json_string(std::string& out, std::string_view s) {
    out += '"';
    for (char ch : s) {
        const auto c = static_cast<unsigned char>(ch);
        if (c == '"' || c == '\\') {
            out += '\\';
            out += ch;
        } else if (c < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\u%04x", c);
            out += buf;
        } else {
            out += ch;
        }
    }
    out += '"';
}

/// Shortest round-tripping form for floats from the wire; null for NaN/inf.
inline void json_number(std::string& out, double v, int digits = 9) {
    if (!std::isfinite(v)) {
        out += "null";
        return;
    }
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.*g", digits, v);
    out += buf;
}

inline void json_int(std::string& out, std::int64_t v) {
    out += std::to_string(v);
}
inline void json_uint(std::string& out, std::uint64_t v) {
    out += std::to_string(v);
}

}  // namespace mocap::client
