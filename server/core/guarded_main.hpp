#pragma once
// The body of a program's main() with a last-resort handler.
//
// An exception that leaves main() ends the program through std::terminate (an abort, maybe a
// core dump, and no message a user can act on). Every executable's main() runs its body
// through guarded_main, so such an exception becomes one line on stderr and exit status 1.
// Expected errors are still handled, and reported, where they happen.

#include <cstdio>
#include <exception>

namespace mocap {

/// Returns body()'s exit status, or 1 after printing "<program>: <what>" if it throws.
template <class Body>
int guarded_main(const char* program, Body&& body) noexcept {
    try {
        return body();
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s: %s\n", program, e.what());
    } catch (...) {
        std::fprintf(stderr, "%s: unknown exception\n", program);
    }
    return 1;
}

}  // namespace mocap
