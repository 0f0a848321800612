// The cluster output against a real nats-server on a loopback port (docs/outputs.md,
// "Cluster publisher"): the real mocapd fed by mocap-sim stream publishes every pose frame to
// mocap.<site>.<subject>.pose and a heartbeat to mocap.<site>.host.<host_id>; a NATS
// subscriber (the C client, here) decodes them; mocap-client --nats cat prints them; a lost
// cluster costs the local pose service nothing and publishing resumes when it is back.
#include <gtest/gtest.h>
#include <nats/nats.h>

#include <atomic>
#include <csignal>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <thread>

#include "harness.hpp"
#include "mocap/v1/mocap.pb.h"
#include "nats_harness.hpp"
#include "pose_client.hpp"

namespace mocap::itest {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

constexpr const char* kUser = kNatsUser;
constexpr const char* kPassword = kNatsPassword;
constexpr const char* kSite = "itest";
constexpr const char* kHost = "rack1";

std::string cluster_section(std::uint16_t nats_port, const std::string& credentials) {
    return itest::cluster_section(nats_port, kSite, kHost, credentials);
}

class Cluster : public ::testing::Test {
protected:
    void SetUp() override {
        if (!have_nats_server())
            GTEST_SKIP() << "no nats-server binary at " << nats_server_bin() << " (setup.sh installs it)";
        nats_port_ = free_port();
        nats_ = start_nats(nats_port_, dir_.file("nats.log"));
        sink_port_ = free_port();
        pose_port_ = free_port();
        bvh_port_ = free_port();
        HostConfig h{.sink_port = sink_port_, .pose_port = pose_port_, .calibration_dir = dir_.path().string()};
        h.ingest = "sink_idle_timeout_s = 5.0\n";
        h.serve = "client_queue_frames = 4096\n";
        h.outputs = "bvh_listen = \"127.0.0.1:" + std::to_string(bvh_port_) + "\"\n";
        h.http = "listen = \"127.0.0.1:" + std::to_string(free_port()) + "\"\n";
        h.cluster = cluster_section(nats_port_, cluster_credentials());
        daemon_ = start_mocapd(MOCAPD_BIN, h, dir_);
        ASSERT_FALSE(HasFailure());
    }

    void TearDown() override {
        if (!daemon_) return;
        if (HasFailure()) std::cerr << "--- mocapd log ---\n" << daemon_->log();
        EXPECT_EQ(daemon_->stop(10s), 0) << "mocapd must exit 0 on SIGTERM, cluster or not";
    }

    std::unique_ptr<Process> sim(int subjects, int seconds) {
        return stream_sim(MOCAP_SIM_BIN, sink_port_, subjects, seconds, dir_.file("sim.log"));
    }

    std::uint64_t counter(const std::string& name) { return stats_counter(pose_port_, name); }

    /// Polls `name` until `pred` holds or `limit` passes; returns the last value.
    template <class Pred>
    std::uint64_t wait_counter(const std::string& name, Pred pred, std::chrono::milliseconds limit) {
        return wait_stats_counter(pose_port_, name, pred, limit);
    }

    TempDir dir_;
    std::uint16_t nats_port_ = 0, sink_port_ = 0, pose_port_ = 0, bvh_port_ = 0;
    std::unique_ptr<Process> nats_;
    std::unique_ptr<Process> daemon_;
};

TEST_F(Cluster, EveryFrameIsPublishedOnItsSubjectWithMonotonicSyncAndAHeartbeatEachSecond) {
    NatsSubscriber poses(nats_port_, std::string("mocap.") + kSite + ".*.pose");
    NatsSubscriber beats(nats_port_, std::string("mocap.") + kSite + ".host." + kHost);
    auto s = sim(2, 4);
    std::map<std::uint32_t, std::vector<std::uint64_t>> syncs;
    const auto end = Clock::now() + 30s;
    while (Clock::now() < end) {
        auto m = poses.next(s->running() ? 1000ms : 500ms);
        if (!m) {
            if (!s->running()) break;
            continue;
        }
        const v1::SkeletonFrame f = decode_pose_payload(m->second);
        EXPECT_EQ(m->first, std::string("mocap.") + kSite + "." + std::to_string(f.subject_id()) + ".pose");
        EXPECT_EQ(f.segment_count(), 15u);
        EXPECT_EQ(f.q_world_segment_wxyz_size(), 60) << "every field is published";
        EXPECT_EQ(f.position_m_size(), 45);
        EXPECT_GT(f.joint_angles_rad_size(), 0);
        syncs[f.subject_id()].push_back(f.sync());
    }
    ASSERT_EQ(s->wait(10s).value_or(-1), 0) << s->log();
    // Instants the simulator skipped when it ran late on a loaded machine never existed.
    const std::uint64_t skipped = sim_syncs_skipped(s->log()).value_or(0);
    ASSERT_EQ(syncs.size(), 2u);
    for (const auto& [subject, v] : syncs) {
        // A sanity bound (a starved machine sends fewer of the 4 s); completeness is the gap check.
        EXPECT_GE(v.size(), 100u) << "subject " << subject << ": at least 1 s of the 4 s run";
        std::uint64_t gaps = 0;
        for (std::size_t i = 1; i < v.size(); ++i) {
            ASSERT_GT(v[i], v[i - 1]) << "subject " << subject << ": sync must increase";
            gaps += v[i] - v[i - 1] - 1;
        }
        EXPECT_LE(gaps, skipped) << "subject " << subject << ": every frame the sink sent is published once";
    }
    EXPECT_EQ(counter("cluster.frames_dropped"), 0u);
    EXPECT_GE(counter("cluster.frames_published"), syncs[1].size() + syncs[2].size());

    // Heartbeats: one a second (by the publisher's own stamps: the subscription queued them
    // while the frames above were read), naming the host and the subjects served.
    std::vector<std::int64_t> at_us;
    bool subjects_named = false;
    const auto beat_end = Clock::now() + 15s;
    while (at_us.size() < 6 && Clock::now() < beat_end) {
        auto m = beats.next(3000ms);
        if (!m) continue;
        const auto j = nlohmann::json::parse(m->second);
        at_us.push_back(j.at("time_us").get<std::int64_t>());
        EXPECT_EQ(j.at("host_id"), kHost);
        EXPECT_EQ(j.at("site"), kSite);
        EXPECT_EQ(j.at("segments").size(), 15u);
        EXPECT_EQ(j.at("health"), "ok");
        subjects_named = subjects_named || !j.at("subjects").empty();
    }
    ASSERT_GE(at_us.size(), 6u) << "heartbeats must keep coming (with or without frames)";
    EXPECT_TRUE(subjects_named) << "a heartbeat while frames flowed names the subjects and rates";
    // One a second on average: the publisher keeps a fixed schedule, so a beat a starved
    // machine delays is followed by an early one; the mean over the run stays 1 s.
    for (std::size_t i = 1; i < at_us.size(); ++i)
        EXPECT_GT(at_us[i], at_us[i - 1]) << "heartbeat stamps only grow";
    const double mean_s =
        static_cast<double>(at_us.back() - at_us.front()) / 1e6 / static_cast<double>(at_us.size() - 1);
    EXPECT_GT(mean_s, 0.75);
    EXPECT_LT(mean_s, 1.5);
}

TEST_F(Cluster, MocapClientCatReadsFromTheClusterInThePoseServiceFormat) {
    auto s = sim(1, 15);
    const std::string out = dir_.file("cat.out");
    Process cat({"/bin/sh", "-c",
                 std::string(MOCAP_CLIENT_BIN) + " --nats nats://127.0.0.1:" + std::to_string(nats_port_) + " --site " +
                     kSite + " --nats-user " + kUser + " --nats-password " + kPassword + " cat --frames 50 > " + out},
                dir_.file("cat.log"));
    ASSERT_EQ(cat.wait(20s).value_or(-1), 0) << cat.log();
    std::istringstream lines(read_file(out));
    int n = 0;
    for (std::string line; std::getline(lines, line); ++n) {
        EXPECT_EQ(line.rfind("subject 1 sync ", 0), 0u) << line;
        EXPECT_NE(line.find("segments=15"), std::string::npos) << line;
        EXPECT_NE(line.find("| pelvis q=("), std::string::npos) << "segment names from the heartbeat: " << line;
    }
    EXPECT_EQ(n, 50);
    s->stop();
}

/// The text of a BVH file before its MOTION lines, and the MOTION lines.
std::pair<std::string, std::vector<std::string>> split_bvh(const std::string& text) {
    const auto at = text.find("Frame Time:");
    const auto end = text.find('\n', at);
    if (at == std::string::npos || end == std::string::npos) return {text, {}};
    std::vector<std::string> lines;
    std::istringstream in(text.substr(end + 1));
    for (std::string line; std::getline(in, line);)
        lines.push_back(line);
    return {text.substr(0, end + 1), lines};
}

std::vector<double> bvh_values(const std::string& line) {
    std::vector<double> v;
    std::istringstream in(line);
    for (double x = 0; in >> x;)
        v.push_back(x);
    return v;
}

// `mocap-client --nats … record` writes the BVH file `record` writes from the live BVH port:
// the same HIERARCHY, frame count and Frame Time (built from the heartbeat's body and BVH
// settings), MOTION lines of the same width, and the same subject: its root height agrees
// with the live port's (the two record about the same second of the same walk).
TEST_F(Cluster, MocapClientRecordWritesFromTheClusterTheBvhTheLiveBvhPortGives) {
    auto s = sim(2, 30);
    NatsSubscriber poses(nats_port_, std::string("mocap.") + kSite + ".2.pose");
    ASSERT_TRUE(poses.next(15s)) << "no frame on the cluster";
    const std::string live = dir_.file("live.bvh"), nats = dir_.file("nats.bvh");
    Process from_port({MOCAP_CLIENT_BIN, "--connect", "127.0.0.1:" + std::to_string(bvh_port_), "record", "--out", live,
                       "--frames", "200", "--subject", "2"},
                      dir_.file("record-live.log"));
    Process from_nats(
        {MOCAP_CLIENT_BIN, "--nats", "nats://127.0.0.1:" + std::to_string(nats_port_), "--site", kSite, "--nats-user",
         kUser, "--nats-password", kPassword, "record", "--out", nats, "--frames", "200", "--subject", "2"},
        dir_.file("record-nats.log"));
    ASSERT_EQ(from_port.wait(30s).value_or(-1), 0) << from_port.log();
    ASSERT_EQ(from_nats.wait(30s).value_or(-1), 0) << from_nats.log();
    s->stop();
    EXPECT_NE(from_nats.log().find("200 frames, 48 values per frame"), std::string::npos) << from_nats.log();

    const auto [live_head, live_lines] = split_bvh(read_file(live));
    const auto [nats_head, nats_lines] = split_bvh(read_file(nats));
    // Frame Time is measured by each from the frames it saw (the port from the subject's
    // first 10 intervals on, the NATS recorder over its 200 frames): the same rate, not the
    // same digits. The rest of the header is byte for byte the same.
    const auto frame_time = [](std::string& head) {
        const auto at = head.find("Frame Time: ");
        if (at == std::string::npos) return -1.0;
        const auto end = head.find('\n', at);
        const double t = std::stod(head.substr(at + 12, end - at - 12));
        head.erase(at, end - at);
        return t;
    };
    auto live_rest = live_head, nats_rest = nats_head;
    const double live_t = frame_time(live_rest), nats_t = frame_time(nats_rest);
    EXPECT_EQ(nats_rest, live_rest) << "HIERARCHY and Frames";
    EXPECT_NEAR(live_t, 0.01, 0.001) << "the simulated sink's 100 Hz";
    EXPECT_NEAR(nats_t, 0.01, 0.001) << "the simulated sink's 100 Hz";
    EXPECT_NE(nats_head.find("Frames: 200\n"), std::string::npos);
    ASSERT_EQ(live_lines.size(), 200u);
    ASSERT_EQ(nats_lines.size(), 200u);
    double live_y = 0, nats_y = 0;
    for (std::size_t i = 0; i < 200; ++i) {
        const auto a = bvh_values(live_lines[i]);
        const auto b = bvh_values(nats_lines[i]);
        ASSERT_EQ(a.size(), 48u) << live_lines[i];
        ASSERT_EQ(b.size(), 48u) << nats_lines[i];
        live_y += a[1] / 200.0;  // root Y: BVH is Y-up, centimetres
        nats_y += b[1] / 200.0;
    }
    std::cout << "[ metrics  ] root height over 200 frames: live BVH port " << live_y << " cm, from NATS " << nats_y
              << " cm\n";
    EXPECT_GT(nats_y, 50.0) << "a standing subject's pelvis";
    EXPECT_NEAR(nats_y, live_y, 5.0) << "the same subject as the live port's";
}

// `mocap-client --nats … load` measures the cluster path as `load` measures the pose service:
// every client subscribed, every frame of both subjects counted once, latencies stamped.
TEST_F(Cluster, MocapClientLoadMeasuresTheClusterPath) {
    auto s = sim(2, 30);
    // Frames flow before the measurement starts.
    NatsSubscriber poses(nats_port_, std::string("mocap.") + kSite + ".*.pose");
    ASSERT_TRUE(poses.next(15s)) << "no frame on the cluster";
    const std::string out = dir_.file("load.json");
    Process load({"/bin/sh", "-c",
                  std::string(MOCAP_CLIENT_BIN) + " --nats nats://127.0.0.1:" + std::to_string(nats_port_) +
                      " --site " + kSite + " --nats-user " + kUser + " --nats-password " + kPassword +
                      " load --clients 3 --duration 3 --json > " + out},
                 dir_.file("load.log"));
    ASSERT_EQ(load.wait(60s).value_or(-1), 0) << load.log();
    s->stop();
    const auto j = nlohmann::json::parse(read_file(out));
    EXPECT_EQ(j.at("connected"), 3);
    // 2 subjects x 100 Hz x ~3 s per client; a loaded machine may deliver fewer, never none.
    EXPECT_GT(j.at("frames_per_client_min").get<std::uint64_t>(), 200u) << j.dump();
    // Instants the simulator skipped when it ran late never existed.
    EXPECT_LE(j.at("gaps").get<std::uint64_t>(), sim_syncs_skipped(s->log()).value_or(0)) << j.dump();
    EXPECT_EQ(j.at("latency_samples"), j.at("frames")) << "every frame carries its sink send time";
    EXPECT_FALSE(j.at("p99_ms").is_null());
    EXPECT_EQ(j.at("drops"), 0);
    EXPECT_FALSE(j.contains("error")) << j.dump();
}

// A subscriber nobody here wrote (nats.js, the `nats` package of the npm registry) reads every
// subject of the site through one wildcard; the bytes it got decode with the project's
// generated code, subject by subject, in order.
TEST_F(Cluster, ANatsClientFromNpmReadsEverySubjectOfTheSite) {
    constexpr int kMessages = 300;
    const std::string out = dir_.file("js.out");
    Process js({"/bin/sh", "-c",
                std::string(NODE_BIN) + " " + NATS_JS_DIR +
                    "/nats_subscriber.mjs nats://127.0.0.1:" + std::to_string(nats_port_) + " " + kUser + " " +
                    kPassword + " 'mocap." + kSite + ".*.pose' " + std::to_string(kMessages) + " 120 > " + out},
               dir_.file("js.log"));
    ASSERT_TRUE(wait_until([&] { return js.log().find("subscribed") != std::string::npos || !js.running(); }, 30s));
    ASSERT_NE(js.log().find("subscribed"), std::string::npos) << "node could not subscribe:\n" << js.log();
    auto s = sim(2, 30);
    ASSERT_EQ(js.wait(120s).value_or(-1), 0) << js.log();
    s->stop();

    std::map<std::uint32_t, std::vector<std::uint64_t>> syncs;
    std::istringstream lines(read_file(out));
    int n = 0;
    for (std::string subject, hex; lines >> subject >> hex; ++n) {
        ASSERT_EQ(hex.size() % 2, 0u);
        std::string bytes(hex.size() / 2, '\0');
        for (std::size_t i = 0; i < bytes.size(); ++i)
            bytes[i] = static_cast<char>(std::stoi(hex.substr(2 * i, 2), nullptr, 16));
        const v1::SkeletonFrame f = decode_pose_payload(bytes);
        EXPECT_EQ(subject, std::string("mocap.") + kSite + "." + std::to_string(f.subject_id()) + ".pose");
        EXPECT_EQ(f.segment_count(), 15u);
        EXPECT_EQ(f.q_world_segment_wxyz_size(), 60);
        syncs[f.subject_id()].push_back(f.sync());
    }
    EXPECT_EQ(n, kMessages);
    EXPECT_EQ(syncs.size(), 2u) << "both subjects arrive through the one wildcard subscription";
    for (const auto& [subject, v] : syncs)
        for (std::size_t i = 1; i < v.size(); ++i)
            EXPECT_GT(v[i], v[i - 1]) << "subject " << subject << ": in order, each frame once";
}

TEST_F(Cluster, ALostClusterCostsThePoseServiceNothingAndPublishingResumes) {
    NatsSubscriber poses(nats_port_, std::string("mocap.") + kSite + ".1.pose");
    client::PoseClient pose;
    std::string err;
    ASSERT_TRUE(pose.connect("127.0.0.1", pose_port_, 5s, err)) << err;
    ASSERT_TRUE(pose.subscribe({.subject_ids = {1}}, 5s, err)) << err;
    std::atomic<bool> stop_reading{false};
    std::vector<std::uint64_t> pose_syncs;
    std::thread reader([&] {
        v1::SkeletonFrame f;
        while (!stop_reading.load()) {
            if (pose.next_frame(f, 200ms) == client::ReadStatus::kMessage) pose_syncs.push_back(f.sync());
        }
    });
    auto s = sim(1, 60);

    // Frames reach the cluster.
    std::optional<std::pair<std::string, std::string>> m;
    for (auto end = Clock::now() + 15s; !m && Clock::now() < end;)
        m = poses.next(1000ms);
    ASSERT_TRUE(m) << "no frame on the cluster";
    const std::uint64_t sync_before = decode_pose_payload(m->second).sync();

    // The cluster dies: the publisher notices and drops (counted), the pipeline goes on.
    nats_->signal(SIGKILL);
    ASSERT_TRUE(nats_->wait(10s)) << "nats-server did not die";
    EXPECT_GE(wait_counter(
                  "cluster.disconnects", [](auto v) { return v >= 1; }, 15s),
              1u);
    const std::uint64_t dropped = wait_counter(
        "cluster.frames_dropped", [](auto v) { return v >= 100; }, 15s);
    EXPECT_GE(dropped, 100u) << "frames while the cluster is down are dropped, oldest first";

    // It comes back on the same port: the publisher reconnects by itself and publishes again.
    nats_ = start_nats(nats_port_, dir_.file("nats2.log"));
    EXPECT_GE(wait_counter(
                  "cluster.reconnects", [](auto v) { return v >= 1; }, 20s),
              1u);
    std::optional<std::uint64_t> sync_after;
    for (auto end = Clock::now() + 20s; !sync_after && Clock::now() < end;) {
        if (auto r = poses.next(1000ms)) {
            const auto f = decode_pose_payload(r->second);
            if (f.sync() > sync_before + 100) sync_after = f.sync();
        }
    }
    EXPECT_TRUE(sync_after) << "publishing must resume after the cluster is back";

    stop_reading.store(true);
    reader.join();
    s->stop();
    ASSERT_FALSE(pose_syncs.empty());
    EXPECT_LE(pose_syncs.front(), sync_before) << "the pose client read from before the cluster died";
    EXPECT_GE(pose_syncs.back(), sync_after.value_or(0)) << "... until after publishing resumed";
    std::uint64_t gaps = 0;
    for (std::size_t i = 1; i < pose_syncs.size(); ++i)
        gaps += pose_syncs[i] - pose_syncs[i - 1] - 1;
    // mocap-sim prints its stats line on SIGTERM too: instants it skipped never existed.
    EXPECT_LE(gaps, sim_syncs_skipped(s->log()).value_or(0))
        << "the pose client gets every frame the sink sent while the cluster is down";
    EXPECT_EQ(pose.drops_announced(), 0u);
}

// Two zones of one site (docs/cluster.md, "Subject ids across a site"): hosts with
// subject_id_base 0 and 1000, each fed by a sink with sink id 1, serve subjects 1 and 1001;
// one subscriber to the site sees both, poses and raw samples, and the 1000 host's pose
// service names, calibrates and shares subject 1001.
TEST(ClusterZones, SinksWithOneSinkIdOnHostsOfTwoZonesAreTwoSubjectsOfTheSite) {
    if (!have_nats_server()) GTEST_SKIP() << "no nats-server binary at " << nats_server_bin();
    constexpr const char* kZoneSite = "zones";
    constexpr const char* kToken = "zone-control-token-1";
    TempDir dir;
    const std::uint16_t nats_port = free_port();
    auto nats = start_nats(nats_port, dir.file("nats.log"), {"-js", "-sd", dir.file("js")});
    NatsSubscriber poses(nats_port, std::string("mocap.") + kZoneSite + ".*.pose");
    NatsSubscriber raw(nats_port, std::string("mocap.") + kZoneSite + ".*.raw");
    NatsSubscriber bucket(nats_port, "$KV.mocap_calibration.>");

    struct Zone {
        std::uint32_t base;
        std::uint16_t sink_port = free_port(), pose_port = free_port();
        std::unique_ptr<Process> daemon{}, sim{};
    };
    Zone zones[] = {{.base = 0}, {.base = 1000}};
    for (Zone& z : zones) {
        const std::string name = "zone" + std::to_string(z.base);
        HostConfig h{.sink_port = z.sink_port, .pose_port = z.pose_port, .calibration_dir = dir.path().string()};
        h.ingest = "subject_id_base = " + std::to_string(z.base) + "\n";
        h.skeleton = "auto_calibrate = \"off\"\n";
        h.serve = std::string("[control]\ntoken = \"") + kToken + "\"\n";
        h.cluster = itest::cluster_section(nats_port, kZoneSite, name, cluster_credentials());
        z.daemon = start_mocapd(MOCAPD_BIN, h, dir, name);
        ASSERT_FALSE(HasFailure());
        // Sink id 1 on both hosts; 4 s still (a T-pose) first, so a calibration succeeds.
        z.sim = std::make_unique<Process>(
            std::vector<std::string>{MOCAP_SIM_BIN, "stream", "--connect", "127.0.0.1:" + std::to_string(z.sink_port),
                                     "--rate", "100", "--subjects", "1", "--first-sink-id", "1", "--duration", "8",
                                     "--calibrate-s", "4"},
            dir.file(name + "-sim.log"));
    }
    const auto logs = [&] {
        std::string out;
        for (const Zone& z : zones)
            out += "--- mocapd base " + std::to_string(z.base) + " ---\n" + z.daemon->log();
        return out;
    };

    // The 1000 host's pose service: Hello names subject 1001 (and only the zone's ids), and
    // subject 1001 is calibrated with the control token.
    client::PoseClient pc;
    std::string err;
    ASSERT_TRUE(pc.connect("127.0.0.1", zones[1].pose_port, 5s, err)) << err;
    std::vector<std::uint32_t> hello_ids;
    for (const auto& s : pc.hello().subjects())
        hello_ids.push_back(s.id());
    EXPECT_EQ(hello_ids, (std::vector<std::uint32_t>{1001, 1002, 1003, 1004}));
    client::SubscribeOptions o;
    o.subject_ids = {1001};
    ASSERT_TRUE(pc.subscribe(o, 5s, err)) << err;
    // A second of frames first (the filters settle), as the calibration tests do.
    v1::SkeletonFrame f;
    for (int i = 0; i < 100; ++i) {
        ASSERT_EQ(pc.next_frame(f, 10s), client::ReadStatus::kMessage) << logs();
        ASSERT_EQ(f.subject_id(), 1001u);
    }
    v1::ControlRequest req;
    req.set_token(kToken);
    req.mutable_calibrate()->set_subject_id(1001);
    req.mutable_calibrate()->set_pose(v1::POSE_T);
    v1::ControlReply reply;
    ASSERT_TRUE(pc.control(req, reply, 5s, err)) << err;
    EXPECT_TRUE(reply.ok()) << reply.error();
    req.mutable_calibrate()->set_subject_id(1);  // the other zone's subject: not served here
    ASSERT_TRUE(pc.control(req, reply, 5s, err)) << err;
    EXPECT_FALSE(reply.ok());
    EXPECT_NE(reply.error().find("unknown subject 1"), std::string::npos) << reply.error();
    EXPECT_EQ(wait_stats_counter(
                  zones[1].pose_port, "skeleton.calibrations_ok", [](auto v) { return v >= 1; }, 15s),
              1u)
        << logs();

    // One subscriber to the site: both zones' subjects, payloads carrying the same ids.
    std::map<std::uint32_t, std::uint64_t> frames;
    for (const auto end = Clock::now() + 20s; Clock::now() < end && (frames[1] < 100 || frames[1001] < 100);) {
        auto m = poses.next(1000ms);
        if (!m) continue;
        const v1::SkeletonFrame pf = decode_pose_payload(m->second);
        EXPECT_EQ(m->first, std::string("mocap.") + kZoneSite + "." + std::to_string(pf.subject_id()) + ".pose");
        ++frames[pf.subject_id()];
    }
    EXPECT_GE(frames[1], 100u) << logs();
    EXPECT_GE(frames[1001], 100u) << logs();
    for (const auto& [id, n] : frames)
        EXPECT_TRUE(id == 1 || id == 1001) << "subject " << id << ": " << n << " frames";
    std::set<std::string> raw_subjects;
    for (const auto end = Clock::now() + 10s; Clock::now() < end && raw_subjects.size() < 2;) {
        if (auto m = raw.next(1000ms)) raw_subjects.insert(m->first);
    }
    EXPECT_EQ(raw_subjects, (std::set<std::string>{"mocap.zones.1.raw", "mocap.zones.1001.raw"}));
    // The calibration is shared under the subject's site-wide id.
    std::optional<std::pair<std::string, std::string>> put;
    for (const auto end = Clock::now() + 10s; Clock::now() < end && !put;)
        put = bucket.next(1000ms);
    ASSERT_TRUE(put) << logs();
    EXPECT_EQ(put->first, "$KV.mocap_calibration.zones.1001");

    for (Zone& z : zones) {
        z.sim->stop();
        EXPECT_EQ(z.daemon->stop(10s), 0) << "base " << z.base << " must exit 0 on SIGTERM";
    }
}

TEST(ClusterConfig, AnonymousIsRefusedAtCheckAndStartUnlessAllowed) {
    TempDir dir;
    const std::uint16_t port = free_port();  // nothing listens: nothing must be needed to refuse
    HostConfig h{.sink_port = free_port(), .pose_port = free_port(), .calibration_dir = dir.path().string()};
    h.cluster = cluster_section(port, "");
    write_file(dir.file("anon.toml"), daemon_config(h));
    Process check({MOCAPD_BIN, "--check-config", dir.file("anon.toml")}, dir.file("check.log"));
    EXPECT_NE(check.wait(10s).value_or(0), 0);
    EXPECT_NE(check.log().find("cluster.nats_url: set credentials"), std::string::npos) << check.log();
    Process start({MOCAPD_BIN, "--config", dir.file("anon.toml")}, dir.file("start.log"));
    EXPECT_NE(start.wait(10s).value_or(0), 0) << "mocapd must refuse to start";
    EXPECT_NE(start.log().find("allow_anonymous"), std::string::npos) << start.log();

    // allow_anonymous = true passes, and an unreachable cluster does not stop the daemon.
    h.cluster = cluster_section(port, "allow_anonymous = true\n");
    write_file(dir.file("ok.toml"), daemon_config(h));
    Process ok({MOCAPD_BIN, "--check-config", dir.file("ok.toml")}, dir.file("ok.log"));
    EXPECT_EQ(ok.wait(10s).value_or(-1), 0) << ok.log();
}

}  // namespace
}  // namespace mocap::itest
