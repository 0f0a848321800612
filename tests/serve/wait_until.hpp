// wait_until.hpp — the serve tests' one bounded poll: true as soon as `pred` holds, false
// once `limit` has passed without it (generous: a sanitizer build on a loaded machine is
// slow, and the limit only matters when the test fails). Sleeps 1 ms between polls.
#pragma once

#include <chrono>
#include <thread>

namespace mocap::serve {

template <typename Pred>
bool wait_until(Pred pred, std::chrono::milliseconds limit = std::chrono::seconds(30)) {
    const auto deadline = std::chrono::steady_clock::now() + limit;
    while (!pred()) {
        if (std::chrono::steady_clock::now() > deadline) return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    return true;
}

}  // namespace mocap::serve
