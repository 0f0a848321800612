// event_count.hpp — lets a consumer sleep when its rings are empty without a lock on the
// producer's fast path (an "event count", as in folly/Eigen), on a Linux futex.
//
// Protocol (consumer side; any number of threads may wait on one EventCount):
//     auto key = ev.prepare_wait();
//     if (work_available() || stopping) { ev.cancel_wait(); continue; }
//     ev.wait(key);                      // or wait_for(key, timeout_us)
// Producer side, after publishing work (e.g. a ring push with release order):
//     ev.notify_all();
// A notify that races with prepare_wait is never lost: both sides read the waiter count with
// an atomic read-modify-write (acq_rel), and RMWs on one variable are totally ordered, so
// either the notifier sees the waiter or the waiter's RMW synchronises with the notifier's
// and it sees the published work. (Standalone fences would do as well but ThreadSanitizer
// cannot check them.) notify_all() costs one uncontended locked RMW when nobody waits
// (~5–10 ns; the line stays with the notifier until a consumer goes to sleep); with a waiter
// it adds an increment and a futex wake syscall (a few µs). Waking a sleeping thread takes
// the scheduler's wake-up latency (typically 5–50 µs on an idle host).
//
// Thread-safety: every member may be called from any thread. Linux only (futex).
#pragma once

#include <atomic>
#include <cstdint>

namespace mocap {

class EventCount {
public:
    using Key = std::uint32_t;

    EventCount() = default;
    EventCount(const EventCount&) = delete;
    EventCount& operator=(const EventCount&) = delete;

    /// Registers the caller as a waiter; re-check the wait condition after this.
    [[nodiscard]] Key prepare_wait() noexcept {
        waiters_.fetch_add(1, std::memory_order_acq_rel);
        return epoch_.load(std::memory_order_acquire);
    }

    /// Withdraws after prepare_wait() when the condition turned out true.
    void cancel_wait() noexcept { waiters_.fetch_sub(1, std::memory_order_acq_rel); }

    /// Sleeps until a notify after prepare_wait() (returns at once if one already happened).
    void wait(Key key) noexcept;

    /// Like wait() but sleeps at most once, for at most timeout_us (<= 0: does not sleep).
    /// Returns true if a notify happened since prepare_wait(). It may return early (signal,
    /// spurious wake-up) without a notify: callers re-check their condition and their clock.
    bool wait_for(Key key, std::int64_t timeout_us) noexcept;

    /// Wakes every thread between prepare_wait() and the end of its wait.
    void notify_all() noexcept {
        // An RMW, not a load: it is ordered against prepare_wait's increment (see above).
        if (waiters_.fetch_add(0, std::memory_order_acq_rel) != 0) wake_all();
    }

private:
    void wake_all() noexcept;

    std::atomic<std::uint32_t> epoch_{0};    // futex word: bumped by every effective notify
    std::atomic<std::uint32_t> waiters_{0};  // threads between prepare_wait and wake-up
};

}  // namespace mocap
