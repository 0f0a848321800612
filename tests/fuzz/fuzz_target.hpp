// fuzz_target.hpp — what every fuzz target shares: the entry point and a check that aborts.
//
// A target is one file defining MOCAP_FUZZ_ENTRY(name) { ... }. Built for libFuzzer
// (clang, -fsanitize=fuzzer) it is LLVMFuzzerTestOneInput; built with MOCAP_FUZZ_REPLAY
// (the normal g++ test build) it is mocap_fuzz_<name>(), which fuzz_replay_test.cpp
// calls on every committed seed and regression input. Checks abort with a message, so
// libFuzzer saves the input as a crash and the replay test fails loudly.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

#define MOCAP_FUZZ_CHECK(cond, what)                                                                        \
    do {                                                                                                    \
        if (!(cond)) {                                                                                      \
            std::fprintf(stderr, "fuzz check failed at %s:%d: %s (%s)\n", __FILE__, __LINE__, #cond, what); \
            std::abort();                                                                                   \
        }                                                                                                   \
    } while (0)

#ifdef MOCAP_FUZZ_REPLAY
#define MOCAP_FUZZ_ENTRY(name) int mocap_fuzz_##name(const std::uint8_t* data, std::size_t size)
#else
#define MOCAP_FUZZ_ENTRY(name) extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
#endif

namespace mocap::fuzz {

/// Takes bytes off the front of the input; past the end it yields zeros.
class ByteReader {
public:
    ByteReader(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
    [[nodiscard]] bool empty() const { return pos_ >= size_; }
    [[nodiscard]] std::size_t remaining() const { return size_ - pos_; }
    std::uint8_t u8() { return pos_ < size_ ? data_[pos_++] : 0; }
    std::uint16_t u16() {
        const std::uint16_t lo = u8();
        return static_cast<std::uint16_t>(lo | (u8() << 8));
    }
    /// Up to n bytes; returns the pointer and sets n to what was available.
    const std::uint8_t* take(std::size_t& n) {
        if (n > remaining()) n = remaining();
        const std::uint8_t* p = data_ + pos_;
        pos_ += n;
        return p;
    }

private:
    const std::uint8_t* data_;
    std::size_t size_;
    std::size_t pos_ = 0;
};

}  // namespace mocap::fuzz
