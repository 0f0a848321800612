// Durable takes (docs/outputs.md, "Durable takes (JetStream)") against a real nats-server with
// JetStream on a loopback port and a store in a temporary directory: mocapd publishes every
// raw sample to the stream MOCAP_RAW, `mocapd --jetstream URL --subject N` reads the take
// back and re-solves it exactly as `mocapd --replay FILE` does a raw recording; a host killed
// mid-take loses nothing JetStream acknowledged; a cluster absent at start or lost at run time
// costs the local pose service nothing, raw samples are dropped (counted) and publishing
// resumes on its own.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <csignal>
#include <filesystem>
#include <thread>

#include "harness.hpp"
#include "mocap/v1/mocap.pb.h"
#include "nats_harness.hpp"
#include "pose_client.hpp"

namespace mocap::itest {
namespace {

using namespace std::chrono_literals;

constexpr const char* kSite = "take";
constexpr std::uint64_t kNodes = 15;  // mocap-sim's body: one sample per node per SYNC

class JetStream : public OneHostClusterTest {
protected:
    void SetUp() override {
        OneHostClusterTest::SetUp();
        if (IsSkipped()) return;
        std::filesystem::create_directories(dir_.file("rec"));
    }

    // Not the base's: some tests kill mocapd on purpose (kill -9 mid-take).
    void TearDown() override {
        if (HasFailure() && daemon_) std::cerr << "--- mocapd log ---\n" << daemon_->log();
        if (daemon_ && daemon_->running()) {
            EXPECT_EQ(daemon_->stop(15s), 0) << "mocapd must exit 0 on SIGTERM";
        }
    }

    void start_nats_js(const std::string& log) {
        nats_ = start_nats(nats_port_, dir_.file(log), {"-js", "-sd", dir_.file("js")});
    }

    /// mocapd with the raw recorder and the cluster on; `more` goes into [cluster].
    void start_daemon(const std::string& more = "") {
        HostConfig h{.sink_port = sink_port_, .pose_port = pose_port_, .calibration_dir = dir_.path().string()};
        h.ingest = "sink_idle_timeout_s = 5.0\n";
        h.serve = "client_queue_frames = 4096\n";
        h.outputs = "bvh_live = false\nraw_record = true\nrecord_dir = \"" + dir_.file("rec") + "\"\n";
        h.cluster = cluster_section(nats_port_, kSite, "rack1", cluster_credentials() + more);
        daemon_ = start_mocapd(MOCAPD_BIN, h, dir_);
        ASSERT_FALSE(HasFailure());
    }

    std::unique_ptr<Process> sim(int subjects, int seconds) {
        return stream_sim(MOCAP_SIM_BIN, sink_port_, subjects, seconds, dir_.file("sim.log"));
    }

    std::uint64_t counter(const std::string& name) { return stats_counter(pose_port_, name); }
    std::uint64_t wait_counter(const std::string& name, const std::function<bool(std::uint64_t)>& pred,
                               std::chrono::milliseconds limit) {
        return wait_stats_counter(pose_port_, name, pred, limit);
    }

    /// `mocapd --config ... ARGS`, its exit status and output (stdout and log).
    std::pair<int, std::string> replay(const std::string& name, std::vector<std::string> args) {
        std::vector<std::string> argv{MOCAPD_BIN, "--config", dir_.file("mocapd.toml")};
        argv.insert(argv.end(), args.begin(), args.end());
        Process p(argv, dir_.file(name + ".log"));
        const int rc = p.wait(120s).value_or(-1);
        return {rc, p.log()};
    }

    std::vector<std::string> jetstream_args(std::uint32_t subject) const {
        return jetstream_replay_args(nats_port_, subject);
    }
};

TEST_F(JetStream, AReplayFromJetStreamEqualsTheReplayOfTheRawFileRecordedBesideIt) {
    start_nats_js("nats.log");
    start_daemon();
    auto s = sim(2, 5);
    ASSERT_EQ(s->wait(30s).value_or(-1), 0) << s->log();
    // Everything published is acknowledged while the daemon runs (not only at its stop).
    const std::uint64_t queued = wait_counter(
        "cluster.raw_samples_queued", [](auto v) { return v >= 2 * kNodes * 400; }, 20s);
    EXPECT_GE(queued, 2 * kNodes * 400) << "~5 s of 2 subjects at 100 Hz";
    const std::uint64_t acked = wait_counter(
        "cluster.raw_samples_acked", [&](auto v) { return v >= queued; }, 30s);
    EXPECT_EQ(acked, queued);
    EXPECT_EQ(counter("cluster.raw_samples_dropped"), 0u);
    EXPECT_EQ(counter("cluster.raw_samples_failed"), 0u);
    EXPECT_EQ(daemon_->stop(15s), 0);  // the raw file is complete

    std::vector<std::string> files;
    for (const auto& e : std::filesystem::directory_iterator(dir_.file("rec")))
        if (e.path().extension() == ".mocapraw") files.push_back(e.path().string());
    std::sort(files.begin(), files.end());
    ASSERT_FALSE(files.empty());

    for (std::uint32_t subject : {1u, 2u}) {
        const std::string n = std::to_string(subject);
        std::vector<std::string> from_file{"--replay"};
        from_file.insert(from_file.end(), files.begin(), files.end());
        from_file.insert(from_file.end(), {"--subject", n});
        from_file.insert(from_file.end(), {"--bvh-subject", n, "--bvh-out", dir_.file("file" + n + ".bvh"),
                                           "--angles-out", dir_.file("file" + n + ".csv")});
        auto from_js = jetstream_args(subject);
        from_js.insert(from_js.end(), {"--bvh-subject", n, "--bvh-out", dir_.file("js" + n + ".bvh"), "--angles-out",
                                       dir_.file("js" + n + ".csv")});
        const auto [file_rc, file_log] = replay("file" + n, from_file);
        ASSERT_EQ(file_rc, 0) << file_log;
        const auto [js_rc, js_log] = replay("js" + n, from_js);
        ASSERT_EQ(js_rc, 0) << js_log;

        const auto file_samples = replayed_samples(file_log);
        ASSERT_TRUE(file_samples) << file_log;
        EXPECT_GE(*file_samples, kNodes * 400) << "subject " << subject;
        EXPECT_EQ(replayed_samples(js_log), file_samples) << js_log;
        const std::string file_csv = read_file(dir_.file("file" + n + ".csv"));
        EXPECT_GE(csv_syncs(file_csv).size(), 400u);
        EXPECT_TRUE(file_csv == read_file(dir_.file("js" + n + ".csv")))
            << "subject " << subject << ": the joint angles of both replays are identical to the last digit";
        EXPECT_TRUE(read_file(dir_.file("file" + n + ".bvh")) == read_file(dir_.file("js" + n + ".bvh")))
            << "subject " << subject << ": the BVH files of both replays are byte-identical";
    }

    // A time range selects by received time, from either source: a range before the take
    // holds nothing, one around it everything.
    auto early = jetstream_args(1);
    early.insert(early.end(), {"--from", "2001-01-01T00:00:00Z", "--to", "1000000000.5"});
    const auto [early_rc, early_log] = replay("early", early);
    EXPECT_EQ(early_rc, 0) << early_log;
    EXPECT_EQ(replayed_samples(early_log), 0u) << early_log;
    auto around = jetstream_args(1);
    around.insert(around.end(), {"--from", "2020-01-01T01:00:00+01:00", "--to", "4102444800"});
    const auto [around_rc, around_log] = replay("around", around);
    EXPECT_EQ(around_rc, 0) << around_log;
    EXPECT_EQ(replayed_samples(around_log), replayed_samples(read_file(dir_.file("js1.log")))) << around_log;

    // A subject with no take is a clear error.
    const auto [none_rc, none_log] = replay("none", jetstream_args(3));
    EXPECT_NE(none_rc, 0);
    EXPECT_NE(none_log.find("no raw samples on mocap.take.3.raw"), std::string::npos) << none_log;
}

TEST_F(JetStream, AHostKilledMidTakeLosesNothingJetStreamAcknowledged) {
    start_nats_js("nats.log");
    start_daemon();
    auto s = sim(1, 60);
    wait_counter(
        "cluster.raw_samples_acked", [](auto v) { return v >= 3 * kNodes * 100; }, 30s);
    const std::uint64_t acked = counter("cluster.raw_samples_acked");
    ASSERT_GE(acked, 3 * kNodes * 100) << "~3 s acknowledged";
    daemon_->signal(SIGKILL);
    ASSERT_TRUE(daemon_->wait(10s)) << "mocapd did not die";
    s->stop();

    auto args = jetstream_args(1);
    args.insert(args.end(), {"--angles-out", dir_.file("killed.csv")});
    const auto [rc, log] = replay("killed", args);
    ASSERT_EQ(rc, 0) << log;
    const auto samples = replayed_samples(log);
    ASSERT_TRUE(samples) << log;
    EXPECT_GE(*samples, acked) << "every acknowledged sample is in the take";
    // The take is whole up to its end: every SYNC from the first, every node of each.
    const auto syncs = csv_syncs(read_file(dir_.file("killed.csv")));
    ASSERT_GE(syncs.size(), acked / kNodes);
    std::uint64_t gaps = 0;
    for (std::size_t i = 1; i < syncs.size(); ++i) {
        ASSERT_GT(syncs[i], syncs[i - 1]);
        gaps += syncs[i] - syncs[i - 1] - 1;
    }
    EXPECT_LE(gaps, sim_syncs_skipped(s->log()).value_or(0)) << "no frame missing but what the sink never sent";
    EXPECT_GE(*samples, (syncs.size() - 1) * kNodes) << "every frame but the last is complete";
}

TEST_F(JetStream, NoClusterAtStartAndALostClusterCostThePoseServiceNothingAndPublishingResumes) {
    // A small raw queue: drops show within a second of samples.
    start_daemon("raw_queue_samples = 1500\n");
    client::PoseClient pose;
    std::string err;
    ASSERT_TRUE(pose.connect("127.0.0.1", pose_port_, 5s, err)) << err;
    ASSERT_TRUE(pose.subscribe({.subject_ids = {1}}, 5s, err)) << err;
    std::atomic<bool> stop_reading{false};
    std::atomic<std::uint64_t> pose_frames{0};
    std::thread reader([&] {
        v1::SkeletonFrame f;
        while (!stop_reading.load()) {
            if (pose.next_frame(f, 200ms) == client::ReadStatus::kMessage) pose_frames.fetch_add(1);
        }
    });
    auto frames_flow = [&](const char* when) {
        const std::uint64_t before = pose_frames.load();
        EXPECT_TRUE(wait_until([&] { return pose_frames.load() >= before + 100; }, 15s))
            << "the pose service serves " << when;
    };
    auto s = sim(1, 90);

    // No server: the pose service serves, raw samples are dropped oldest first and counted.
    frames_flow("with no cluster at start");
    EXPECT_GE(wait_counter(
                  "cluster.raw_samples_dropped", [](auto v) { return v >= 1; }, 20s),
              1u);
    EXPECT_EQ(counter("cluster.raw_messages_sent"), 0u);

    // The server appears: the publisher connects, creates the stream and publishes.
    start_nats_js("nats1.log");
    EXPECT_GE(wait_counter(
                  "cluster.raw_samples_acked", [](auto v) { return v >= 2 * kNodes * 100; }, 30s),
              2 * kNodes * 100);

    // Lost at run time: counted, dropped, the pose service goes on.
    nats_->signal(SIGKILL);
    ASSERT_TRUE(nats_->wait(10s)) << "nats-server did not die";
    EXPECT_GE(wait_counter(
                  "cluster.disconnects", [](auto v) { return v >= 1; }, 15s),
              1u);
    const std::uint64_t dropped = counter("cluster.raw_samples_dropped");
    frames_flow("while the cluster is lost");
    EXPECT_GE(wait_counter(
                  "cluster.raw_samples_dropped", [&](auto v) { return v >= dropped + kNodes * 100; }, 20s),
              dropped + kNodes * 100);

    // Back on the same port and store: reconnects by itself, the stream is still there.
    start_nats_js("nats2.log");
    EXPECT_GE(wait_counter(
                  "cluster.reconnects", [](auto v) { return v >= 1; }, 30s),
              1u);
    const std::uint64_t acked = counter("cluster.raw_samples_acked");
    EXPECT_GE(wait_counter(
                  "cluster.raw_samples_acked", [&](auto v) { return v >= acked + 2 * kNodes * 100; }, 30s),
              acked + 2 * kNodes * 100);
    frames_flow("after the cluster is back");
    s->stop();
    stop_reading.store(true);
    reader.join();
    EXPECT_EQ(pose.drops_announced(), 0u);

    // Every sample settles (acknowledged, dropped or failed); the take holds both stretches,
    // at least what was acknowledged.
    const std::uint64_t queued = counter("cluster.raw_samples_queued");  // final: the sink stopped
    const std::uint64_t acked_all = wait_counter(
        "cluster.raw_samples_acked",
        [&](auto v) {
            return v + counter("cluster.raw_samples_dropped") + counter("cluster.raw_samples_failed") >= queued;
        },
        30s);
    const auto [rc, log] = replay("resumed", jetstream_args(1));
    ASSERT_EQ(rc, 0) << log;
    EXPECT_GE(replayed_samples(log).value_or(0), acked_all) << log;
}

}  // namespace
}  // namespace mocap::itest
