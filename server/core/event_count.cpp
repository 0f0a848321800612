// event_count.cpp — the futex calls behind EventCount. A raw futex (instead of
// std::atomic::wait) because the assembler thread needs a timed wait for its deadlines.
#include "core/event_count.hpp"

#include <linux/futex.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <climits>
#include <ctime>

namespace mocap {
namespace {

static_assert(sizeof(std::atomic<std::uint32_t>) == sizeof(std::uint32_t) &&
                  std::atomic<std::uint32_t>::is_always_lock_free,
              "futex needs a plain 32-bit word");

std::uint32_t* futex_word(std::atomic<std::uint32_t>& a) noexcept {
    return reinterpret_cast<std::uint32_t*>(&a);
}

// Returns when woken, on timeout, on a signal, or at once if *word != expected.
void futex_wait(std::atomic<std::uint32_t>& word, std::uint32_t expected, const timespec* timeout) noexcept {
    syscall(SYS_futex, futex_word(word), FUTEX_WAIT_PRIVATE, expected, timeout, nullptr, 0);
}

}  // namespace

void EventCount::wait(Key key) noexcept {
    while (epoch_.load(std::memory_order_acquire) == key)
        futex_wait(epoch_, key, nullptr);
    waiters_.fetch_sub(1, std::memory_order_acq_rel);
}

bool EventCount::wait_for(Key key, std::int64_t timeout_us) noexcept {
    // One sleep at most: the caller owns time (docs/style.md, "Inject time") and loops on its own clock.
    bool notified = epoch_.load(std::memory_order_acquire) != key;
    if (!notified && timeout_us > 0) {
        const timespec rel{static_cast<time_t>(timeout_us / 1'000'000),
                           static_cast<long>((timeout_us % 1'000'000) * 1000)};
        futex_wait(epoch_, key, &rel);
        notified = epoch_.load(std::memory_order_acquire) != key;
    }
    waiters_.fetch_sub(1, std::memory_order_acq_rel);
    return notified;
}

void EventCount::wake_all() noexcept {
    epoch_.fetch_add(1, std::memory_order_release);
    syscall(SYS_futex, futex_word(epoch_), FUTEX_WAKE_PRIVATE, INT_MAX, nullptr, nullptr, 0);
}

}  // namespace mocap
