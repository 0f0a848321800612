// wall_clock.hpp — the daemon's one clock: CLOCK_REALTIME in µs since the epoch.
//
// Wall time (not steady) so stage stamps compare with the sink's clock and a client's
// receive time on the same or a synchronised host. Only daemon/ reads a clock; everything
// below gets this injected. Thread-safe, ~20 ns (vDSO).
#pragma once

#include <time.h>

#include "core/clock.hpp"

namespace mocap::daemon {

class WallClock final : public Clock {
public:
    [[nodiscard]] std::int64_t now_us() const noexcept override {
        timespec ts{};
        clock_gettime(CLOCK_REALTIME, &ts);
        return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000 + ts.tv_nsec / 1000;
    }
};

}  // namespace mocap::daemon
