// spsc_ring.hpp — fixed-capacity single-producer single-consumer lock-free ring.
//
// Contract
// - Exactly one producer thread calls try_push/producer-side members, exactly one consumer
//   thread calls try_pop/front/pop. Which thread plays each role may change only across a
//   synchronisation point (thread start/join). size_approx()/capacity() may be called from
//   any thread.
// - Capacity is a power of two >= 2, fixed at construction (the only allocation). After
//   that, push and pop never allocate, never block, never take a lock (docs/style.md, "Hot path never allocates").
// - T is copied in by try_push and out by try_pop (or read in place with front()/pop()).
//   T must be default-constructible and nothrow-copy-assignable; slots are
//   default-constructed once up front.
// - Memory order: the producer publishes a slot with a release store of tail_, the consumer
//   frees it with a release store of head_; each side reads the other's index with acquire.
//   Each side caches the opposite index and re-reads it only when the cache says full/empty,
//   so an uncontended push or pop touches one shared cache line at most.
// Cost: push/pop are a copy of T plus one release store; ~a few ns when the caches are warm.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <type_traits>

namespace mocap {

/// Cache-line size used for padding shared indices (x86-64 and most ARMv8 cores).
inline constexpr std::size_t kCacheLineBytes = 64;

template <typename T>
class SpscRing {
    static_assert(std::is_default_constructible_v<T>, "ring slots are default-constructed");
    static_assert(std::is_nothrow_copy_assignable_v<T>, "push/pop must not throw");

public:
    /// @throws std::invalid_argument unless capacity is a power of two >= 2.
    explicit SpscRing(std::size_t capacity)
        : capacity_(checked_capacity(capacity)), mask_(capacity - 1), slots_(std::make_unique<T[]>(capacity)) {}

    SpscRing(const SpscRing&) = delete;
    SpscRing& operator=(const SpscRing&) = delete;

    /// Producer only. Returns false (and leaves the ring unchanged) when full.
    bool try_push(const T& value) noexcept {
        const std::uint64_t tail = tail_.load(std::memory_order_relaxed);
        if (tail - head_cache_ == capacity_) {
            head_cache_ = head_.load(std::memory_order_acquire);
            if (tail - head_cache_ == capacity_) return false;
        }
        slots_[tail & mask_] = value;
        tail_.store(tail + 1, std::memory_order_release);
        return true;
    }

    /// Consumer only. Returns false when empty.
    bool try_pop(T& out) noexcept {
        const T* slot = front();
        if (slot == nullptr) return false;
        out = *slot;
        pop();
        return true;
    }

    /// Consumer only. The oldest element, or nullptr when empty. The pointer stays valid
    /// (and the slot is not reused by the producer) until pop().
    [[nodiscard]] const T* front() noexcept {
        const std::uint64_t head = head_.load(std::memory_order_relaxed);
        if (head == tail_cache_) {
            tail_cache_ = tail_.load(std::memory_order_acquire);
            if (head == tail_cache_) return nullptr;
        }
        return &slots_[head & mask_];
    }

    /// Consumer only, after front() returned non-null: releases the oldest slot.
    void pop() noexcept { head_.store(head_.load(std::memory_order_relaxed) + 1, std::memory_order_release); }

    /// Consumer only: true when nothing is ready (re-reads the producer's index).
    [[nodiscard]] bool empty() const noexcept {
        return head_.load(std::memory_order_relaxed) == tail_.load(std::memory_order_acquire);
    }

    /// Any thread: number of elements at some recent instant (exact when both sides idle).
    [[nodiscard]] std::size_t size_approx() const noexcept {
        const std::uint64_t head = head_.load(std::memory_order_acquire);
        const std::uint64_t tail = tail_.load(std::memory_order_acquire);
        return tail >= head ? static_cast<std::size_t>(tail - head) : 0;
    }

    [[nodiscard]] std::size_t capacity() const noexcept { return capacity_; }

private:
    static std::size_t checked_capacity(std::size_t capacity) {
        if (capacity < 2 || (capacity & (capacity - 1)) != 0) {
            throw std::invalid_argument("SpscRing capacity must be a power of two >= 2");
        }
        return capacity;
    }

    // Read-only after construction (shared by both sides, never written: no false sharing).
    const std::uint64_t capacity_;
    const std::uint64_t mask_;
    const std::unique_ptr<T[]> slots_;

    // Producer-owned line: the index it writes and its cache of the consumer's index.
    alignas(kCacheLineBytes) std::atomic<std::uint64_t> tail_{0};
    std::uint64_t head_cache_ = 0;

    // Consumer-owned line.
    alignas(kCacheLineBytes) std::atomic<std::uint64_t> head_{0};
    std::uint64_t tail_cache_ = 0;
    // sizeof(SpscRing) is a multiple of the line size, so nothing that follows the object
    // shares the consumer's line.
};

}  // namespace mocap
