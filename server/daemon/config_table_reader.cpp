#include "daemon/config_table_reader.hpp"

#include <cmath>
#include <sstream>

namespace mocap::daemon {

std::size_t line_of(const toml::node& n) {
    return n.source().begin.line;
}

// A TOML number (integer or float) as a double. toml++'s value<double>() refuses an
// integer that a double cannot hold exactly (above 2^53), so convert by hand: the range
// checks that follow reject such values with a proper message.
double number_of(const toml::node& n) {
    if (const auto* i = n.as_integer()) return static_cast<double>(i->get());
    return n.as_floating_point()->get();
}

const toml::node* TableReader::take(std::string_view key) {
    taken_.insert(std::string(key));
    return table_.get(key);
}

std::string TableReader::key_path(std::string_view key) const {
    return path_.empty() ? std::string(key) : path_ + "." + std::string(key);
}

void TableReader::fail(std::string_view key, const toml::node* n, std::string msg) const {
    throw ConfigError{key_path(key), n ? line_of(*n) : line_of(table_), std::move(msg)};
}

void TableReader::read(std::string_view key, std::string& out) {
    if (const auto* n = take(key)) {
        if (!n->is_string()) fail(key, n, "expected a string");
        out = n->value<std::string>().value();
    }
}

void TableReader::read(std::string_view key, double& out, double lo, double hi) {
    if (const auto* n = take(key)) {
        if (!n->is_number()) fail(key, n, "expected a number");
        const double v = number_of(*n);
        if (!std::isfinite(v) || v < lo || v > hi) {
            std::ostringstream s;
            s << "must be between " << lo << " and " << hi;
            fail(key, n, s.str());
        }
        out = v;
    }
}

// 0 switches the feature off; any other value must lie in lo..hi (a tiny period or size
// is never what an operator means: raw_rotate_s = 0.001 made hundreds of files a second).
void TableReader::read_zero_or(std::string_view key, double& out, double lo, double hi) {
    if (const auto* n = take(key)) {
        if (!n->is_number()) fail(key, n, "expected a number");
        const double v = number_of(*n);
        if (!std::isfinite(v) || (v != 0.0 && (v < lo || v > hi))) {
            std::ostringstream s;
            s << "must be 0 (off) or between " << lo << " and " << hi;
            fail(key, n, s.str());
        }
        out = v;
    }
}

void TableReader::read(std::string_view key, Endpoint& out) {
    if (const auto* n = take(key)) {
        if (!n->is_string()) fail(key, n, "expected a string \"host:port\"");
        std::string err;
        auto ep = parse_endpoint(n->value<std::string>().value(), &err);
        if (!ep) fail(key, n, err);
        out = *ep;
    }
}

const toml::table* TableReader::sub_table(std::string_view key) {
    const auto* n = take(key);
    if (!n) return nullptr;
    if (!n->is_table()) fail(key, n, "expected a table");
    return n->as_table();
}

const toml::array* TableReader::array(std::string_view key) {
    const auto* n = take(key);
    if (!n) return nullptr;
    if (!n->is_array()) fail(key, n, "expected an array");
    return n->as_array();
}

void TableReader::finish() const {
    for (const auto& [k, v] : table_) {
        if (!taken_.count(std::string(k.str()))) fail(k.str(), &v, "unknown key");
    }
}

}  // namespace mocap::daemon
