// counters.hpp — monotonically increasing event counters, grouped per component
// (house style 5: every component exposes counters that only go up; the daemon publishes them).
//
// Contract
// - Counter: add() from any thread (relaxed atomic fetch_add, ~1–5 ns uncontended; a counter
//   written by several threads bounces its cache line, so hot counters are per thread);
//   value() from any thread. Values never decrease. Relaxed order: a reader sees each counter's
//   own history in order but no ordering between different counters.
// - CounterGroup: names a component's counters for a stats reader. It holds pointers to
//   Counter objects owned by the component, so it must not outlive them. It is built during
//   set-up (add()/add_part() from one thread, before any reader runs) and is read-only
//   afterwards: snapshot()/value() may then be called from any thread. An entry may sum
//   several parts (e.g. one counter per worker thread) under one name.
// - snapshot() allocates (a vector): stats path only, never the hot path.
#pragma once

#include <atomic>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace mocap {

class Counter {
  public:
    void add(std::uint64_t n = 1) noexcept { value_.fetch_add(n, std::memory_order_relaxed); }
    [[nodiscard]] std::uint64_t value() const noexcept {
        return value_.load(std::memory_order_relaxed);
    }

  private:
    std::atomic<std::uint64_t> value_{0};
};

struct CounterValue {
    std::string name;
    std::uint64_t value = 0;
};

class CounterGroup {
  public:
    explicit CounterGroup(std::string component) : component_(std::move(component)) {}

    CounterGroup(const CounterGroup&) = delete;
    CounterGroup& operator=(const CounterGroup&) = delete;

    /// Set-up only. Adds `counter` as a part of entry `name` (creates the entry if new;
    /// adding to an existing name sums the parts). Entries keep their first-added order.
    void add(std::string_view name, const Counter& counter);

    [[nodiscard]] const std::string& component() const noexcept { return component_; }

    /// Any thread (after set-up). One value per entry, in entry order.
    [[nodiscard]] std::vector<CounterValue> snapshot() const;

    /// Any thread (after set-up). The summed value of one entry, or nullopt if unknown.
    [[nodiscard]] std::optional<std::uint64_t> value(std::string_view name) const;

  private:
    struct Entry {
        std::string name;
        std::vector<const Counter*> parts;
        [[nodiscard]] std::uint64_t sum() const noexcept;
    };

    std::string component_;
    std::vector<Entry> entries_;
};

}  // namespace mocap
