// bvh_text.hpp — small checks on BVH text that the server and the clients share,
// header-only and dependency-free (the client library does not link the skeleton).
#pragma once

#include <cstddef>
#include <string_view>

namespace mocap::serve {

/// Numbers (whitespace-separated tokens) on one MOTION line. No BVH importer rejects a line
/// with too many values, so writers and readers of mocapd's BVH check this themselves.
inline std::size_t bvh_value_count(std::string_view line) {
    std::size_t count = 0;
    bool in_token = false;
    for (const char c : line) {
        const bool space = c == ' ' || c == '\t' || c == '\r' || c == '\n';
        if (!space && !in_token) ++count;
        in_token = !space;
    }
    return count;
}

}  // namespace mocap::serve
