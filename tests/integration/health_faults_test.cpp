// /healthz and the systemd watchdog while one thread of the real mocapd is frozen alone
// (issue 24, item 7; docs/reliability.md, "A thread frozen alone"). The test stops one
// thread of the daemon with ptrace (PTRACE_SEIZE + PTRACE_INTERRUPT on its thread id: a
// signal would stop the whole process), and requires /healthz to answer 503 naming that
// thread and the watchdog pings to stop; released, /healthz is 200 and the pings resume.
// The watchdog is systemd's protocol on a datagram socket of the test (NOTIFY_SOCKET,
// WATCHDOG_USEC), as the service manager would run it.
#include <sys/ptrace.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <array>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <utility>

#include "harness.hpp"
#include "http_test_client.hpp"

namespace mocap::itest {
namespace {

using namespace std::chrono_literals;
using mocap::testing::http_request;

/// The id of the thread of process `pid` named `name` (/proc/PID/task/TID/comm), or -1.
pid_t thread_named(pid_t pid, const std::string& name) {
    std::error_code ec;
    for (const auto& t : std::filesystem::directory_iterator("/proc/" + std::to_string(pid) + "/task", ec)) {
        std::string comm = read_file((t.path() / "comm").string());
        while (!comm.empty() && comm.back() == '\n')
            comm.pop_back();
        if (comm == name) return static_cast<pid_t>(std::stol(t.path().filename().string()));
    }
    return -1;
}

/// One thread stopped by ptrace while this lives; detached (and so resumed) on release().
class FrozenThread {
public:
    explicit FrozenThread(pid_t tid) : tid_(tid) {
        if (::ptrace(PTRACE_SEIZE, tid_, nullptr, nullptr) != 0) {
            error_ = std::string("PTRACE_SEIZE: ") + std::strerror(errno);
            return;
        }
        attached_ = true;
        int status = 0;
        if (::ptrace(PTRACE_INTERRUPT, tid_, nullptr, nullptr) != 0 || ::waitpid(tid_, &status, __WALL) != tid_) {
            error_ = std::string("PTRACE_INTERRUPT: ") + std::strerror(errno);
        }
    }
    ~FrozenThread() { release(); }
    FrozenThread(const FrozenThread&) = delete;
    FrozenThread& operator=(const FrozenThread&) = delete;
    [[nodiscard]] const std::string& error() const { return error_; }
    void release() {
        if (attached_) ::ptrace(PTRACE_DETACH, tid_, nullptr, nullptr);
        attached_ = false;
    }

private:
    pid_t tid_;
    bool attached_ = false;
    std::string error_;
};

/// The service manager's end of sd_notify: a datagram socket at `path`.
class NotifySocket {
public:
    explicit NotifySocket(const std::string& path) {
        fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
        sockaddr_un a{};
        a.sun_family = AF_UNIX;
        std::strncpy(a.sun_path, path.c_str(), sizeof a.sun_path - 1);
        ok_ = fd_ >= 0 && ::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
    }
    ~NotifySocket() {
        if (fd_ >= 0) ::close(fd_);
    }
    NotifySocket(const NotifySocket&) = delete;
    NotifySocket& operator=(const NotifySocket&) = delete;
    [[nodiscard]] bool ok() const { return ok_; }
    /// WATCHDOG=1 messages that arrived by now (reads what is queued, never waits).
    int pings() {
        int n = 0;
        std::array<char, 512> buf{};
        for (;;) {
            const ssize_t r = ::recv(fd_, buf.data(), buf.size(), MSG_DONTWAIT);
            if (r <= 0) return n;
            n += std::string(buf.data(), static_cast<std::size_t>(r)).find("WATCHDOG=1") != std::string::npos ? 1 : 0;
        }
    }

private:
    int fd_ = -1;
    bool ok_ = false;
};

class HealthFaults : public ::testing::Test {
protected:
    void TearDown() override { stop_daemon_at_teardown(daemon_.get(), sim_.get()); }

    TempDir dir_;
    WebDaemon ports_;
    std::unique_ptr<Process> daemon_;
    std::unique_ptr<Process> sim_;
};

// Each thread that must make progress, frozen alone while a subject streams: /healthz names
// it within a few seconds and the watchdog pings stop; released, both recover. Before,
// /healthz stayed 200 "ok" (the ingest thread, the pose serve thread or a worker frozen for
// 5 s: 0 frames, half the segments stale) and the watchdog kept being pinged.
TEST_F(HealthFaults, AThreadFrozenAloneMakesHealthzNameItAndWithholdsTheWatchdog) {
    NotifySocket notify(dir_.file("notify.sock"));
    ASSERT_TRUE(notify.ok()) << std::strerror(errno);
    write_file(dir_.file("mocapd.toml"), ports_.config(dir_.path().string(), "health-faults-0123456789"));
    ::setenv("NOTIFY_SOCKET", dir_.file("notify.sock").c_str(), 1);
    ::setenv("WATCHDOG_USEC", "400000", 1);  // a ping every 100 ms or so
    daemon_ = std::make_unique<Process>(std::vector<std::string>{MOCAPD_BIN, "--config", dir_.file("mocapd.toml")},
                                        dir_.file("mocapd.log"), dir_.path().string());
    ::unsetenv("NOTIFY_SOCKET");
    ::unsetenv("WATCHDOG_USEC");
    ASSERT_TRUE(wait_for_port(ports_.http_port, 30s)) << daemon_->log();
    ASSERT_TRUE(wait_for_port(ports_.sink_port, 30s)) << daemon_->log();
    sim_ = std::make_unique<Process>(ports_.walk_sim(MOCAP_SIM_BIN, 300), dir_.file("sim.log"));
    // Every look at /healthz also reads the pings queued so far: the kernel queues at most
    // 10 datagrams on a Unix socket (net.unix.max_dgram_qlen), and a full queue would block
    // the daemon's sd_notify() until the test reads, as a hung service manager would.
    int pings_seen = 0;
    const auto healthz = [&] {
        pings_seen += notify.pings();
        return http_request(ports_.http_port, "/healthz");
    };
    const auto new_pings = [&] {
        pings_seen += notify.pings();
        return std::exchange(pings_seen, 0);
    };
    ASSERT_TRUE(wait_until([&] { return healthz().body == "ok\n"; }, 60s)) << healthz().body;
    ASSERT_TRUE(wait_until([&] { return new_pings() > 0; }, 30s)) << "the watchdog is pinged";

    const std::pair<const char*, const char*> parts[] = {
        {"mocap-ingest", "ingest thread"},
        {"mocap-worker-0", "worker 0"},
        {"mocap-serve-0", "pose serve thread 0"},
    };
    for (const auto& [thread, part] : parts) {
        SCOPED_TRACE(part);
        const pid_t tid = thread_named(daemon_->pid(), thread);
        ASSERT_GT(tid, 0) << "no thread named " << thread;
        const std::size_t withheld_before = count_lines(daemon_->log(), "watchdog: not pinging systemd");
        const auto t0 = std::chrono::steady_clock::now();
        FrozenThread frozen(tid);
        if (frozen.error().find("PTRACE_SEIZE") == 0) GTEST_SKIP() << "cannot ptrace here: " << frozen.error();
        ASSERT_TRUE(frozen.error().empty()) << frozen.error();
        mocap::testing::HttpReply reply;
        ASSERT_TRUE(wait_until(
            [&] {
                reply = healthz();
                return reply.status == 503;
            },
            30s))
            << "still " << reply.status << " " << reply.body;
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::cout << "[ metrics  ] " << part << " frozen: /healthz 503 after " << seconds << " s: " << reply.body;
        EXPECT_NE(reply.body.find(part), std::string::npos) << reply.body;
        // The watchdog hook decides on its own thread: once it has said that it withholds the
        // ping, every ping it decided before is queued (one it decided just before the monitor
        // called the thread stale may arrive late on a loaded machine), and none follows.
        ASSERT_TRUE(wait_until(
            [&] { return count_lines(daemon_->log(), "watchdog: not pinging systemd") > withheld_before; }, 30s))
            << daemon_->log();
        new_pings();
        EXPECT_EQ(healthz().status, 503u);
        EXPECT_EQ(new_pings(), 0) << "the watchdog must not be pinged while " << part << " is frozen";

        frozen.release();
        ASSERT_TRUE(wait_until([&] { return healthz().body == "ok\n"; }, 30s)) << healthz().body;
        ASSERT_TRUE(wait_until([&] { return new_pings() > 0; }, 30s)) << "pings resume";
    }
    EXPECT_GE(count_lines(daemon_->log(), "watchdog: not pinging systemd"), 1u) << "said once per episode";
}

}  // namespace
}  // namespace mocap::itest
