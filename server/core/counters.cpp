// counters.cpp — CounterGroup bookkeeping. Nothing here is on a hot path: the counters' add()
// is inline in the header, the group only maps names to counters for the stats reader.
#include "core/counters.hpp"

#include <algorithm>

namespace mocap {

void CounterGroup::add(std::string_view name, const CounterBase& counter) {
    auto it = std::find_if(entries_.begin(), entries_.end(), [&](const Entry& e) { return e.name == name; });
    if (it == entries_.end()) {
        entries_.push_back(Entry{std::string(name), {&counter}});
    } else {
        it->parts.push_back(&counter);
    }
}

std::uint64_t CounterGroup::Entry::sum() const noexcept {
    std::uint64_t total = 0;
    for (const CounterBase* part : parts)
        total += part->value();
    return total;
}

std::vector<CounterValue> CounterGroup::snapshot() const {
    std::vector<CounterValue> out;
    out.reserve(entries_.size());
    for (const Entry& e : entries_)
        out.push_back(CounterValue{e.name, e.sum()});
    return out;
}

std::optional<std::uint64_t> CounterGroup::value(std::string_view name) const {
    for (const Entry& e : entries_) {
        if (e.name == name) return e.sum();
    }
    return std::nullopt;
}

}  // namespace mocap
