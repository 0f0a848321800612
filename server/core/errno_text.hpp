#pragma once
// errno as text, safe on any thread.
//
// std::strerror may return one buffer shared by all threads, and libstdc++'s
// std::system_category().message() calls it; the daemon reports I/O errors from its serve and
// ingest threads. The GNU strerror_r writes into the caller's buffer or returns a static
// string. Cost: one libc call and one std::string.

#include <cstring>
#include <string>

namespace mocap {

/// The message for error number `err` (pass errno right after the failing call).
inline std::string errno_text(int err) {
    char buf[128];
    return ::strerror_r(err, buf, sizeof buf);
}

}  // namespace mocap
