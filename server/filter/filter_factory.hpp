// filter_factory.hpp — builds orientation filters by name from textual key=value parameters
// (command lines, config files).
//
// Names: filter_names(). Keys: the `key "..."` named in each filter's Params header, listed
// with their defaults by filter_keys(). Values: numbers as written by C++ (from_chars, no
// trailing characters), booleans as true/false/1/0/yes/no/on/off; every number has a range
// (FilterKey::min..max), so `--check-config` and the start refuse `beta = 1e308`. Keys not
// given keep their defaults. Untrusted input: a bad name, key or value never throws, it returns nullptr and
// a message naming the offending item.
//
// Thread-safety: all functions are pure (the tables are constant). Cost: allocation, call
// only at start-up.
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "filter/orientation_filter.hpp"

namespace mocap::filter {

/// Ordered (key, value) pairs; a key given twice takes its last value.
using FilterParamList = std::vector<std::pair<std::string, std::string>>;

/// Builds the filter `name` with `params` applied over its defaults. On failure returns
/// nullptr and, if error is non-null, sets *error to a message naming the unknown filter,
/// the unknown key, or the key whose value is malformed or out of range.
std::unique_ptr<OrientationFilter> make_filter(std::string_view name, const FilterParamList& params,
                                               std::string* error = nullptr);

/// Every name make_filter accepts, the product default ("mocap") first.
std::vector<std::string_view> filter_names();

/// One documented parameter of a filter.
struct FilterKey {
    std::string_view key;
    std::string default_value;  ///< the default, written so that make_filter accepts it
    /// The values make_filter accepts, inclusive (a filter's own check may narrow them, e.g.
    /// "> 0"); infinite for booleans and the particle filter's seed.
    double min = -std::numeric_limits<double>::infinity();
    double max = std::numeric_limits<double>::infinity();
};

/// The parameters of filter `name` (empty for an unknown name).
std::vector<FilterKey> filter_keys(std::string_view name);

/// Relative cost of one update of filter `name`, for balancing a worker pool by work rather
/// than by segment count: 20 for the particle filter ("pf", tens of times a complementary
/// filter), 1 for every other name (unknown names too).
std::uint32_t filter_cost_weight(std::string_view name);

}  // namespace mocap::filter
