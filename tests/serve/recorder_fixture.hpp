// recorder_fixture.hpp — shared helpers of the file recorder tests: a scratch directory,
// a clock the test sets, distinct known samples, and a FileWriter that fills up.
#pragma once

#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "core/clock.hpp"
#include "core/frame.hpp"
#include "serve/record_file.hpp"

namespace mocap::serve::test {

namespace fs = std::filesystem;

struct TempDir {
    fs::path path;
    TempDir() {
        char tmpl[] = "/tmp/mocap-bvhrec-XXXXXX";
        path = ::mkdtemp(tmpl);
    }
    ~TempDir() { fs::remove_all(path); }
    [[nodiscard]] std::string file(const char* name) const { return (path / name).string(); }
};

class StepClock final : public Clock {
public:
    [[nodiscard]] std::int64_t now_us() const noexcept override { return now.load(); }
    std::atomic<std::int64_t> now{1'700'000'000'000'000};
};

inline SegmentSample sample(std::uint64_t k, bool quat) {
    SegmentSample s;
    s.subject_id = 2;
    s.node_id = static_cast<std::uint8_t>(1 + k % 15);
    s.sync = 1000 + k / 15;
    s.imu.t_us = static_cast<std::int64_t>(k) * 667;
    s.imu.flags = static_cast<std::uint8_t>(k % 3);
    s.imu.gyro_rad_s = {0.25f * static_cast<float>(k), -1.5f, 3.0f};
    s.imu.accel_m_s2 = {0.1f, 9.81f, -0.3f};
    s.imu.mag_ut = {20.5f, -3.25f, static_cast<float>(k)};
    if (quat) {
        s.has_node_quat = true;
        s.node_q_wxyz = {0.5, 0.5, -0.5, 0.5};
    }
    s.times.sink_send_us = 5 + static_cast<std::int64_t>(k);
    s.times.received_us = 9 + static_cast<std::int64_t>(k);
    return s;
}

inline void expect_same(const SegmentSample& a, const SegmentSample& b) {
    EXPECT_EQ(a.subject_id, b.subject_id);
    EXPECT_EQ(a.node_id, b.node_id);
    EXPECT_EQ(a.sync, b.sync);
    EXPECT_EQ(a.imu.t_us, b.imu.t_us);
    EXPECT_EQ(a.imu.flags, b.imu.flags);
    EXPECT_EQ(a.has_node_quat, b.has_node_quat);
    if (a.has_node_quat) {
        EXPECT_EQ(a.node_q_wxyz, b.node_q_wxyz);
    } else {
        EXPECT_EQ(a.imu.gyro_rad_s, b.imu.gyro_rad_s);  // float32 values: exact
        EXPECT_EQ(a.imu.accel_m_s2, b.imu.accel_m_s2);
        EXPECT_EQ(a.imu.mag_ut, b.imu.mag_ut);
    }
    EXPECT_EQ(a.times.sink_send_us, b.times.sink_send_us);
    EXPECT_EQ(a.times.received_us, b.times.received_us);
}

inline std::vector<std::string> raw_files(const fs::path& dir) {
    std::vector<std::string> out;
    for (const auto& e : fs::directory_iterator(dir))
        out.push_back(e.path().string());
    std::sort(out.begin(), out.end());
    return out;
}

/// A disk that holds `capacity` bytes in the files written through it: a write beyond that
/// writes what fits (a short write) and the next call fails with ENOSPC, as a filling disk
/// does. Truncation frees the space again. `max_chunk` makes every write short.
class FillingDisk final : public FileWriter {
public:
    ssize_t pwrite(int fd, const void* data, std::size_t n, off_t offset) override {
        while (hold.load())  // the test is still publishing: the writer waits here
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
        const auto cap = static_cast<off_t>(capacity.load());
        if (offset >= cap) {
            full_hits.fetch_add(1);
            errno = ENOSPC;
            return -1;
        }
        n = std::min<std::size_t>({n, static_cast<std::size_t>(cap - offset), max_chunk.load()});
        return ::pwrite(fd, data, n, offset);
    }
    int ftruncate(int fd, off_t length) override {
        truncations.fetch_add(1);
        return ::ftruncate(fd, length);
    }
    void free_space() { capacity = std::numeric_limits<std::int64_t>::max(); }

    std::atomic<std::int64_t> capacity{std::numeric_limits<std::int64_t>::max()};
    std::atomic<std::size_t> max_chunk{std::numeric_limits<std::size_t>::max()};
    /// While true every write waits: frames published meanwhile all reach the recorder
    /// before its writer can fail, however slowly the machine runs.
    std::atomic<bool> hold{false};
    std::atomic<int> full_hits{0};
    std::atomic<int> truncations{0};
};

}  // namespace mocap::serve::test
