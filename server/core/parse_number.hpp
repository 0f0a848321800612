// parse_number.hpp — strict text-to-number conversion for command-line arguments, config
// values and text formats: the whole token must be the number (no leading space, no
// trailing characters), the value must fit the type, and a floating-point value must be
// finite. A leading '+' is accepted. std::from_chars underneath: locale-independent and
// allocation-free, unlike sscanf/strtod, which silently accept "5x" or saturate on
// overflow.
#pragma once

#include <charconv>
#include <cmath>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <vector>

namespace mocap::core {

template <typename T>
requires std::is_arithmetic_v<T> &&(!std::is_same_v<T, bool>)
    [[nodiscard]] bool parse_number(std::string_view text, T& out) {
    if (!text.empty() && text.front() == '+') {
        text.remove_prefix(1);
        if (!text.empty() && text.front() == '-') return false;  // "+-1"
    }
    T v{};
    const char* end = text.data() + text.size();
    const auto r = std::from_chars(text.data(), end, v);
    if (r.ec != std::errc() || r.ptr != end) return false;
    if constexpr (std::is_floating_point_v<T>) {
        if (!std::isfinite(v)) return false;
    }
    out = v;
    return true;
}

/// Splits "a:b:c" at every `separator`; an empty text gives one empty field.
[[nodiscard]] inline std::vector<std::string_view> split_fields(std::string_view text, char separator) {
    std::vector<std::string_view> fields;
    for (;;) {
        const std::size_t at = text.find(separator);
        fields.push_back(text.substr(0, at));
        if (at == std::string_view::npos) return fields;
        text.remove_prefix(at + 1);
    }
}

}  // namespace mocap::core
