// subject_ids.hpp — where a subject id sits in a sorted list of subject ids.
//
// Subject ids are sparse 32-bit numbers ([ingest] subject_id_base + sink id, or a SocketCAN
// subject's own id, docs/cluster.md): tables keyed by subject hold a sorted id list and
// search it (O(log subjects), no allocation), never an array indexed by the id itself.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

namespace mocap {

/// Position of `id` in `sorted_ids` (ascending, each id once), or -1 if it is not there.
[[nodiscard]] inline int subject_position(const std::vector<std::uint32_t>& sorted_ids, std::uint32_t id) noexcept {
    const auto it = std::lower_bound(sorted_ids.begin(), sorted_ids.end(), id);
    return (it != sorted_ids.end() && *it == id) ? static_cast<int>(it - sorted_ids.begin()) : -1;
}

}  // namespace mocap
