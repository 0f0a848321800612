// saturating.hpp — int64 microsecond arithmetic that clamps instead of overflowing.
//
// Stamps that come off the network (a sink's packet timestamp) are untrusted: the sum or
// difference of two of them can leave int64, and signed overflow is undefined behaviour (in
// practice a wrap that turned a hostile stamp into a latency of decades). These clamp to
// INT64_MIN/INT64_MAX instead; callers that need a plausible value check the range after.
// Pure, constexpr, no allocation.
#pragma once

#include <cstdint>
#include <limits>

namespace mocap {

inline constexpr std::int64_t kInt64Max = std::numeric_limits<std::int64_t>::max();
inline constexpr std::int64_t kInt64Min = std::numeric_limits<std::int64_t>::min();

/// a + b, clamped to the int64 range.
constexpr std::int64_t saturating_add(std::int64_t a, std::int64_t b) noexcept {
    std::int64_t r = 0;
    if (__builtin_add_overflow(a, b, &r)) return b > 0 ? kInt64Max : kInt64Min;
    return r;
}

/// a - b, clamped to the int64 range.
constexpr std::int64_t saturating_sub(std::int64_t a, std::int64_t b) noexcept {
    std::int64_t r = 0;
    if (__builtin_sub_overflow(a, b, &r)) return b < 0 ? kInt64Max : kInt64Min;
    return r;
}

/// An unsigned wire value as int64, clamped at INT64_MAX (a plain cast wraps to negative).
constexpr std::int64_t saturating_int64(std::uint64_t v) noexcept {
    return v > static_cast<std::uint64_t>(kInt64Max) ? kInt64Max : static_cast<std::int64_t>(v);
}

}  // namespace mocap
