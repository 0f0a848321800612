// Shared calibration (docs/cluster.md, "Shared calibration") against a real nats-server with
// JetStream on a loopback port: a subject calibrated through the control plane of one mocapd
// host is used by another host that serves the same subject (a simulated sink with the same
// id connected to it), which never calibrates it itself; its poses match the simulator's
// truth as a locally calibrated subject's do (daemon_test.cpp). The hosts share the site's
// calibration key (calibration_key_file), so every value is signed and checked on the way
// (calibration_security_test.cpp has the values that fail the check). A host that starts later
// reads the calibration from the bucket. Without JetStream on the server the bucket cannot
// be opened: the calibration stays local, the log says why, nothing crashes.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <filesystem>
#include <sstream>

#include "harness.hpp"
#include "mocap/v1/mocap.pb.h"
#include "nats_harness.hpp"
#include "pose_client.hpp"
#include "truth_check.hpp"

namespace mocap::itest {
namespace {

using namespace std::chrono_literals;

constexpr const char* kSite = "hall";
constexpr const char* kToken = "kv-s3cret-0123456789";
constexpr int kRateHz = 100;

struct Host {
    std::string id;
    std::uint16_t sink_port = 0, pose_port = 0;
    std::unique_ptr<TempDir> dir;  // its own calibration directory: nothing shared on disk
    std::unique_ptr<Process> daemon;
};

class CalibrationKv : public ::testing::Test {
protected:
    void SetUp() override {
        if (!have_nats_server()) {
            GTEST_SKIP() << "no nats-server binary at " << nats_server_bin() << " (setup.sh installs it)";
        }
        nats_port_ = free_port();
        key_file_ = dir_.file("calibration.key");
        write_file(key_file_, "kv-test-site-key-0123456789abcdef0123\n");
        ::chmod(key_file_.c_str(), 0600);
    }

    void TearDown() override {
        for (Host* h : {&a_, &b_, &c_}) {
            if (!h->daemon) continue;
            if (HasFailure()) std::cerr << "--- mocapd " << h->id << " log ---\n" << h->daemon->log();
            if (h->daemon->running()) {
                EXPECT_EQ(h->daemon->stop(15s), 0) << h->id << " must exit 0 on SIGTERM";
            }
        }
    }

    /// mocapd that never calibrates on its own (auto_calibrate off), heading "earth" and a
    /// facing of 0 as daemon_test's truth check needs, a control token, the cluster on.
    void start_host(Host& h, const std::string& id) {
        h.id = id;
        h.dir = std::make_unique<TempDir>();
        h.sink_port = free_port();
        h.pose_port = free_port();
        HostConfig c;
        c.sink_port = h.sink_port;
        c.pose_port = h.pose_port;
        c.calibration_dir = h.dir->path().string();
        c.ingest = "sink_idle_timeout_s = 5.0\n";
        c.skeleton = "auto_calibrate = \"off\"\nheading = \"earth\"\nfacing = \"given\"\nfacing_heading_deg = 0.0\n";
        c.serve = "client_queue_frames = 4096\n[control]\ntoken = \"" + std::string(kToken) + "\"\n";
        c.cluster = cluster_section(nats_port_, kSite, id,
                                    cluster_credentials() + "calibration_key_file = \"" + key_file_ + "\"\n");
        h.daemon = start_mocapd(MOCAPD_BIN, c, *h.dir);
        ASSERT_FALSE(HasFailure());
    }

    /// The simulated subject 1 (seed 11: the same body, sensor mounting and facing on every
    /// host), 4 s still in the T-pose, then walking.
    std::unique_ptr<Process> sim(const Host& h, int seconds, const std::string& truth) {
        return std::make_unique<Process>(
            std::vector<std::string>{MOCAP_SIM_BIN, "stream", "--connect", "127.0.0.1:" + std::to_string(h.sink_port),
                                     "--rate", std::to_string(kRateHz), "--subjects", "1", "--nodes", "15",
                                     "--duration", std::to_string(seconds), "--calibrate-s", "4", "--seed", "11",
                                     "--truth-poses", truth},
            h.dir->file("sim.log"));
    }

    static client::PoseClient connect_client(const Host& h) {
        client::PoseClient c;
        std::string err;
        EXPECT_TRUE(c.connect("127.0.0.1", h.pose_port, 5s, err)) << err;
        client::SubscribeOptions o;
        o.subject_ids = {1};
        EXPECT_TRUE(c.subscribe(o, 5s, err)) << err;
        return c;
    }

    static std::vector<std::string> segment_names(const client::PoseClient& c) {
        std::vector<std::string> n;
        for (const auto& s : c.hello().skeleton().segments())
            n.push_back(s.name());
        return n;
    }

    /// Frames of the client until `done` or `limit`.
    template <typename Done>
    static std::vector<v1::SkeletonFrame> collect(client::PoseClient& c, std::chrono::milliseconds limit, Done done) {
        std::vector<v1::SkeletonFrame> out;
        const auto end = std::chrono::steady_clock::now() + limit;
        v1::SkeletonFrame f;
        while (std::chrono::steady_clock::now() < end && !done(out)) {
            const auto st = c.next_frame(f, 200ms);
            if (st == client::ReadStatus::kMessage) {
                out.push_back(f);
            } else if (st != client::ReadStatus::kTimeout) {
                break;
            }
        }
        return out;
    }

    static v1::ControlReply calibrate(client::PoseClient& c) {
        v1::ControlRequest req;
        req.set_token(kToken);
        req.mutable_calibrate()->set_subject_id(1);
        req.mutable_calibrate()->set_pose(v1::POSE_T);
        v1::ControlReply reply;
        std::string err;
        EXPECT_TRUE(c.control(req, reply, 5s, err)) << err;
        return reply;
    }

    std::uint16_t nats_port_ = 0;
    TempDir dir_;
    std::string key_file_;
    std::unique_ptr<Process> nats_;
    Host a_, b_, c_;
};

TEST_F(CalibrationKv, ASubjectCalibratedOnOneHostIsSolvedWithThatCalibrationOnAnother) {
    nats_ = start_nats(nats_port_, dir_.file("nats.log"), {"-js", "-sd", dir_.file("js")});
    start_host(a_, "host-a");
    start_host(b_, "host-b");
    auto ca = connect_client(a_);
    auto cb = connect_client(b_);
    const auto names = segment_names(cb);
    ASSERT_EQ(names.size(), 15u);
    // The same subject (sink 1) feeds both hosts, as a sink that moved to host B would.
    auto sa = sim(a_, 8, a_.dir->file("truth.csv"));
    auto sb = sim(b_, 11, b_.dir->file("truth.csv"));

    // Host A: frames flow, then the subject is calibrated in its T-pose on command.
    const auto first = collect(ca, 10s, [](const auto& v) { return v.size() >= 100; });
    ASSERT_GE(first.size(), 100u) << "no frames on host A";
    const v1::ControlReply reply = calibrate(ca);
    ASSERT_TRUE(reply.ok()) << reply.error();
    EXPECT_EQ(wait_stats_counter(
                  a_.pose_port, "calibration_kv.puts", [](auto v) { return v >= 1; }, 15s),
              1u)
        << "host A puts its calibration to the bucket";
    EXPECT_EQ(stats_counter(a_.pose_port, "skeleton.calibrations_ok"), 1u);

    // Host B: its frames until its simulator ends.
    auto frames = collect(cb, 30s, [&](const auto&) { return !sb->running(); });
    const auto tail = collect(cb, 1s, [](const auto&) { return false; });
    frames.insert(frames.end(), tail.begin(), tail.end());
    ASSERT_EQ(sb->wait(5s).value_or(-1), 0) << sb->log();
    ASSERT_EQ(sa->wait(5s).value_or(-1), 0) << sa->log();

    EXPECT_EQ(stats_counter(b_.pose_port, "skeleton.calibrations_ok"), 0u) << "host B never calibrates by itself";
    EXPECT_EQ(stats_counter(b_.pose_port, "skeleton.calibrations_shared"), 1u);
    EXPECT_GE(stats_counter(b_.pose_port, "calibration_kv.received"), 1u);
    EXPECT_EQ(stats_counter(b_.pose_port, "calibration_kv.errors"), 0u);
    EXPECT_EQ(stats_counter(b_.pose_port, "calibration_kv.refused"), 0u) << "host A's signed value verifies on host B";
    EXPECT_NE(b_.daemon->log().find("subject 1: calibration from bucket mocap_calibration (key hall.1, revision"),
              std::string::npos)
        << b_.daemon->log();

    const std::uint32_t motion_start = 5 * kRateHz;  // 4 s still + 1 s blend
    const TruthErrors e = truth_errors(frames, names, b_.dir->file("truth.csv"), 1, motion_start);
    ASSERT_GT(e.calibrated_frames, 0u) << "host A's calibration never applied on host B";
    ASSERT_EQ(e.malformed, 0u);
    ASSERT_GT(e.motion_frames, 5u * kRateHz) << "too few calibrated frames in motion on host B";
    ASSERT_GT(e.err_deg.size(), e.motion_frames * 14);
    std::cout << "[ metrics  ] host B, calibrated on host A: segment orientation error vs truth: median " << e.median()
              << " deg, p95 " << e.p95() << " deg over " << e.err_deg.size() << " segment-frames\n";
    EXPECT_LT(e.median(), 3.0);
    EXPECT_LT(e.p95(), 8.0);
    // Host B keeps the shared calibration in its own directory: its fallback if the
    // cluster is away at its next start.
    EXPECT_TRUE(std::filesystem::exists(b_.dir->file("calibration-subject-1.toml")));

    // A host that starts later, and has not seen a frame of the subject, reads the bucket.
    start_host(c_, "host-c");
    EXPECT_GE(wait_stats_counter(
                  c_.pose_port, "calibration_kv.received", [](auto v) { return v >= 1; }, 15s),
              1u)
        << "a starting host reads the calibrations of its site";
}

TEST_F(CalibrationKv, WithoutJetStreamTheCalibrationStaysLocalAndTheLogSaysWhy) {
    nats_ = start_nats(nats_port_, dir_.file("nats.log"));  // no -js: no bucket
    start_host(a_, "host-a");
    auto ca = connect_client(a_);
    auto sa = sim(a_, 5, a_.dir->file("truth.csv"));
    const auto first = collect(ca, 10s, [](const auto& v) { return v.size() >= 100; });
    ASSERT_GE(first.size(), 100u);
    const v1::ControlReply reply = calibrate(ca);
    ASSERT_TRUE(reply.ok()) << reply.error();
    const auto calibrated =
        collect(ca, 10s, [](const auto& v) { return !v.empty() && (v.back().flags(0) & v1::SEGMENT_CALIBRATED) != 0; });
    ASSERT_FALSE(calibrated.empty());
    EXPECT_NE(calibrated.back().flags(0) & v1::SEGMENT_CALIBRATED, 0u) << "the local calibration applies";
    EXPECT_TRUE(wait_until([&] { return std::filesystem::exists(a_.dir->file("calibration-subject-1.toml")); }, 10s))
        << "saved in the local calibration directory";
    EXPECT_GE(wait_stats_counter(
                  a_.pose_port, "calibration_kv.errors", [](auto v) { return v >= 1; }, 10s),
              1u);
    EXPECT_EQ(stats_counter(a_.pose_port, "calibration_kv.puts"), 0u);
    const std::string log = a_.daemon->log();
    EXPECT_NE(log.find("calibration bucket mocap_calibration: cannot open it on nats://127.0.0.1:"), std::string::npos)
        << log;
    EXPECT_NE(log.find("calibrations stay local until it opens"), std::string::npos) << log;
    ASSERT_EQ(sa->wait(10s).value_or(-1), 0) << sa->log();
    EXPECT_EQ(a_.daemon->stop(15s), 0) << "no crash, a clean stop";
}

}  // namespace
}  // namespace mocap::itest
