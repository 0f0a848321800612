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

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "harness.hpp"
#include "mocap_wire/mw_can.h"
#include "mocap_wire/mw_packet.h"
#include "skeleton/body_model.hpp"
#include "skeleton/joint_angles.hpp"

namespace {

namespace fs = std::filesystem;

using mocap::itest::free_port;  // never the same port twice in one process

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
        for (const auto& a : argv)
            args.push_back(const_cast<char*>(a.c_str()));
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
        for (int attempt = 0; attempt < 3 && daemon_ < 0; ++attempt)
            start_daemon();
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
        std::ofstream(dir_ / "mocapd.toml") << "[log]\nlevel = \"warn\"\n"
                                            << "[ingest]\nsink_listen = \"127.0.0.1:" << sink_port_ << "\"\n"
                                            << "[serve]\npose_listen = \"127.0.0.1:" << pose_port_ << "\"\n"
                                            << "[skeleton]\ncalibration_dir = \"" << dir_.string() << "\"\n"
                                            << "[outputs]\nbvh_listen = \"127.0.0.1:" << bvh_port << "\"\n";
        const pid_t pid =
            spawn({MOCAPD_BIN, "--config", (dir_ / "mocapd.toml").string()}, dir_ / "mocapd.out", dir_ / "mocapd.err");
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
    const pid_t client = spawn(
        {MOCAP_CLIENT_BIN, "--connect", "127.0.0.1:" + std::to_string(pose_port_), "cat", "--frames", "200", "--json"},
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

// The truth files say what went on the wire: a plain listener decodes the stream with the wire
// library, and every ATT quaternion (noiseless quat mode) equals the --truth-poses file's
// q_earth_sensor of its subject, node and counter within the ATT resolution; the --truth file
// holds, for every SYNC, the joint angles of those segment orientations under the daemon's
// sync value (2^32 + counter).
TEST_F(StreamEndToEnd, TruthFileMatchesTheFramesOnTheWire) {
    const int listener = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t len = sizeof a;
    ASSERT_EQ(::bind(listener, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    ASSERT_EQ(::getsockname(listener, reinterpret_cast<sockaddr*>(&a), &len), 0);
    ASSERT_EQ(::listen(listener, 4), 0);
    const int port = ntohs(a.sin_port);
    const fs::path truth = dir_ / "truth.csv";
    const pid_t sim = spawn({MOCAP_SIM_BIN, "stream", "--connect", "127.0.0.1:" + std::to_string(port), "--subjects",
                             "1", "--mode", "quat", "--noise-scale", "0", "--calibrate-s", "0.5", "--duration", "1.5",
                             "--truth-poses", truth.string(), "--truth", (dir_ / "angles.csv").string()},
                            dir_ / "sim.out", dir_ / "sim.err");
    const int conn = ::accept(listener, nullptr, nullptr);
    ASSERT_GE(conn, 0);
    std::vector<std::uint8_t> bytes;
    std::uint8_t buf[65536];
    for (ssize_t n; (n = ::recv(conn, buf, sizeof buf, 0)) > 0;)
        bytes.insert(bytes.end(), buf, buf + n);
    ::close(conn);
    ::close(listener);
    ASSERT_EQ(wait_exit(sim), 0) << slurp(dir_ / "sim.err");

    // (node, counter low 14 bits) -> q_earth_sensor from the truth file (1.5 s < 2^14 counters).
    std::map<std::pair<int, int>, std::array<double, 4>> expected;
    std::map<std::uint32_t, std::array<mocap::skeleton::Quat, 15>> segments;  // counter -> q_earth_segment
    std::istringstream rows(slurp(truth));
    std::string row;
    std::getline(rows, row);
    EXPECT_EQ(row,
              "t_us,subject,segment,node,counter,seg_qw,seg_qx,seg_qy,seg_qz,sensor_qw,sensor_qx,sensor_qy,sensor_qz");
    while (std::getline(rows, row)) {
        std::vector<std::string> c;
        std::stringstream cells(row);
        for (std::string cell; std::getline(cells, cell, ',');)
            c.push_back(cell);
        ASSERT_EQ(c.size(), 13u) << row;
        EXPECT_EQ(c[1], "1");
        expected[{std::stoi(c[3]), std::stoi(c[4]) & 0x3FFF}] = {std::stod(c[9]), std::stod(c[10]), std::stod(c[11]),
                                                                 std::stod(c[12])};
        segments[static_cast<std::uint32_t>(std::stoul(c[4]))][static_cast<std::size_t>(std::stoi(c[3]) - 1)] =
            mocap::skeleton::Quat(std::stod(c[5]), std::stod(c[6]), std::stod(c[7]), std::stod(c[8])).normalized();
    }
    EXPECT_GT(expected.size(), 15u * 100u);

    // The joint angles of the same instants, in mocap-client angles' columns.
    const auto model = mocap::skeleton::default_body_model();
    const auto joints = mocap::skeleton::default_joint_specs(model);
    std::istringstream angle_rows(slurp(dir_ / "angles.csv"));
    std::getline(angle_rows, row);
    EXPECT_EQ(row.rfind("subject,sync,t_s,left_hip.flexion_deg,", 0), 0u) << row;
    std::size_t angle_count = 0;
    double worst_deg = 0.0;
    while (std::getline(angle_rows, row)) {
        std::vector<std::string> c;
        std::stringstream cells(row);
        for (std::string cell; std::getline(cells, cell, ',');)
            c.push_back(cell);
        ASSERT_EQ(c.size(), 3u + 3u * joints.size()) << row;
        const std::uint64_t sync = std::stoull(c[1]);
        ASSERT_EQ(sync >> 32, 1u) << "the daemon's first stream starts at 2^32 + counter";
        const auto it = segments.find(static_cast<std::uint32_t>(sync & 0xFFFFFFFFu));
        ASSERT_NE(it, segments.end()) << row;
        for (std::size_t j = 0; j < joints.size(); ++j) {
            const auto& spec = joints[j];
            const auto angles = mocap::skeleton::joint_angles(spec.kind, spec.side, it->second[spec.parent_segment],
                                                              it->second[spec.child_segment]);
            const double deg = 180.0 / M_PI;
            worst_deg = std::max({worst_deg, std::abs(std::stod(c[3 + 3 * j]) - angles.flexion_rad * deg),
                                  std::abs(std::stod(c[4 + 3 * j]) - angles.abduction_rad * deg),
                                  std::abs(std::stod(c[5 + 3 * j]) - angles.rotation_rad * deg)});
        }
        ++angle_count;
    }
    EXPECT_EQ(angle_count, segments.size()) << "one row per SYNC";
    EXPECT_LT(worst_deg, 0.01) << "the poses file has 6 decimals, the angles 3";

    mw_stream_decoder decoder;
    mw_stream_decoder_init(&decoder);
    auto packet = std::make_unique<mw_packet>();
    std::size_t offset = 0, matched = 0;
    double worst = 0.0;
    while (offset < bytes.size()) {
        std::size_t used = 0;
        const mw_stream_result r =
            mw_stream_decoder_feed(&decoder, bytes.data() + offset, bytes.size() - offset, &used, packet.get());
        offset += used;
        if (r == MW_STREAM_NEED_MORE) break;
        ASSERT_EQ(r, MW_STREAM_PACKET);
        EXPECT_EQ(packet->header.sink_id, 1);
        for (std::size_t i = 0; i < packet->frame_count; ++i) {
            mw_attitude att{};
            if (mw_can_id_function(packet->frames[i].frame.id) != MW_FN_ATTITUDE) continue;
            ASSERT_EQ(mw_attitude_decode(&packet->frames[i].frame, &att), MW_OK);
            const auto it = expected.find({att.node_id, att.counter_low});
            ASSERT_NE(it, expected.end()) << "node " << int(att.node_id) << " counter " << att.counter_low;
            // Both normalised in double: acos near 1 would turn a 1e-7 norm error into 1e-3 rad.
            double dot = 0.0, n_truth = 0.0, n_att = 0.0;
            for (int k = 0; k < 4; ++k) {
                dot += it->second[k] * att.q[k];
                n_truth += it->second[k] * it->second[k];
                n_att += static_cast<double>(att.q[k]) * att.q[k];
            }
            dot /= std::sqrt(n_truth * n_att);
            worst = std::max(worst, 2.0 * std::acos(std::min(1.0, std::abs(dot))));
            ++matched;
        }
    }
    EXPECT_EQ(decoder.counters.bytes_discarded, 0u);
    EXPECT_GT(matched, 15u * 100u);
    EXPECT_LT(worst, 2e-4) << "rad";
}

}  // namespace
