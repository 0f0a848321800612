// mocap-sim stream against the real mocapd, read back through mocap-client: both subjects'
// frames arrive with all 15 segments filled from live samples. MOCAPD_BIN, MOCAP_SIM_BIN and
// MOCAP_CLIENT_BIN are the built executables (tests/clients/CMakeLists.txt).
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace {

namespace fs = std::filesystem;

// A port the OS just handed out (bound to 0, then released). The daemon's config cannot take
// port 0, so a race with another process is possible but unlikely; SetUp retries once.
int free_port() {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = 0;
    socklen_t len = sizeof a;
    if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 ||
        ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) != 0) {
        if (fd >= 0) ::close(fd);
        return -1;
    }
    ::close(fd);
    return ntohs(a.sin_port);
}

bool accepts(int port) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
    ::close(fd);
    return ok;
}

pid_t spawn(const std::vector<std::string>& argv, const fs::path& out, const fs::path& err) {
    const pid_t pid = ::fork();
    if (pid == 0) {
        std::FILE* o = std::freopen(out.c_str(), "w", stdout);
        std::FILE* e = std::freopen(err.c_str(), "w", stderr);
        (void)o;
        (void)e;
        std::vector<char*> args;
        for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
        args.push_back(nullptr);
        ::execv(args[0], args.data());
        std::_Exit(127);
    }
    return pid;
}

int wait_exit(pid_t pid) {
    int status = 0;
    ::waitpid(pid, &status, 0);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string slurp(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

class StreamEndToEnd : public ::testing::Test {
protected:
    void SetUp() override {
        dir_ = fs::temp_directory_path() / ("mocap_stream_e2e_" + std::to_string(::getpid()));
        fs::create_directories(dir_);
        for (int attempt = 0; attempt < 3 && daemon_ < 0; ++attempt) start_daemon();
        ASSERT_GT(daemon_, 0) << slurp(dir_ / "mocapd.err");
    }
    void TearDown() override {
        if (daemon_ > 0) {
            ::kill(daemon_, SIGTERM);
            wait_exit(daemon_);
        }
        fs::remove_all(dir_);
    }

    void start_daemon() {
        sink_port_ = free_port();
        pose_port_ = free_port();
        const int bvh_port = free_port();
        if (sink_port_ <= 0 || pose_port_ <= 0 || bvh_port <= 0 || sink_port_ == pose_port_ ||
            bvh_port == sink_port_ || bvh_port == pose_port_) {
            return;
        }
        std::ofstream(dir_ / "mocapd.toml") << "[log]\nlevel = \"warn\"\n"
                                            << "[ingest]\nsink_listen = \"127.0.0.1:" << sink_port_ << "\"\n"
                                            << "[serve]\npose_listen = \"127.0.0.1:" << pose_port_ << "\"\n"
                                            << "[skeleton]\ncalibration_dir = \"" << dir_.string() << "\"\n"
                                            << "[outputs]\nbvh_listen = \"127.0.0.1:" << bvh_port << "\"\n";
        const pid_t pid = spawn({MOCAPD_BIN, "--config", (dir_ / "mocapd.toml").string()}, dir_ / "mocapd.out",
                                dir_ / "mocapd.err");
        for (int i = 0; i < 100; ++i) {
            if (accepts(pose_port_) && accepts(sink_port_)) {
                daemon_ = pid;
                return;
            }
            int status = 0;
            if (::waitpid(pid, &status, WNOHANG) == pid) return;  // exited (port taken?): retry
            std::this_thread::sleep_for(std::chrono::milliseconds(100));
        }
        ::kill(pid, SIGKILL);
        wait_exit(pid);
    }

    fs::path dir_;
    int sink_port_ = -1, pose_port_ = -1;
    pid_t daemon_ = -1;
};

TEST_F(StreamEndToEnd, TwoSubjectsArriveWithAllFifteenSegments) {
    const pid_t sim = spawn({MOCAP_SIM_BIN, "stream", "--connect", "127.0.0.1:" + std::to_string(sink_port_),
                             "--subjects", "2", "--duration", "3", "--sink-rate-stats"},
                            dir_ / "sim.out", dir_ / "sim.err");
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    const pid_t client = spawn({MOCAP_CLIENT_BIN, "--connect", "127.0.0.1:" + std::to_string(pose_port_), "cat",
                                "--frames", "200", "--json"},
                               dir_ / "client.out", dir_ / "client.err");
    const int client_rc = wait_exit(client);
    const int sim_rc = wait_exit(sim);
    EXPECT_EQ(sim_rc, 0) << slurp(dir_ / "sim.err");
    EXPECT_EQ(client_rc, 0) << slurp(dir_ / "client.err");

    // Every frame line: its subject, its segment count, and whether all segments were live.
    std::map<int, int> frames, live_frames;
    std::istringstream lines(slurp(dir_ / "client.out"));
    const std::regex subject_re("^\\{\"subject\":(\\d+)");
    const std::regex flags_re("\"flags\":(\\d+)");
    std::string line;
    while (std::getline(lines, line)) {
        std::smatch m;
        ASSERT_TRUE(std::regex_search(line, m, subject_re)) << line.substr(0, 200);
        const int subject = std::stoi(m[1]);
        int segments = 0, stale = 0;
        for (auto it = std::sregex_iterator(line.begin(), line.end(), flags_re); it != std::sregex_iterator(); ++it) {
            ++segments;
            stale += (std::stoi((*it)[1]) & 3) != 0 ? 1 : 0;  // SEGMENT_STALE | SEGMENT_NEVER_SEEN
        }
        EXPECT_EQ(segments, 15) << line.substr(0, 200);
        ++frames[subject];
        live_frames[subject] += stale == 0 ? 1 : 0;
    }
    EXPECT_EQ(frames.size(), 2u);
    for (int subject : {1, 2}) {
        EXPECT_GT(frames[subject], 20) << "subject " << subject;
        EXPECT_GT(live_frames[subject], frames[subject] / 2) << "subject " << subject;
    }
    const std::string stats = slurp(dir_ / "sim.out");
    EXPECT_NE(stats.find("\"subjects\":2"), std::string::npos) << stats;
    EXPECT_NE(stats.find("\"connects\":1"), std::string::npos) << stats;
}

TEST_F(StreamEndToEnd, APeerThatNeverAcceptsEndsAtTheDuration) {
    const int closed_port = free_port();
    const auto t0 = std::chrono::steady_clock::now();
    const pid_t sim = spawn({MOCAP_SIM_BIN, "stream", "--connect", "127.0.0.1:" + std::to_string(closed_port),
                             "--duration", "1.5", "--sink-rate-stats"},
                            dir_ / "sim.out", dir_ / "sim.err");
    const int rc = wait_exit(sim);
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_EQ(rc, 1) << "never connected";
    EXPECT_LT(elapsed, 4.0);
    EXPECT_GE(elapsed, 1.4);
    EXPECT_NE(slurp(dir_ / "sim.err").find("never connected"), std::string::npos);
    const std::string stats = slurp(dir_ / "sim.out");
    EXPECT_NE(stats.find("\"packets\":0"), std::string::npos) << stats;
}

}  // namespace
