// The real mocapd's web endpoint on loopback, fed by the real mocap-sim stream:
// /metrics names follow the Prometheus conventions for EVERY metric the daemon keeps and
// the values move under load; /healthz; the viewer's WebSocket carries real frames;
// control over HTTP with the token.
#include <gtest/gtest.h>

#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <thread>

#include "harness.hpp"
#include "http_test_client.hpp"

namespace mocap::itest {
namespace {

using namespace std::chrono_literals;
using boost::beast::http::verb;
using mocap::testing::http_request;

constexpr const char* kToken = "web-s3cret-0123456789";

struct Scrape {
    std::map<std::string, std::string> types;  // family -> counter|gauge|histogram
    std::map<std::string, double> samples;     // full series (name + labels) -> value
    std::vector<std::string> problems;
};

// Parses the text format and checks the naming rules on every line.
Scrape scrape(std::uint16_t port) {
    Scrape s;
    const auto reply = http_request(port, "/metrics");
    if (reply.status != 200) {
        s.problems.push_back("status " + std::to_string(reply.status));
        return s;
    }
    const std::regex name_re("^mocapd_[a-z0-9_]+$");
    std::set<std::string> helps;
    std::istringstream in(reply.body);
    for (std::string line; std::getline(in, line);) {
        std::istringstream ls(line);
        if (line.rfind("# HELP ", 0) == 0) {
            std::string a, b, name;
            ls >> a >> b >> name;
            helps.insert(name);
            continue;
        }
        if (line.rfind("# TYPE ", 0) == 0) {
            std::string a, b, name, type;
            ls >> a >> b >> name >> type;
            if (!helps.count(name)) s.problems.push_back("no HELP before TYPE: " + name);
            if (!std::regex_match(name, name_re)) s.problems.push_back("bad name: " + name);
            if (type == "counter" && !name.ends_with("_total")) s.problems.push_back("counter without _total: " + name);
            if (type != "counter" && name.ends_with("_total"))
                s.problems.push_back("_total on a " + type + ": " + name);
            // Units as suffixes, in base units: no µs/ms, seconds and bytes last.
            for (const char* bad : {"_us_", "_ms_", "_us", "_ms"}) {
                if (name.ends_with(bad) || name.find(std::string(bad) + "_") != std::string::npos) {
                    s.problems.push_back("non-base unit: " + name);
                }
            }
            if (name.find("_bytes_") != std::string::npos && !name.ends_with("_bytes_total")) {
                s.problems.push_back("bytes not last: " + name);
            }
            if (name.find("latency") != std::string::npos && type == "histogram" && !name.ends_with("_seconds")) {
                s.problems.push_back("latency without _seconds: " + name);
            }
            if (!s.types.emplace(name, type).second) s.problems.push_back("TYPE twice: " + name);
            continue;
        }
        const std::size_t space = line.rfind(' ');
        const std::string series = line.substr(0, space);
        const std::string name = series.substr(0, series.find('{'));
        if (!std::regex_match(name, name_re)) s.problems.push_back("bad sample name: " + line);
        std::string family = name;
        for (const std::string suffix : {"_bucket", "_sum", "_count"}) {
            if (!s.types.count(family) && family.ends_with(suffix)) family.resize(family.size() - suffix.size());
        }
        if (!s.types.count(family)) s.problems.push_back("sample without TYPE: " + line);
        s.samples[series] = std::stod(line.substr(space + 1));
    }
    return s;
}

class WebEndpoint : public ::testing::Test {
protected:
    void SetUp() override {
        write_file(dir_.file("mocapd.toml"), ports_.config(dir_.path().string(), kToken));
        daemon_ = std::make_unique<Process>(std::vector<std::string>{MOCAPD_BIN, "--config", dir_.file("mocapd.toml")},
                                            dir_.file("mocapd.log"), dir_.path().string());
        ASSERT_TRUE(wait_for_port(http_port_, 10s)) << daemon_->log();
        ASSERT_TRUE(wait_for_port(sink_port_, 10s)) << daemon_->log();
    }
    void TearDown() override {
        if (sim_) sim_->stop();
        if (HasFailure()) std::cerr << "--- mocapd log ---\n" << daemon_->log();
        EXPECT_EQ(daemon_->stop(10s), 0);
    }
    void start_sim() { sim_ = std::make_unique<Process>(ports_.walk_sim(MOCAP_SIM_BIN, 60), dir_.file("sim.log")); }

    TempDir dir_;
    const WebDaemon ports_;
    const std::uint16_t sink_port_ = ports_.sink_port, pose_port_ = ports_.pose_port, http_port_ = ports_.http_port;
    std::unique_ptr<Process> daemon_;
    std::unique_ptr<Process> sim_;
};

TEST_F(WebEndpoint, MetricsFollowPrometheusConventionsAndMoveUnderLoad) {
    const Scrape idle = scrape(http_port_);
    EXPECT_TRUE(idle.problems.empty()) << ::testing::PrintToString(idle.problems);
    EXPECT_EQ(http_request(http_port_, "/healthz").body, "ok\n");

    start_sim();
    std::this_thread::sleep_for(1500ms);
    const Scrape a = scrape(http_port_);
    std::this_thread::sleep_for(1500ms);
    const Scrape b = scrape(http_port_);
    EXPECT_TRUE(a.problems.empty()) << ::testing::PrintToString(a.problems);
    EXPECT_TRUE(b.problems.empty()) << ::testing::PrintToString(b.problems);

    // Every counter the daemon keeps is there (components of the whole pipeline).
    for (const char* family :
         {"mocapd_route_samples_routed_total", "mocapd_ingest_tcp_packets_total", "mocapd_serve_frames_published_total",
          "mocapd_serve_sent_bytes_total", "mocapd_http_requests_total", "mocapd_stage_latency_seconds",
          "mocapd_pose_clients", "mocapd_subjects_active", "mocapd_sinks_connected"}) {
        EXPECT_TRUE(b.types.count(family)) << family;
    }
    // Under load, counters and latency counts increase between two scrapes.
    for (const char* series :
         {"mocapd_route_samples_routed_total", "mocapd_ingest_tcp_packets_total", "mocapd_serve_frames_published_total",
          "mocapd_stage_latency_seconds_count{stage=\"filter\"}",
          "mocapd_stage_latency_seconds_count{stage=\"assembly\"}",
          "mocapd_stage_latency_seconds_count{stage=\"ingest\"}"}) {
        ASSERT_TRUE(a.samples.count(series) && b.samples.count(series)) << series;
        EXPECT_GT(b.samples.at(series), a.samples.at(series)) << series;
    }
    EXPECT_GT(b.samples.at("mocapd_route_samples_routed_total") - a.samples.at("mocapd_route_samples_routed_total"),
              15 * 100 * 1.0)
        << "15 nodes at 100 Hz for 1.5 s";
    EXPECT_EQ(b.samples.at("mocapd_subjects_active"), 1.0);
    EXPECT_EQ(b.samples.at("mocapd_sinks_connected"), 1.0);
    EXPECT_GE(b.samples.at("mocapd_http_metrics_scrapes_total"), 3.0);

    const auto health = http_request(http_port_, "/healthz");
    EXPECT_EQ(health.status, 200u);
    EXPECT_EQ(health.body, "ok\n");
}

TEST_F(WebEndpoint, WebSocketCarriesRealFramesAndControlNeedsToken) {
    start_sim();
    mocap::testing::WsTestClient ws;
    ASSERT_TRUE(ws.connect(http_port_, "/ws?subject=1"));
    const auto hello = ws.read();
    ASSERT_TRUE(hello);
    EXPECT_NE(hello->find("\"name\":\"pelvis\",\"parent\":-1"), std::string::npos) << *hello;
    int frames = 0;
    std::int64_t last_sync = -1;
    while (frames < 50) {
        const auto m = ws.read();
        ASSERT_TRUE(m) << "no frame within 5 s";
        if (m->find("\"type\":\"frame\"") == std::string::npos) continue;
        const auto at = m->find("\"sync\":");
        const std::int64_t sync = std::stoll(m->substr(at + 7));
        EXPECT_GT(sync, last_sync);
        last_sync = sync;
        EXPECT_NE(m->find("\"subject\":1,"), std::string::npos);
        ++frames;
    }
    const std::map<std::string, std::string> token{{"X-Mocap-Token", kToken}};
    EXPECT_EQ(http_request(http_port_, "/api/record/start", verb::post).status, 401u);
    EXPECT_EQ(http_request(http_port_, "/api/record/start", verb::post, token).status, 200u);
    std::this_thread::sleep_for(300ms);
    EXPECT_EQ(http_request(http_port_, "/api/record/stop", verb::post, token).status, 200u);
    EXPECT_EQ(http_request(http_port_, "/api/calibrate?subject=1&pose=t", verb::post, token).status, 200u);
}

}  // namespace
}  // namespace mocap::itest
