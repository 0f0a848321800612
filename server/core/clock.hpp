// clock.hpp — injected time source (docs/style.md, "Inject time").
//
// Core never reads a clock itself; the daemon passes an implementation (wall clock,
// CLOCK_REALTIME µs, so stage stamps compare with the sink's and the client's clocks) and
// tests pass a manual one. now_us() is called from pipeline threads concurrently, so an
// implementation must be thread-safe and must not block or allocate.
#pragma once

#include <cstdint>

namespace mocap {

class Clock {
public:
    virtual ~Clock() = default;
    /// Microseconds on the clock's own epoch; monotonic enough for stage differences.
    [[nodiscard]] virtual std::int64_t now_us() const noexcept = 0;
};

}  // namespace mocap
