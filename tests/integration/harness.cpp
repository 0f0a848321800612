#include "harness.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <signal.h>
#include <spawn.h>
#include <sys/mount.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <array>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <mutex>
#include <random>
#include <set>
#include <sstream>
#include <stdexcept>
#include <thread>

extern char** environ;

namespace mocap::itest {

namespace fs = std::filesystem;

TempDir::TempDir() {
    std::random_device rd;
    path_ = fs::temp_directory_path() / ("mocapd-itest-" + std::to_string(::getpid()) + "-" + std::to_string(rd()));
    fs::create_directories(path_);
}

TempDir::~TempDir() {
    std::error_code ec;
    if (std::getenv("MOCAP_KEEP_TEST_DIRS") == nullptr) fs::remove_all(path_, ec);
}

Process::Process(std::vector<std::string> argv, const std::string& log_path, const std::string& cwd)
    : log_path_(log_path) {
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, log_path.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
    if (!cwd.empty()) posix_spawn_file_actions_addchdir_np(&fa, cwd.c_str());
    std::vector<char*> args;
    for (auto& a : argv)
        args.push_back(a.data());
    args.push_back(nullptr);
    const int rc = posix_spawn(&pid_, args[0], &fa, nullptr, args.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    if (rc != 0) throw std::runtime_error("cannot start " + argv[0]);
}

Process::~Process() {
    if (pid_ > 0 && !status_) stop(std::chrono::seconds(2));
}

bool Process::running() {
    if (status_) return false;
    int st = 0;
    const pid_t r = ::waitpid(pid_, &st, WNOHANG);
    if (r == pid_) {
        status_ = WIFEXITED(st) ? WEXITSTATUS(st) : -WTERMSIG(st);
        return false;
    }
    return true;
}

std::optional<int> Process::wait(std::chrono::milliseconds limit) {
    const auto end = std::chrono::steady_clock::now() + limit;
    while (running()) {
        if (std::chrono::steady_clock::now() >= end) return std::nullopt;
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return status_;
}

void Process::signal(int sig) {
    if (running()) ::kill(pid_, sig);
}

int Process::stop(std::chrono::milliseconds grace) {
    signal(SIGTERM);
    if (auto s = wait(grace)) return *s;
    signal(SIGKILL);
    return wait(std::chrono::seconds(5)).value_or(-SIGKILL);
}

std::string Process::log() const {
    return read_file(log_path_);
}

std::string WebDaemon::config(const std::string& dir, const std::string& token) const {
    std::ostringstream cfg;
    cfg << "[log]\nstats_interval_s = 0\n"
        << "[ingest]\nsink_listen = \"127.0.0.1:" << sink_port << "\"\n"
        << "[pipeline]\nworkers = 2\nmax_subjects = 2\n"
        << "[skeleton]\ncalibration_dir = \"" << dir << "\"\n"
        << "[serve]\npose_listen = \"127.0.0.1:" << pose_port << "\"\n"
        << "[control]\ntoken = \"" << token << "\"\n"
        << "[outputs]\nbvh_live = false\nrecord_dir = \"" << dir << "\"\n"
        << "[http]\nlisten = \"127.0.0.1:" << http_port << "\"\n";
    return cfg.str();
}

std::vector<std::string> WebDaemon::walk_sim(const std::string& sim_bin, int duration_s) const {
    return {sim_bin,      "stream",
            "--connect",  "127.0.0.1:" + std::to_string(sink_port),
            "--subjects", "1",
            "--nodes",    "15",
            "--rate",     "100",
            "--motion",   "walk",
            "--duration", std::to_string(duration_s)};
}

std::uint16_t free_port() {
    static std::mutex mutex;
    static std::set<std::uint16_t> handed_out;
    const std::lock_guard lock(mutex);
    for (int attempt = 0; attempt < 1000; ++attempt) {
        const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        a.sin_port = 0;
        socklen_t len = sizeof a;
        const bool bound = ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
                           ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0;
        ::close(fd);
        if (!bound) break;
        if (handed_out.insert(ntohs(a.sin_port)).second) return ntohs(a.sin_port);
    }
    throw std::runtime_error("no free port");
}

void stop_daemon_at_teardown(Process* daemon, Process* sim) {
    if (sim != nullptr) sim->stop();
    if (daemon == nullptr) return;
    if (::testing::Test::HasFailure()) std::cerr << "--- mocapd log ---\n" << daemon->log();
    EXPECT_EQ(daemon->stop(std::chrono::seconds(10)), 0) << "mocapd must drain and exit 0 on SIGTERM";
}

bool wait_for_port(std::uint16_t port, std::chrono::milliseconds limit) {
    const auto end = std::chrono::steady_clock::now() + limit;
    while (std::chrono::steady_clock::now() < end) {
        const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        a.sin_port = htons(port);
        const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
        ::close(fd);
        if (ok) return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return false;
}

void write_file(const std::string& path, const std::string& text) {
    std::ofstream out(path, std::ios::trunc);
    out << text;
}

std::string read_file(const std::string& path) {
    std::ifstream in(path);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

std::size_t count_lines(const std::string& text, const std::string& needle) {
    std::size_t n = 0;
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);)
        n += line.find(needle) != std::string::npos ? 1 : 0;
    return n;
}

std::optional<std::uint64_t> sim_syncs_skipped(const std::string& sim_output) {
    const std::string key = "\"syncs_skipped\":";
    const auto at = sim_output.find(key);
    if (at == std::string::npos) return std::nullopt;
    return std::stoull(sim_output.substr(at + key.size()));
}

int tcp_connect(std::uint16_t port, const std::string& host, int rcvbuf) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    if (rcvbuf > 0) ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    ::inet_pton(AF_INET, host.c_str(), &a.sin_addr);
    a.sin_port = htons(port);
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
        ::close(fd);
        return -1;
    }
    const int one = 1;
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    timeval tv{0, 200'000};
    ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    return fd;
}

bool send_all(int fd, const void* data, std::size_t n) {
    const auto* p = static_cast<const std::uint8_t*>(data);
    while (n > 0) {
        const ssize_t w = ::send(fd, p, n, MSG_NOSIGNAL);
        if (w <= 0) return false;
        p += w;
        n -= static_cast<std::size_t>(w);
    }
    return true;
}
bool send_all(int fd, const std::vector<std::uint8_t>& b) {
    return send_all(fd, b.data(), b.size());
}
bool send_all(int fd, const std::string& s) {
    return send_all(fd, s.data(), s.size());
}

unsigned http_status(int fd) {
    std::string head;
    std::array<char, 512> buf{};
    for (int i = 0; i < 50 && head.find("\r\n") == std::string::npos; ++i) {
        const ssize_t r = ::recv(fd, buf.data(), buf.size(), 0);
        if (r == 0) break;
        if (r > 0) head.append(buf.data(), static_cast<std::size_t>(r));
    }
    const auto sp = head.find(' ');
    return sp == std::string::npos ? 0u : static_cast<unsigned>(std::atoi(head.c_str() + sp + 1));
}

bool closed_by_peer(int fd, std::chrono::milliseconds limit) {
    const auto end = std::chrono::steady_clock::now() + limit;
    std::array<char, 4096> buf{};
    while (std::chrono::steady_clock::now() < end) {
        const ssize_t r = ::recv(fd, buf.data(), buf.size(), 0);
        if (r == 0) return true;
        if (r < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) return true;
    }
    return false;
}

std::vector<std::uint64_t> csv_syncs(const std::string& text) {
    std::vector<std::uint64_t> syncs;
    std::istringstream lines(text);
    std::string line;
    std::getline(lines, line);  // header
    while (std::getline(lines, line)) {
        const auto a = line.find(',');
        const auto b = line.find(',', a + 1);
        syncs.push_back(std::stoull(line.substr(a + 1, b - a - 1)));
    }
    return syncs;
}

std::uintmax_t take_raw_bytes(const std::filesystem::path& dir) {
    std::uintmax_t n = 0;
    std::error_code ec;
    for (const auto& f : std::filesystem::directory_iterator(dir, ec)) {
        if (f.path().extension() == ".mocapraw") n += f.file_size(ec);
    }
    return n;
}

TmpfsMount::TmpfsMount(const std::string& path, const std::string& size) : path_(path) {
    std::filesystem::create_directories(path);
    const std::string options = "size=" + size + ",mode=0755";
    if (::mount("tmpfs", path.c_str(), "tmpfs", 0, options.c_str()) != 0) {
        error_ = std::string("mount tmpfs: ") + std::strerror(errno);
    } else {
        mounted_ = true;
    }
}

TmpfsMount::~TmpfsMount() {
    if (mounted_) ::umount2(path_.c_str(), MNT_DETACH);
}

bool TmpfsMount::resize(const std::string& size) {
    const std::string options = "size=" + size;
    return ::mount("tmpfs", path_.c_str(), "tmpfs", MS_REMOUNT, options.c_str()) == 0;
}

}  // namespace mocap::itest
