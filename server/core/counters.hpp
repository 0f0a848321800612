// counters.hpp — monotonically increasing event counters, grouped per component
// (docs/style.md, "Counters only go up": every component exposes counters that only go up; the daemon publishes them).
//
// Contract
// - Counter: add() from any thread (relaxed atomic fetch_add: a locked read-modify-write,
//   ~5 ns uncontended on x86; a counter written by several threads bounces its cache line,
//   so hot counters are per thread); value() from any thread. Values never decrease. Relaxed
//   order: a reader sees each counter's own history in order but no ordering between
//   different counters.
// - SingleWriterCounter: the same for readers, but add() is a relaxed load + relaxed store
//   (plain loads and stores on x86 and ARM, well under 1 ns: no locked instruction; see
//   docs/performance.md), which is only correct while ONE thread writes it.
//   SINGLE-WRITER RULE: every add() of a given SingleWriterCounter must happen on one thread,
//   or on threads handed over with a happens-before edge (a join, a mutex, a strand). Two
//   threads adding concurrently lose increments silently — no crash, and no sanitizer report,
//   because every access is atomic. A component that declares one states which thread owns
//   it; to add a writer on another thread, give that thread its own counter (CounterGroup
//   sums parts under one name) or use Counter. Readers are unrestricted and race-free.
// - CounterGroup: names a component's counters for a stats reader. It holds pointers to
//   counters (either kind, as CounterBase) owned by the component, so it must not outlive
//   them. It is built during set-up (add()/add_part() from one thread, before any reader
//   runs) and is read-only afterwards: snapshot()/value() may then be called from any
//   thread. An entry may sum several parts (e.g. one counter per worker thread) under one
//   name.
// - snapshot() allocates (a vector): stats path only, never the hot path.
#pragma once

#include <atomic>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace mocap {

/// `cell += n` for an atomic that only the calling thread writes (the single-writer rule
/// above): relaxed load + relaxed store, so concurrent readers never race and see a value
/// that only goes up. Shared by SingleWriterCounter and SingleWriterLatencyHistogram.
inline void single_writer_add(std::atomic<std::uint64_t>& cell, std::uint64_t n) noexcept {
    cell.store(cell.load(std::memory_order_relaxed) + n, std::memory_order_relaxed);
}

/// What a stats reader needs of either counter type (CounterGroup holds these).
class CounterBase {
public:
    CounterBase(const CounterBase&) = delete;
    CounterBase& operator=(const CounterBase&) = delete;

    [[nodiscard]] std::uint64_t value() const noexcept { return value_.load(std::memory_order_relaxed); }

protected:
    CounterBase() = default;
    ~CounterBase() = default;
    std::atomic<std::uint64_t> value_{0};
};

/// Any number of writer threads.
class Counter : public CounterBase {
public:
    void add(std::uint64_t n = 1) noexcept { value_.fetch_add(n, std::memory_order_relaxed); }
};

/// One writer thread (see the single-writer rule above); readers on any thread.
class SingleWriterCounter : public CounterBase {
public:
    void add(std::uint64_t n = 1) noexcept { single_writer_add(value_, n); }
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
    void add(std::string_view name, const CounterBase& counter);

    [[nodiscard]] const std::string& component() const noexcept { return component_; }

    /// Any thread (after set-up). One value per entry, in entry order.
    [[nodiscard]] std::vector<CounterValue> snapshot() const;

    /// Any thread (after set-up). The summed value of one entry, or nullopt if unknown.
    [[nodiscard]] std::optional<std::uint64_t> value(std::string_view name) const;

private:
    struct Entry {
        std::string name;
        std::vector<const CounterBase*> parts;
        [[nodiscard]] std::uint64_t sum() const noexcept;
    };

    std::string component_;
    std::vector<Entry> entries_;
};

}  // namespace mocap
