// The real mocapd on loopback with a generated config, fed by the real mocap-sim stream,
// read through the real pose port (docs/style.md, "Real binaries on loopback"). Orientation accuracy is checked against
// the simulator's own truth file.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <sstream>
#include <thread>

#include "harness.hpp"
#include "math/quaternion.hpp"
#include "pose_client.hpp"
#include "truth_check.hpp"

namespace mocap::itest {
namespace {

using namespace std::chrono_literals;
using math::Quat;

constexpr const char* kToken = "it-s3cret-0123456789";
constexpr int kRateHz = 100;

struct Received {
    v1::SkeletonFrame frame;
    std::int64_t receive_us = 0;
};

class Daemon : public ::testing::Test {
protected:
    void SetUp() override {
        sink_port_ = free_port();
        pose_port_ = free_port();
        std::ostringstream cfg;
        cfg << "[log]\nlevel = \"info\"\nstats_interval_s = 0\n"
            << "[ingest]\nsink_listen = \"127.0.0.1:" << sink_port_ << "\"\nsink_idle_timeout_s = 2.0\n"
            << "[pipeline]\nworkers = 2\nmax_subjects = 4\nassembly_deadline_ms = 20.0\n"
            << "[skeleton]\ncalibration_dir = \"" << dir_.path().string() << "\"\nheading = \"earth\"\n"
            << "facing = \"given\"\nfacing_heading_deg = 0.0\n"
            << "[serve]\npose_listen = \"127.0.0.1:" << pose_port_
            << "\"\nclient_queue_frames = " << client_queue_frames_ << "\n"
            << "[control]\ntoken = \"" << kToken
            << "\"\n"
            // Every listening port is a free one: ctest runs daemons in parallel.
            << "[outputs]\nbvh_listen = \"127.0.0.1:" << free_port() << "\"\n"
            << "[http]\nlisten = \"127.0.0.1:" << free_port() << "\"\n";
        config_ = dir_.file("mocapd.toml");
        write_file(config_, cfg.str());
        daemon_ = std::make_unique<Process>(std::vector<std::string>{MOCAPD_BIN, "--config", config_},
                                            dir_.file("mocapd.log"), dir_.path().string());
        ASSERT_TRUE(wait_for_port(pose_port_, 10s)) << daemon_->log();
        ASSERT_TRUE(wait_for_port(sink_port_, 10s)) << daemon_->log();
    }

    void TearDown() override { stop_daemon_at_teardown(daemon_.get()); }

    // Small: a client that stops reading drops frames within a fraction of a second.
    int client_queue_frames_ = 16;

    std::unique_ptr<Process> sim(std::vector<std::string> extra, const std::string& log = "sim.log") {
        std::vector<std::string> argv{MOCAP_SIM_BIN, "stream",
                                      "--connect",   "127.0.0.1:" + std::to_string(sink_port_),
                                      "--rate",      std::to_string(kRateHz)};
        argv.insert(argv.end(), extra.begin(), extra.end());
        return std::make_unique<Process>(argv, dir_.file(log));
    }

    client::PoseClient connect_client(std::vector<std::uint32_t> subjects = {}, std::uint32_t fields = 0) {
        client::PoseClient c;
        std::string err;
        EXPECT_TRUE(c.connect("127.0.0.1", pose_port_, 5s, err)) << err;
        client::SubscribeOptions o;
        o.subject_ids = std::move(subjects);
        o.fields = fields;
        EXPECT_TRUE(c.subscribe(o, 5s, err)) << err;
        return c;
    }

    // Reads frames until `done` says so or `limit` passes.
    template <typename Done>
    std::vector<Received> collect(client::PoseClient& c, std::chrono::milliseconds limit, Done done) {
        std::vector<Received> out;
        const auto end = std::chrono::steady_clock::now() + limit;
        v1::SkeletonFrame f;
        while (std::chrono::steady_clock::now() < end && !done(out)) {
            const auto st = c.next_frame(f, 200ms);
            if (st == client::ReadStatus::kMessage) {
                out.push_back({f, c.last_receive_us()});
            } else if (st != client::ReadStatus::kTimeout) {
                break;
            }
        }
        return out;
    }

    v1::ControlReply calibrate(client::PoseClient& c, std::uint32_t subject, const std::string& token) {
        v1::ControlRequest req;
        req.set_token(token);
        req.mutable_calibrate()->set_subject_id(subject);
        req.mutable_calibrate()->set_pose(v1::POSE_T);
        v1::ControlReply reply;
        std::string err;
        EXPECT_TRUE(c.control(req, reply, 5s, err)) << err;
        return reply;
    }

    std::uint64_t stat(client::PoseClient& c, const std::string& name) {
        v1::Stats s;
        std::string err;
        EXPECT_TRUE(c.request_stats(s, 5s, err)) << err;
        for (const auto& kv : s.counters()) {
            if (kv.name() == name) return kv.value();
        }
        ADD_FAILURE() << "no counter " << name;
        return 0;
    }

    TempDir dir_;
    std::uint16_t sink_port_ = 0;
    std::uint16_t pose_port_ = 0;
    std::string config_;
    std::unique_ptr<Process> daemon_;
};

TEST_F(Daemon, PosesMatchSimulatorTruthAfterCalibration) {
    auto c = connect_client({1});
    const std::vector<std::string> names = [&] {
        std::vector<std::string> n;
        for (const auto& s : c.hello().skeleton().segments())
            n.push_back(s.name());
        return n;
    }();
    ASSERT_EQ(names.size(), 15u);
    auto s = sim({"--subjects", "1", "--nodes", "15", "--duration", "14", "--calibrate-s", "4", "--seed", "11",
                  "--truth-poses", dir_.file("truth.csv")});

    // Frames flow before calibration (raw sensor orientations), then calibrate in the T-pose.
    auto first = collect(c, 10s, [](const auto& v) { return v.size() >= 100; });
    ASSERT_GE(first.size(), 100u) << "no frames from the simulated subject";
    const v1::ControlReply reply = calibrate(c, 1, kToken);
    ASSERT_TRUE(reply.ok()) << reply.error();

    auto frames = collect(c, 25s, [&](const auto&) { return !s->running(); });
    auto tail = collect(c, 1s, [](const auto&) { return false; });
    frames.insert(frames.end(), tail.begin(), tail.end());
    ASSERT_EQ(s->wait(5s).value_or(-1), 0) << s->log();

    const auto truth = read_truth(dir_.file("truth.csv"));
    ASSERT_FALSE(truth.empty());
    // With heading "earth" and a given facing of 0, the output equals the truth turned by the
    // subject's own facing ψ during calibration: q_out ⊗ Rz(ψ) = q_true. ψ from the truth.
    const Quat pelvis0 = truth.begin()->second;
    const double psi = math::to_euler_zyx(pelvis0).yaw_rad;
    const Quat rz_psi(Eigen::AngleAxisd(psi, math::Vec3::UnitZ()));

    std::vector<double> err_deg;
    std::size_t calibrated_frames = 0, motion_frames = 0, stale = 0;
    const std::uint32_t motion_start = 5 * kRateHz;  // 4 s still + 1 s blend
    for (const auto& r : frames) {
        const auto& f = r.frame;
        ASSERT_EQ(f.segment_count(), 15u);
        ASSERT_EQ(f.q_world_segment_wxyz_size(), 60);
        const bool calibrated = (f.flags(0) & v1::SEGMENT_CALIBRATED) != 0;
        if (!calibrated) continue;
        ++calibrated_frames;
        if (counter_of(f) < motion_start) continue;
        ++motion_frames;
        for (int i = 0; i < 15; ++i) {
            if ((f.flags(i) & v1::SEGMENT_STALE) != 0) ++stale;
            const auto it = truth.find({1, counter_of(f), names[static_cast<std::size_t>(i)]});
            if (it == truth.end()) continue;
            const Quat q_err = segment_q(f, i) * rz_psi * it->second.conjugate();
            err_deg.push_back(math::error_total_rad(q_err) * 180.0 / std::numbers::pi);
        }
    }
    ASSERT_GT(calibrated_frames, 0u) << "calibration never applied";
    ASSERT_GT(motion_frames, 5u * kRateHz) << "too few frames in motion";
    ASSERT_GT(err_deg.size(), motion_frames * 14);
    std::sort(err_deg.begin(), err_deg.end());
    const double median = err_deg[err_deg.size() / 2];
    const double p95 = err_deg[err_deg.size() * 95 / 100];
    std::cout << "[ metrics  ] segment orientation error vs truth after calibration: median " << median << " deg, p95 "
              << p95 << " deg over " << err_deg.size() << " segment-frames\n";
    EXPECT_LT(median, 3.0);
    EXPECT_LT(p95, 8.0);
    // No node was cut, so a stale segment can only be the assembler's 20 ms deadline passing
    // on a starved machine (a loaded sanitizer run: 106 of ~13,000 once). A fault that
    // leaves a segment stale stays stale in every frame, far above this bound.
    const std::size_t segment_frames = motion_frames * 15;
    std::cout << "[ metrics  ] stale segments in motion: " << stale << " of " << segment_frames << "\n";
    EXPECT_LT(static_cast<double>(stale), 0.02 * static_cast<double>(segment_frames))
        << "no node was cut: stale segments beyond the assembler's deadline on a loaded machine";
}

// A service manager (or a script) may stop mocapd the moment it sees a port: the signal must
// drain it (exit 0), never kill it with the default action. The pose port opens first, so
// each round stops the daemon as soon as that port answers, while it is still starting.
TEST_F(Daemon, SigtermRightAfterTheFirstPortOpensDrains) {
    for (int round = 0; round < 5; ++round) {
        const std::uint16_t pose = free_port();
        const std::string cfg = dir_.file("early-" + std::to_string(round) + ".toml");
        write_file(cfg, "[log]\nlevel = \"info\"\n[ingest]\nsink_listen = \"127.0.0.1:" + std::to_string(free_port()) +
                            "\"\n[skeleton]\ncalibration_dir = \"" + dir_.path().string() +
                            "\"\n[serve]\npose_listen = \"127.0.0.1:" + std::to_string(pose) +
                            "\"\n[outputs]\nbvh_listen = \"127.0.0.1:" + std::to_string(free_port()) +
                            "\"\n[http]\nlisten = \"127.0.0.1:" + std::to_string(free_port()) + "\"\n");
        Process early({MOCAPD_BIN, "--config", cfg}, dir_.file("early-" + std::to_string(round) + ".log"));
        ASSERT_TRUE(wait_for_port(pose, 20s)) << early.log();
        EXPECT_EQ(early.stop(20s), 0) << "round " << round << ": killed instead of drained\n" << early.log();
    }
}

TEST_F(Daemon, DeadNodeIsFlaggedStaleAndRecovers) {
    auto c = connect_client({1});
    // Node 5 (segment index 4) is silent from 3 s to 5 s.
    auto s = sim({"--subjects", "1", "--nodes", "15", "--duration", "7", "--calibrate-s", "1.8", "--seed", "5",
                  "--dropout", "5:3:5"});
    auto frames = collect(c, 20s, [&](const auto&) { return !s->running(); });
    auto tail = collect(c, 500ms, [](const auto&) { return false; });
    frames.insert(frames.end(), tail.begin(), tail.end());
    ASSERT_EQ(s->wait(5s).value_or(-1), 0) << s->log();
    // The dropout is in the simulator's clock, the frame counter counts the SYNCs it sent: a
    // late loop (a loaded machine) skips instants, so a counter reads up to skipped/rate
    // earlier than the clock did. The window judged is the one that is surely silent.
    const double lag_s = static_cast<double>(sim_syncs_skipped(s->log()).value_or(0)) / kRateHz;
    const double window_end = 4.8 - lag_s;
    ASSERT_GT(window_end - 3.2, 0.5) << "the simulator ran " << lag_s << " s late: no silent window to judge";

    std::size_t in_window = 0, stale_in_window = 0, after = 0, stale_after = 0, others_stale = 0;
    std::size_t uncalibrated_late = 0;
    for (const auto& r : frames) {
        const auto& f = r.frame;
        const double t = counter_of(f) / static_cast<double>(kRateHz);
        // No calibrate request was sent: the first still period (the simulator's T-pose)
        // calibrates the subject automatically (skeleton.auto_calibrate = "t-pose").
        if (t > 2.0 && (f.flags(0) & v1::SEGMENT_CALIBRATED) == 0) ++uncalibrated_late;
        const bool stale = (f.flags(4) & v1::SEGMENT_STALE) != 0;
        if (t > 3.2 && t < window_end) {
            ++in_window;
            stale_in_window += stale ? 1 : 0;
        } else if (t > 5.3) {
            ++after;
            stale_after += stale ? 1 : 0;
        }
        for (int i = 0; i < 15; ++i) {
            if (i != 4 && (f.flags(i) & v1::SEGMENT_STALE) != 0) ++others_stale;
        }
    }
    // The subject keeps streaming at full rate while the node is dead (never frozen).
    EXPECT_GE(static_cast<double>(in_window), 0.9 * (window_end - 3.2) * kRateHz)
        << "frames must keep flowing while a node is dead";
    EXPECT_EQ(stale_in_window, in_window) << "the dead node's segment is flagged stale";
    EXPECT_GT(after, 100u);
    // Stale beyond the cut node: the assembler's 20 ms deadline on a starved machine (1 and 7
    // of ~9,000 in two runs at load 6). A segment that failed to recover, or a live node
    // wrongly flagged, is stale in every frame, far above these bounds.
    EXPECT_LT(static_cast<double>(stale_after), 0.02 * static_cast<double>(after))
        << "the node's segment recovers when it returns";
    EXPECT_LT(static_cast<double>(others_stale), 0.02 * 14.0 * static_cast<double>(frames.size()))
        << "the live nodes' segments are not stale";
    EXPECT_EQ(uncalibrated_late, 0u) << "the subject is calibrated automatically from its first still period";
}

TEST_F(Daemon, SinkReconnectResumesTheSubject) {
    auto c = connect_client({2});
    auto first = sim({"--subjects", "2", "--nodes", "15", "--duration", "2", "--seed", "1"}, "sim1.log");
    ASSERT_EQ(first->wait(15s).value_or(-1), 0) << first->log();
    auto before = collect(c, 2s, [](const auto&) { return false; });
    ASSERT_GT(before.size(), 100u);
    // The same sink (id 2) comes back on a new connection with its counter restarted.
    auto second = sim({"--subjects", "2", "--nodes", "15", "--duration", "2", "--seed", "2"}, "sim2.log");
    auto after = collect(c, 15s, [&](const auto&) { return !second->running(); });
    ASSERT_EQ(second->wait(5s).value_or(-1), 0) << second->log();
    ASSERT_GT(after.size(), 100u) << "frames resume after the sink reconnects";
    for (const auto& r : after)
        EXPECT_EQ(r.frame.subject_id(), 2u);
    EXPECT_GT(after.front().frame.sync(), before.back().frame.sync()) << "sync stays monotonic across reconnects";
    // Two connections per run (sinks 1 and 2) plus the harness's readiness probe.
    EXPECT_EQ(stat(c, "ingest_tcp.connections_accepted"), 5u);
}

// A queue of 512 frames (1.7 s of three subjects at 100 Hz): a reader starved that long by a
// loaded machine (a sanitizer build at load 6 starved one for more than 16 frames, 53 ms)
// loses nothing, while the client that never reads still overflows it within the 8 s run.
class DaemonSlowClient : public Daemon {
protected:
    DaemonSlowClient() { client_queue_frames_ = 512; }
};

TEST_F(DaemonSlowClient, SlowClientDoesNotSlowTheOthers) {
    auto fast = connect_client({}, v1::FIELD_ORIENTATIONS | v1::FIELD_POSITIONS | v1::FIELD_JOINT_ANGLES);
    auto slow = connect_client({}, v1::FIELD_ORIENTATIONS | v1::FIELD_POSITIONS | v1::FIELD_JOINT_ANGLES);
    auto s = sim({"--subjects", "3", "--nodes", "15", "--duration", "8", "--seed", "3", "--sink-rate-stats"});
    // `slow` never reads again.
    auto frames = collect(fast, 25s, [&](const auto&) { return !s->running(); });
    auto tail = collect(fast, 500ms, [](const auto&) { return false; });
    frames.insert(frames.end(), tail.begin(), tail.end());
    ASSERT_EQ(s->wait(5s).value_or(-1), 0) << s->log();
    std::map<std::uint32_t, std::vector<std::uint64_t>> syncs;
    for (const auto& r : frames)
        syncs[r.frame.subject_id()].push_back(r.frame.sync());
    ASSERT_EQ(syncs.size(), 3u);
    // Instants the simulator skipped when it ran late on a loaded machine never existed.
    const std::uint64_t skipped = sim_syncs_skipped(s->log()).value_or(0);
    for (auto& [subject, v] : syncs) {
        std::uint64_t gaps = 0;
        for (std::size_t i = 1; i < v.size(); ++i)
            gaps += v[i] - v[i - 1] - 1;
        EXPECT_LE(gaps, skipped) << "subject " << subject << ": the fast client must see every frame the sink sent";
        EXPECT_GE(v.size() + skipped, 7u * kRateHz);
    }
    EXPECT_EQ(fast.drops_announced(), 0u);
    EXPECT_GT(stat(fast, "serve.frames_dropped"), 0u) << "the slow client's queue must drop its oldest frames";
}

TEST_F(Daemon, ControlIsRefusedWithoutTheToken) {
    auto c = connect_client({1});
    EXPECT_FALSE(calibrate(c, 1, "").ok());
    EXPECT_FALSE(calibrate(c, 1, "wrong-token").ok());
    EXPECT_TRUE(calibrate(c, 1, kToken).ok());
    EXPECT_FALSE(calibrate(c, 99, kToken).ok()) << "unknown subject";
    EXPECT_EQ(stat(c, "serve.control_refused_no_token"), 1u);
    EXPECT_EQ(stat(c, "serve.control_refused_bad_token"), 1u);
}

TEST(DaemonCli, CheckConfigNamesKeyAndLine) {
    TempDir dir;
    write_file(dir.file("bad.toml"), "[pipeline]\nworkers = 2\nring_capacity = 1000\n");
    write_file(dir.file("good.toml"), "[pipeline]\nworkers = 2\n");
    Process bad({MOCAPD_BIN, "--check-config", dir.file("bad.toml")}, dir.file("bad.log"));
    EXPECT_NE(bad.wait(10s).value_or(0), 0);
    EXPECT_NE(bad.log().find("bad.toml:3: pipeline.ring_capacity: must be a power of two"), std::string::npos)
        << bad.log();
    Process good({MOCAPD_BIN, "--check-config", dir.file("good.toml")}, dir.file("good.log"));
    EXPECT_EQ(good.wait(10s).value_or(-1), 0) << good.log();
}

// ---- the one validation path (server/daemon/config_check.hpp): --check-config refuses what
// start-up refuses, and start-up refuses it with the same message.

/// A complete config on free loopback ports; `extra` is appended (TOML allows a table to be
/// continued only once, so cases add keys to tables this one does not open).
std::string valid_config(const TempDir& dir, const std::string& extra, std::uint16_t pose_port = 0) {
    std::ostringstream cfg;
    cfg << "[log]\nlevel = \"info\"\nstats_interval_s = 0\n"
        << "[ingest]\nsink_listen = \"127.0.0.1:" << free_port() << "\"\n"
        << "[pipeline]\nworkers = 1\nmax_subjects = 4\n"
        << "[skeleton]\ncalibration_dir = \"" << dir.path().string() << "\"\n"
        << "[serve]\npose_listen = \"127.0.0.1:" << (pose_port != 0 ? pose_port : free_port()) << "\"\n"
        << "[http]\nlisten = \"127.0.0.1:" << free_port() << "\"\n"
        << extra;
    return cfg.str();
}

/// Runs mocapd with `args`; expects a non-zero exit within the deadline and returns its output.
std::string refused(const std::vector<std::string>& args, const std::string& log_path) {
    std::vector<std::string> argv{MOCAPD_BIN};
    argv.insert(argv.end(), args.begin(), args.end());
    Process p(argv, log_path);
    const auto rc = p.wait(10s);
    EXPECT_TRUE(rc.has_value()) << "mocapd must exit, not run: " << p.log();
    EXPECT_NE(rc.value_or(0), 0) << p.log();
    return p.log();
}

TEST(DaemonCli, DirectoryOrEmptyFileAsConfigIsRefusedAtStartAndCheck) {
    TempDir dir;
    write_file(dir.file("empty.toml"), "");
    write_file(dir.file("comments.toml"), "# nothing but a comment\n\n");
    for (const auto& mode : {"--config", "--check-config"}) {
        std::string log = refused({mode, dir.path().string()}, dir.file("dir.log"));
        EXPECT_NE(log.find("invalid config: " + dir.path().string() + ": not a regular file (a directory)"),
                  std::string::npos)
            << mode << ": " << log;
        for (const auto& name : {"empty.toml", "comments.toml"}) {
            log = refused({mode, dir.file(name)}, dir.file("empty.log"));
            EXPECT_NE(log.find(dir.file(name) + ": the file has no settings"), std::string::npos)
                << mode << " " << name << ": " << log;
        }
    }
}

TEST(DaemonCli, CheckConfigRefusesEveryConfigStartUpRefuses) {
    TempDir dir;
    const std::string missing = dir.file("no-such-dir");
    const std::uint16_t shared_port = free_port();
    // {what is appended to a valid config, what the message must say}
    const std::vector<std::pair<std::string, std::string>> cases{
        {"[filter]\nname = \"kalman\"\n", "filter.name: unknown filter \"kalman\""},
        {"[[skeleton.segment]]\nname = \"pelvis\"\nnode = 1\nend_m = [0.0, 0.2, 0.0]\nfilter = \"kalmann\"\n",
         "skeleton.segment[0].filter: unknown filter \"kalmann\""},
        {"[filter]\nname = \"madgwick\"\nparams = { beta = \"abc\" }\n", "filter.params.beta: parameter \"beta\""},
        {"[filter]\nname = \"madgwick\"\nparams = { gamma = 0.1 }\n", "filter.params.gamma: filter \"madgwick\""},
        {"[outputs]\nbvh_listen = \"no-such-host.invalid:7002\"\n",
         "outputs.bvh_listen: host \"no-such-host.invalid\" must be an IPv4 or IPv6 address"},
        // The live-BVH listener on the pose port (valid_config puts the pose port there).
        {"[outputs]\nbvh_listen = \"127.0.0.1:" + std::to_string(shared_port) + "\"\n",
         "outputs.bvh_listen: 127.0.0.1:" + std::to_string(shared_port) + " collides with serve.pose_listen"},
        {"[outputs]\nraw_record = true\nrecord_dir = \"" + missing + "\"\n",
         "outputs.record_dir: \"" + missing + "\" is not a directory"},
        {"[outputs]\nraw_rotate_s = 0.001\n", "outputs.raw_rotate_s: must be 0 (off) or between 10"},
        {"[outputs]\nbvh_subject = 65000\n", "outputs.bvh_subject: 65000 is not a configured subject"},
        {"[control]\ntoken = \"   \"\n", "control.token: must not be blank"},
        {"[control]\ntoken = \"fifteen-chars-x\"\n", "control.token: must be at least 16 characters"},
    };
    int n = 0;
    for (const auto& [extra, expect] : cases) {
        const std::string text = valid_config(dir, extra, shared_port);
        const std::string path = dir.file("case" + std::to_string(++n) + ".toml");
        write_file(path, text);
        const std::string check = refused({"--check-config", path}, dir.file("check.log"));
        EXPECT_NE(check.find("mocapd: invalid config: " + path + ":"), std::string::npos) << check;
        EXPECT_NE(check.find(expect), std::string::npos) << "--check-config, case " << n << ": " << check;
        const std::string start = refused({"--config", path}, dir.file("start.log"));
        EXPECT_NE(start.find(expect), std::string::npos) << "--config, case " << n << ": " << start;
    }
    // The same base config passes both ways (the cases fail for their own reason only).
    const std::string good = dir.file("good.toml");
    write_file(good, valid_config(dir, ""));
    Process ok({MOCAPD_BIN, "--check-config", good}, dir.file("good.log"));
    EXPECT_EQ(ok.wait(10s).value_or(-1), 0) << ok.log();
}

}  // namespace
}  // namespace mocap::itest
