// harness.hpp — integration-test helpers: run the real binaries on loopback.
//
// Process: posix_spawn with stdout/stderr to a log file; stop() sends SIGTERM and waits
// (bounded), then SIGKILL. free_port(): a port the kernel just handed out (bound to 0 and
// released), so parallel test runs do not collide, and never one it already returned in this
// process (the kernel may hand the same free port out twice in a row, and a daemon given one
// port for two listeners refuses its config). TempDir: removed on destruction.
// stop_daemon_at_teardown(): the TearDown of every fixture that runs mocapd.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace mocap::itest {

class TempDir {
public:
    TempDir();
    ~TempDir();
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    [[nodiscard]] const std::filesystem::path& path() const { return path_; }
    [[nodiscard]] std::string file(const std::string& name) const { return (path_ / name).string(); }

private:
    std::filesystem::path path_;
};

class Process {
public:
    Process(std::vector<std::string> argv, const std::string& log_path, const std::string& cwd = "");
    ~Process();
    Process(const Process&) = delete;
    Process& operator=(const Process&) = delete;

    [[nodiscard]] bool running();
    /// Waits up to `limit` for the process to exit; returns its exit status if it did.
    std::optional<int> wait(std::chrono::milliseconds limit);
    /// SIGTERM, wait up to `grace`, then SIGKILL. Returns the exit status (or -signal).
    int stop(std::chrono::milliseconds grace = std::chrono::seconds(5));
    void signal(int sig);
    [[nodiscard]] pid_t pid() const { return pid_; }
    [[nodiscard]] std::string log() const;

private:
    pid_t pid_ = -1;
    std::string log_path_;
    std::optional<int> status_;
};

std::uint16_t free_port();

/// The TearDown of a fixture that ran mocapd: stops `sim` if there is one; then, if mocapd was
/// started, prints its log when the test failed and requires (a test failure otherwise) that
/// it drain and exit 0 on SIGTERM within 10 s.
void stop_daemon_at_teardown(Process* daemon, Process* sim = nullptr);

/// A mocapd on loopback with sinks, the pose service and the web endpoint (live BVH off),
/// control by `token`, calibrations and recordings in `dir`; the ports are free_port()s.
struct WebDaemon {
    std::uint16_t sink_port = free_port();
    std::uint16_t pose_port = free_port();
    std::uint16_t http_port = free_port();
    /// The config file's text.
    [[nodiscard]] std::string config(const std::string& dir, const std::string& token) const;
    /// mocap-sim's arguments: one subject of 15 nodes at 100 Hz walking for `duration_s`.
    [[nodiscard]] std::vector<std::string> walk_sim(const std::string& sim_bin, int duration_s) const;
};
/// The SYNC column (second) of a joint-angle CSV (`mocapd --replay ... --angles-out`), in
/// row order.
std::vector<std::uint64_t> csv_syncs(const std::string& text);
/// Polls `done` every 20 ms until it holds or `limit` passes: the integration tests' one
/// bounded wait on an event (never a bare sleep).
template <typename Done>
bool wait_until(Done done, std::chrono::milliseconds limit) {
    const auto end = std::chrono::steady_clock::now() + limit;
    while (std::chrono::steady_clock::now() < end) {
        if (done()) return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return done();
}

/// True once something accepts TCP connections on 127.0.0.1:port (polls until `limit`).
bool wait_for_port(std::uint16_t port, std::chrono::milliseconds limit);
void write_file(const std::string& path, const std::string& text);
std::string read_file(const std::string& path);
/// Lines of `text` that contain `needle`.
std::size_t count_lines(const std::string& text, const std::string& needle);
/// SYNCs `mocap-sim stream --sink-rate-stats` skipped because the simulator itself ran late
/// (read from its output): those instants never existed, so a client's gaps may be up to
/// this. nullopt when the output has no stats line.
std::optional<std::uint64_t> sim_syncs_skipped(const std::string& sim_output);

// Raw TCP sockets, for clients that misbehave on purpose.

/// Blocking connect with a 200 ms receive timeout; rcvbuf > 0 shrinks the receive buffer
/// before the handshake (a client that reads nothing then fills up quickly). -1 on failure.
int tcp_connect(std::uint16_t port, const std::string& host = "127.0.0.1", int rcvbuf = 0);
bool send_all(int fd, const void* data, std::size_t n);
bool send_all(int fd, const std::string& s);
bool send_all(int fd, const std::vector<std::uint8_t>& b);
/// The status code of the HTTP reply read from `fd` (a request was sent on it; 0 = none
/// came). Reads only up to the status line, so a WebSocket can be used after a 101.
unsigned http_status(int fd);
/// True once the peer has closed the connection (EOF or reset), reading and discarding
/// whatever it sends, within `limit`.
bool closed_by_peer(int fd, std::chrono::milliseconds limit);

/// Bytes in the raw file(s) (*.mocapraw) of a take directory (0 while there is none).
std::uintmax_t take_raw_bytes(const std::filesystem::path& dir);

/// A small tmpfs at `path` for the life of the object (needs root: mounted() says whether it
/// is): unmounted lazily, so a file still open cannot keep it, on every way out of the test.
class TmpfsMount {
public:
    TmpfsMount(const std::string& path, const std::string& size);
    ~TmpfsMount();
    TmpfsMount(const TmpfsMount&) = delete;
    TmpfsMount& operator=(const TmpfsMount&) = delete;
    [[nodiscard]] bool mounted() const { return mounted_; }
    [[nodiscard]] const std::string& error() const { return error_; }
    /// Gives the file system a new size without touching what it holds.
    bool resize(const std::string& size);

private:
    std::string path_;
    std::string error_;
    bool mounted_ = false;
};

}  // namespace mocap::itest
