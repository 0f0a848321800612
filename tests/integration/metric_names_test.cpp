// The complete set of metric names mocapd publishes, pinned against a committed golden list
// (metric_names.golden): every Prometheus family with its type and every series of /metrics,
// every Stats counter and latency stage, and the keys the periodic log line may carry.
// Dashboards and scripts read these names, so a change must show up here as a diff.
//
// The real mocapd runs on loopback with every output that needs no hardware (pose service,
// live BVH, BVH and raw recorders, HTTP), fed by a short mocap-sim stream. SocketCAN readers
// need a CAN interface and are not started here (their counters: tests/vm).
//
// To regenerate the list after an intended change: MOCAP_WRITE_GOLDEN=1 ./metric_names_tests
// (writes the file in the source tree), then review the diff and list the change in
// docs/performance.md ("Metrics registry").
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <thread>

#include "harness.hpp"
#include "http_test_client.hpp"
#include "pose_client.hpp"

namespace mocap::itest {
namespace {

using namespace std::chrono_literals;
using mocap::testing::http_request;

// "prometheus <type> <family>" for every # TYPE line, "prometheus_series <series>" for every
// sample line (name and labels, without the value).
std::set<std::string> prometheus_names(const std::string& body) {
    std::set<std::string> out;
    std::istringstream in(body);
    for (std::string line; std::getline(in, line);) {
        if (line.rfind("# TYPE ", 0) == 0) {
            std::istringstream ls(line.substr(7));
            std::string name, type;
            ls >> name >> type;
            out.insert("prometheus " + type + " " + name);
            continue;
        }
        if (line.empty() || line[0] == '#') continue;
        out.insert("prometheus_series " + line.substr(0, line.rfind(' ')));
    }
    return out;
}

std::set<std::string> golden() {
    std::set<std::string> out;
    std::ifstream in(METRIC_NAMES_GOLDEN);
    for (std::string line; std::getline(in, line);) {
        if (!line.empty() && line[0] != '#') out.insert(line);
    }
    return out;
}

std::string diff(const std::set<std::string>& want, const std::set<std::string>& got) {
    std::string out;
    for (const auto& n : want) {
        if (!got.count(n)) out += "  missing: " + n + "\n";
    }
    for (const auto& n : got) {
        if (!want.count(n)) out += "  new:     " + n + "\n";
    }
    return out;
}

TEST(MetricNames, MatchTheGoldenListInStatsMetricsAndLog) {
    TempDir dir;
    const std::uint16_t sink_port = free_port(), pose_port = free_port(), http_port = free_port();
    std::ostringstream cfg;
    cfg << "[log]\nlevel = \"info\"\nstats_interval_s = 0.2\n"
        << "[ingest]\nsink_listen = \"127.0.0.1:" << sink_port << "\"\n"
        << "[pipeline]\nworkers = 2\nmax_subjects = 2\n"
        << "[skeleton]\ncalibration_dir = \"" << dir.path().string() << "\"\n"
        << "[serve]\npose_listen = \"127.0.0.1:" << pose_port << "\"\n"
        << "[control]\ntoken = \"names-token-0123456789\"\n"
        << "[outputs]\nbvh_live = true\nbvh_listen = \"127.0.0.1:" << free_port() << "\"\n"
        << "raw_record = true\nrecord_dir = \"" << dir.path().string() << "\"\n"
        << "[http]\nlisten = \"127.0.0.1:" << http_port
        << "\"\n"
        // The cluster output registers its metrics (poses, durable takes) whether or not a
        // server answers: nothing listens on this port.
        << "[cluster]\nnats_url = \"nats://127.0.0.1:" << free_port() << "\"\nallow_anonymous = true\n";
    write_file(dir.file("mocapd.toml"), cfg.str());
    Process daemon({MOCAPD_BIN, "--config", dir.file("mocapd.toml")}, dir.file("mocapd.log"), dir.path().string());
    ASSERT_TRUE(wait_for_port(http_port, 10s)) << daemon.log();
    ASSERT_TRUE(wait_for_port(pose_port, 10s)) << daemon.log();
    ASSERT_TRUE(wait_for_port(sink_port, 10s)) << daemon.log();

    Process sim({MOCAP_SIM_BIN, "stream", "--connect", "127.0.0.1:" + std::to_string(sink_port), "--subjects", "1",
                 "--nodes", "15", "--rate", "100", "--motion", "walk", "--duration", "3"},
                dir.file("sim.log"));

    client::PoseClient client;
    std::string err;
    ASSERT_TRUE(client.connect("127.0.0.1", pose_port, 5s, err)) << err;
    // Wait (bounded) until samples went through the pipeline, so every stage has run once.
    v1::Stats stats;
    const auto routed = [&] {
        for (const auto& c : stats.counters()) {
            if (c.name() == "route.samples_routed") return c.value();
        }
        return std::uint64_t{0};
    };
    const auto deadline = std::chrono::steady_clock::now() + 20s;
    for (;;) {
        ASSERT_TRUE(client.request_stats(stats, 5s, err)) << err;
        if (routed() >= 100 || std::chrono::steady_clock::now() > deadline) break;
        std::this_thread::sleep_for(200ms);  // poll interval, under the per-client message rate limit
    }
    ASSERT_GE(routed(), 100u) << daemon.log();

    std::set<std::string> names;
    std::set<std::string> stats_counters;
    for (const auto& c : stats.counters()) {
        EXPECT_TRUE(stats_counters.insert(c.name()).second) << "Stats counter twice: " << c.name();
        names.insert("stats_counter " + c.name());
    }
    std::set<std::string> stages;
    for (const auto& l : stats.latencies()) {
        stages.insert(l.stage());
        names.insert("stats_latency " + l.stage());
    }
    const auto reply = http_request(http_port, "/metrics");
    ASSERT_EQ(reply.status, 200u);
    names.merge(prometheus_names(reply.body));

    // The log line: "stats: name=value ... <stage>_p99_us=N ... clients=N". Its keys are
    // Stats names (the nonzero ones), so they are checked against Stats, not the list.
    std::string line;
    const auto log_deadline = std::chrono::steady_clock::now() + 20s;
    while (line.empty() && std::chrono::steady_clock::now() < log_deadline) {
        std::istringstream log(daemon.log());
        for (std::string l; std::getline(log, l);) {
            if (l.find("stats: ") != std::string::npos && l.find("route.samples_routed=") != std::string::npos)
                line = l;
        }
        if (line.empty()) std::this_thread::sleep_for(50ms);
    }
    ASSERT_FALSE(line.empty()) << daemon.log();
    const std::regex kv("([A-Za-z0-9_.]+)=([0-9]+)");
    std::size_t keys = 0;
    for (auto it = std::sregex_iterator(line.begin(), line.end(), kv); it != std::sregex_iterator(); ++it) {
        const std::string key = (*it)[1];
        ++keys;
        if (key == "clients" || key == "cluster") continue;  // gauges: pose clients, cluster_connected
        if (key.ends_with("_p99_us") && stages.count(key.substr(0, key.size() - 7))) continue;
        EXPECT_TRUE(stats_counters.count(key)) << "log key not a Stats counter: " << key << "\n" << line;
    }
    EXPECT_GT(keys, 5u) << line;

    sim.stop();
    EXPECT_EQ(daemon.stop(10s), 0) << daemon.log();

    if (const char* w = std::getenv("MOCAP_WRITE_GOLDEN"); w != nullptr && std::string(w) == "1") {
        std::ofstream out(METRIC_NAMES_GOLDEN);
        out << "# Every metric name mocapd publishes (tests/integration/metric_names_test.cpp).\n";
        for (const auto& n : names)
            out << n << "\n";
        GTEST_SKIP() << "wrote " << METRIC_NAMES_GOLDEN;
    }
    const std::set<std::string> want = golden();
    ASSERT_FALSE(want.empty()) << "no golden list at " << METRIC_NAMES_GOLDEN;
    EXPECT_TRUE(want == names) << "metric names changed (MOCAP_WRITE_GOLDEN=1 rewrites the list):\n"
                               << diff(want, names);
}

}  // namespace
}  // namespace mocap::itest
