// config_table_reader.hpp — reads one table of mocapd's TOML configuration (daemon/config.hpp):
// typed reads with their ranges, every key taken remembered so that finish() rejects the rest
// as unknown, and each problem thrown as a ConfigError naming the key path and the line of the
// value, so the user sees exactly where to look.
//
// Used only while parse_config runs, which catches every ConfigError: none leaves it. Not
// thread-safe (one reader per table); allocates for key paths and messages.
#pragma once

#include <toml++/toml.h>

#include <cstddef>
#include <cstdint>
#include <set>
#include <string>
#include <string_view>
#include <utility>

#include "daemon/endpoint.hpp"

namespace mocap::daemon {

// Thrown only while a config is read and caught by parse_config: carries the key path and
// line of the offending value, so the user sees exactly where to look.
struct ConfigError {
    std::string key;
    std::size_t line;
    std::string message;
};

/// The line of a value in the file.
std::size_t line_of(const toml::node& n);

/// A TOML number (integer or float) as a double, an integer above 2^53 included (rounded).
double number_of(const toml::node& n);

// Reads one table: every key taken is remembered, and finish() rejects the rest.
class TableReader {
public:
    TableReader(const toml::table& t, std::string path) : table_(t), path_(std::move(path)) {}

    /// The value of `key` (nullptr if absent), marked as known.
    const toml::node* take(std::string_view key);
    /// "section.key" of `key` in this table.
    std::string key_path(std::string_view key) const;
    /// Throws the ConfigError for `key` at the line of `n` (or of the table when n is null).
    [[noreturn]] void fail(std::string_view key, const toml::node* n, std::string msg) const;

    void read(std::string_view key, std::string& out);
    void read(std::string_view key, double& out, double lo, double hi);
    // 0 switches the feature off; any other value must lie in lo..hi (a tiny period or size
    // is never what an operator means: raw_rotate_s = 0.001 made hundreds of files a second).
    void read_zero_or(std::string_view key, double& out, double lo, double hi);
    template <typename U>
    void read(std::string_view key, U& out, std::int64_t lo, std::int64_t hi) {
        if (const auto* n = take(key)) {
            if (!n->is_integer()) fail(key, n, "expected an integer");
            const std::int64_t v = n->value<std::int64_t>().value();
            if (v < lo || v > hi) {
                fail(key, n, "must be between " + std::to_string(lo) + " and " + std::to_string(hi));
            }
            out = static_cast<U>(v);
        }
    }

    void read(std::string_view key, Endpoint& out);

    /// The sub-table or array at `key` (nullptr if absent); fails on another type.
    const toml::table* sub_table(std::string_view key);
    const toml::array* array(std::string_view key);

    /// Fails on the first key of the table nothing took.
    void finish() const;

private:
    const toml::table& table_;
    std::string path_;
    std::set<std::string> taken_;
};

}  // namespace mocap::daemon
