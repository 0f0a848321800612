// A site on a real three-server NATS cluster (docs/cluster.md): three nats-server processes
// run on the shipped config/nats/nats-server.conf (its users, permissions and JetStream; only
// what must differ on one machine is given on the command line: names, loopback ports, routes,
// the JetStream directory), routed into one cluster, and two mocapd hosts as its `mocapd`
// user, each fed by its own simulated sinks (sink ids 1-2 and 3-4), both publishing through
// server 0. A subscriber (the `viewer` user) on another server sees every subject of the site
// in one stream; each host's calibrations reach the other through the bucket with no
// permission refused; killing server 0 moves both hosts to the servers they learned from it,
// and each subscriber loses at most a second of frames.
#include <gtest/gtest.h>
#include <nats/nats.h>

#include <atomic>
#include <csignal>
#include <filesystem>
#include <iostream>
#include <map>
#include <mutex>
#include <set>
#include <sstream>
#include <thread>

#include "harness.hpp"
#include "nats_harness.hpp"

namespace mocap::itest {
namespace {

using namespace std::chrono_literals;

// The shipped config's users and site.
constexpr const char* kUser = "mocapd";
constexpr const char* kPassword = "change-me-mocapd";
constexpr const char* kViewer = "viewer";
constexpr const char* kViewerPassword = "change-me-viewer";
constexpr const char* kSite = "venue";
constexpr const char* kShippedStoreDir = "store_dir: /var/lib/nats/jetstream";
constexpr int kRateHz = 100;

/// Every pose frame one subscriber gets, per subject, from a thread of its own.
class Collector {
public:
    Collector(std::uint16_t port, const std::string& subject)
        : sub_(port, subject, kViewer, kViewerPassword), thread_([this] { run(); }) {}
    ~Collector() { stop(); }
    Collector(const Collector&) = delete;
    Collector& operator=(const Collector&) = delete;

    void stop() {
        stop_ = true;
        if (thread_.joinable()) thread_.join();
    }
    /// SYNCs received per subject so far.
    std::map<std::uint32_t, std::vector<std::uint64_t>> syncs() {
        const std::lock_guard<std::mutex> lock(mutex_);
        return syncs_;
    }
    /// True once every subject in `subjects` has a frame with SYNC above its `after` entry
    /// (0 when absent) and at least `n` frames in all.
    bool each_has(const std::set<std::uint32_t>& subjects, std::size_t n,
                  const std::map<std::uint32_t, std::uint64_t>& after = {}) {
        const std::lock_guard<std::mutex> lock(mutex_);
        for (std::uint32_t s : subjects) {
            const auto it = syncs_.find(s);
            if (it == syncs_.end() || it->second.size() < n) return false;
            const auto a = after.find(s);
            if (a != after.end() && it->second.back() <= a->second) return false;
        }
        return true;
    }

private:
    void run() {
        while (!stop_) {
            auto m = sub_.next(200ms);
            if (!m) continue;
            const v1::SkeletonFrame f = decode_pose_payload(m->second);
            EXPECT_EQ(m->first, std::string("mocap.") + kSite + "." + std::to_string(f.subject_id()) + ".pose");
            EXPECT_EQ(f.segment_count(), 15u);
            const std::lock_guard<std::mutex> lock(mutex_);
            syncs_[f.subject_id()].push_back(f.sync());
        }
    }

    NatsSubscriber sub_;
    std::mutex mutex_;
    std::map<std::uint32_t, std::vector<std::uint64_t>> syncs_;
    std::atomic<bool> stop_{false};
    std::thread thread_;
};

/// The largest number of frames one SYNC jump skipped, and whether SYNC only grew.
std::pair<std::uint64_t, bool> largest_gap(const std::vector<std::uint64_t>& v) {
    std::uint64_t worst = 0;
    bool increasing = true;
    for (std::size_t i = 1; i < v.size(); ++i) {
        if (v[i] <= v[i - 1]) {
            increasing = false;
            continue;
        }
        worst = std::max(worst, v[i] - v[i - 1] - 1);
    }
    return {worst, increasing};
}

class ThreeServerCluster : public ::testing::Test {
protected:
    struct Host {
        std::uint16_t sink_port = 0, pose_port = 0;
        std::unique_ptr<Process> daemon, sim;
    };

    void SetUp() override {
        if (!have_nats_server())
            GTEST_SKIP() << "no nats-server binary at " << nats_server_bin() << " (setup.sh installs it)";
        for (int i = 0; i < 3; ++i) {
            client_ports_[i] = free_port();
            route_ports_[i] = free_port();
        }
        const std::string shipped = read_file(NATS_SHIPPED_CONFIG);
        const auto store = shipped.find(kShippedStoreDir);
        ASSERT_NE(store, std::string::npos) << "the shipped config's JetStream store_dir moved";
        for (int i = 0; i < 3; ++i) {
            const std::string name = "nats" + std::to_string(i);
            // nats-server refuses -sd beside a store_dir in the file: the one line is replaced.
            std::string conf = shipped;
            conf.replace(store, std::string(kShippedStoreDir).size(), "store_dir: \"" + dir_.file(name + ".js") + "\"");
            write_file(dir_.file(name + ".conf"), conf);
            std::vector<std::string> routes;
            for (int j = 0; j < 3; ++j)
                if (j != i) routes.push_back("nats://127.0.0.1:" + std::to_string(route_ports_[j]));
            servers_[i] = std::make_unique<Process>(
                std::vector<std::string>{
                    nats_server_bin(), "-c", dir_.file(name + ".conf"), "-n", name, "-a", "127.0.0.1", "-p",
                    std::to_string(client_ports_[i]), "-m", std::to_string(free_port()), "--cluster",
                    "nats://127.0.0.1:" + std::to_string(route_ports_[i]), "--routes", routes[0] + "," + routes[1]},
                dir_.file(name + ".log"));
            ASSERT_TRUE(wait_for_port(client_ports_[i], 15s)) << servers_[i]->log();
        }
        ASSERT_TRUE(routed(0, 1) && routed(0, 2)) << "the three servers did not form one cluster:\n"
                                                  << servers_[0]->log();
        start_host(hosts_[0], "host-a", 1);
        start_host(hosts_[1], "host-b", 3);
    }

    void TearDown() override {
        for (Host& h : hosts_) {
            if (h.sim) h.sim->stop();
            if (!h.daemon) continue;
            if (HasFailure()) std::cerr << "--- mocapd log ---\n" << h.daemon->log();
            EXPECT_EQ(h.daemon->stop(10s), 0) << "mocapd must exit 0 on SIGTERM";
        }
    }

    /// A message published on server `from` reaches a subscriber on server `to`: the routes
    /// are up and interest has propagated.
    bool routed(int from, int to) {
        const std::string probe = std::string("mocap.") + kSite + ".probe";
        NatsSubscriber sub(client_ports_[to], probe, kViewer, kViewerPassword);
        natsOptions* o = nullptr;
        natsConnection* nc = nullptr;
        natsOptions_Create(&o);
        const std::string url = "nats://127.0.0.1:" + std::to_string(client_ports_[from]);
        natsOptions_SetURL(o, url.c_str());
        natsOptions_SetUserInfo(o, kUser, kPassword);
        const bool connected = natsConnection_Connect(&nc, o) == NATS_OK;
        natsOptions_Destroy(o);
        bool got = false;
        for (auto end = std::chrono::steady_clock::now() + 30s;
             connected && !got && std::chrono::steady_clock::now() < end;) {
            natsConnection_PublishString(nc, probe.c_str(), "ping");
            natsConnection_FlushTimeout(nc, 2000);
            got = sub.next(200ms).has_value();
        }
        natsConnection_Destroy(nc);
        return got;
    }

    void start_host(Host& h, const std::string& host_id, int first_sink_id) {
        h.sink_port = free_port();
        h.pose_port = free_port();
        // Each host its own calibration directory: what it saves, it made or received.
        const std::string calibrations = dir_.file(host_id + ".calibrations");
        std::filesystem::create_directories(calibrations);
        HostConfig c{.sink_port = h.sink_port, .pose_port = h.pose_port, .calibration_dir = calibrations};
        c.workers = 1;
        c.cluster = cluster_section(client_ports_[0], kSite, host_id, cluster_credentials(kUser, kPassword),
                                    kDefaultQueueFrames);
        h.daemon = start_mocapd(MOCAPD_BIN, c, dir_, host_id);
        ASSERT_FALSE(HasFailure());
        h.sim = std::make_unique<Process>(
            std::vector<std::string>{MOCAP_SIM_BIN, "stream", "--connect", "127.0.0.1:" + std::to_string(h.sink_port),
                                     "--subjects", "2", "--first-sink-id", std::to_string(first_sink_id), "--nodes",
                                     "15", "--mode", "quat", "--rate", std::to_string(kRateHz), "--duration", "90",
                                     "--sink-rate-stats"},
            dir_.file(host_id + ".sim.log"));
    }

    /// Stops both simulators (they print their stats on SIGTERM); the instants each skipped
    /// when it ran late never existed, so a subscriber's gaps may be up to that many.
    std::uint64_t stop_sims() {
        std::uint64_t skipped = 0;
        for (Host& h : hosts_) {
            h.sim->stop();
            skipped = std::max(skipped, sim_syncs_skipped(h.sim->log()).value_or(0));
        }
        return skipped;
    }

    TempDir dir_;
    std::uint16_t client_ports_[3] = {}, route_ports_[3] = {};
    std::unique_ptr<Process> servers_[3];
    Host hosts_[2];
    const std::set<std::uint32_t> subjects_{1, 2, 3, 4};
};

TEST_F(ThreeServerCluster, OneSubscriberSeesEverySubjectOfBothHostsAtItsRate) {
    Collector poses(client_ports_[2], std::string("mocap.") + kSite + ".*.pose");
    NatsSubscriber beats(client_ports_[1], std::string("mocap.") + kSite + ".host.*", kViewer, kViewerPassword);
    ASSERT_TRUE(wait_until([&] { return poses.each_has(subjects_, 3 * kRateHz); }, 60s))
        << "every subject of both hosts, 3 s of frames each, through server 2";
    const std::uint64_t skipped = stop_sims();
    poses.stop();
    for (const auto& [subject, v] : poses.syncs()) {
        EXPECT_TRUE(subjects_.count(subject)) << "unexpected subject " << subject;
        const auto [gap, increasing] = largest_gap(v);
        EXPECT_TRUE(increasing) << "subject " << subject << ": each frame once, in order";
        EXPECT_LE(gap, skipped) << "subject " << subject << ": every frame its sink sent";
    }
    std::set<std::string> hosts;
    for (auto end = std::chrono::steady_clock::now() + 15s; hosts.size() < 2 && std::chrono::steady_clock::now() < end;)
        if (auto m = beats.next(1000ms)) hosts.insert(m->first);
    EXPECT_EQ(hosts, (std::set<std::string>{std::string("mocap.") + kSite + ".host.host-a",
                                            std::string("mocap.") + kSite + ".host.host-b"}));
}

TEST_F(ThreeServerCluster, TheShippedConfigLetsEachHostsCalibrationsReachTheOther) {
    // Both hosts calibrate their two subjects from the simulators' opening T-pose
    // (auto_calibrate) and put them to the bucket; each receives the other's two.
    for (const Host& h : hosts_) {
        EXPECT_GE(wait_stats_counter(
                      h.pose_port, "calibration_kv.puts", [](auto v) { return v >= 2; }, 60s),
                  2u)
            << "each host puts its two subjects' calibrations";
    }
    for (const Host& h : hosts_) {
        EXPECT_GE(wait_stats_counter(
                      h.pose_port, "calibration_kv.received", [](auto v) { return v >= 2; }, 60s),
                  2u)
            << "each host receives the other's two calibrations";
        EXPECT_EQ(stats_counter(h.pose_port, "calibration_kv.permission_errors"), 0u);
        EXPECT_EQ(stats_counter(h.pose_port, "cluster.permission_errors"), 0u);
    }
    for (const auto& server : servers_)
        EXPECT_EQ(server->log().find("Permissions Violation"), std::string::npos) << server->log();
}

TEST_F(ThreeServerCluster, KillingTheHostsServerCostsEachSubscriberAtMostASecond) {
    Collector on1(client_ports_[1], std::string("mocap.") + kSite + ".*.pose");
    Collector on2(client_ports_[2], std::string("mocap.") + kSite + ".*.pose");
    ASSERT_TRUE(wait_until([&] { return on1.each_has(subjects_, kRateHz) && on2.each_has(subjects_, kRateHz); }, 60s));

    // Both hosts publish through server 0; it dies without a word.
    std::map<std::uint32_t, std::uint64_t> at_kill;
    for (const auto& [subject, v] : on1.syncs())
        at_kill[subject] = v.back();
    servers_[0]->signal(SIGKILL);
    ASSERT_TRUE(servers_[0]->wait(10s)) << "nats-server 0 did not die";

    // The hosts move to servers 1 and 2 (learned from server 0 when they connected) and
    // frames flow again: two more seconds of every subject on both subscribers.
    std::map<std::uint32_t, std::uint64_t> later;
    for (const auto& [subject, sync] : at_kill)
        later[subject] = sync + 2 * kRateHz;
    EXPECT_TRUE(wait_until([&] { return on1.each_has(subjects_, 0, later) && on2.each_has(subjects_, 0, later); }, 60s))
        << "frames must flow again through the other servers";
    for (const Host& h : hosts_)
        EXPECT_GE(stats_counter(h.pose_port, "cluster.reconnects"), 1u);
    const std::uint64_t skipped = stop_sims();
    on1.stop();
    on2.stop();
    std::uint64_t worst = 0;
    for (Collector* c : {&on1, &on2}) {
        for (const auto& [subject, v] : c->syncs()) {
            const auto [gap, increasing] = largest_gap(v);
            worst = std::max(worst, gap);
            EXPECT_TRUE(increasing) << "subject " << subject;
            EXPECT_LE(gap, static_cast<std::uint64_t>(kRateHz) + skipped)
                << "subject " << subject << ": at most 1 s of frames lost when a server dies";
        }
    }
    std::cout << "[ metrics  ] server killed: largest gap " << worst << " frames at " << kRateHz
              << " Hz (simulator skipped " << skipped << ")\n";
}

}  // namespace
}  // namespace mocap::itest
