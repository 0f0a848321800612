// Prometheus naming and text format of /metrics (prometheus_text.hpp).
#include "serve/prometheus_text.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <map>
#include <regex>
#include <set>
#include <sstream>

namespace mocap::serve {
namespace {

std::string name_of(std::string_view dotted) {
    double divisor = 0;
    return prometheus_counter_name(dotted, &divisor);
}

TEST(PrometheusText, CounterNamesFollowConventions) {
    EXPECT_EQ(name_of("serve.frames_sent"), "mocapd_serve_frames_sent_total");
    EXPECT_EQ(name_of("bvh_live.frames_dropped"), "mocapd_bvh_live_frames_dropped_total");
    EXPECT_EQ(name_of("serve.bytes_sent"), "mocapd_serve_sent_bytes_total");  // unit last
    EXPECT_EQ(name_of("ingest_tcp.bytes"), "mocapd_ingest_tcp_bytes_total");
    EXPECT_EQ(name_of("Pool.Samples-Dropped"), "mocapd_pool_samples_dropped_total");
    EXPECT_EQ(name_of("x.dropped_total"), "mocapd_x_dropped_total");  // no _total_total
    double divisor = 0;
    EXPECT_EQ(prometheus_counter_name("worker.stall_us", &divisor), "mocapd_worker_stall_seconds_total");
    EXPECT_DOUBLE_EQ(divisor, 1e6);
    EXPECT_EQ(prometheus_counter_name("a.wait_ms_sum", &divisor), "mocapd_a_wait_sum_seconds_total");
    EXPECT_DOUBLE_EQ(divisor, 1e3);
}

TEST(PrometheusText, FamiliesHaveHelpTypeAndValidNames) {
    MetricsSnapshot m;
    m.counters = {{"serve.frames_sent", 7},
                  {"route.samples_routed", 9},
                  {"worker.stall_us", 2'500'000},
                  {"ingest_tcp.sink1.packets", 2},
                  {"ingest_tcp.sink1.packets", 3}};
    m.gauges = {{"http_ws_clients", "open WebSockets", 2}};
    LatencyValue l;
    l.stage = "filter";
    LatencyHistogram h;
    for (int v : {3, 40, 100, 900, 4'000, 2'000'000})
        h.record(v);
    h.record(-5);
    l.snapshot = h.snapshot();
    m.latencies.push_back(l);
    const std::string text = render_prometheus(m);

    EXPECT_NE(text.find("mocapd_serve_frames_sent_total 7\n"), std::string::npos) << text;
    EXPECT_NE(text.find("mocapd_worker_stall_seconds_total 2.5\n"), std::string::npos) << text;
    EXPECT_NE(text.find("mocapd_ingest_tcp_sink1_packets_total 5\n"), std::string::npos) << text;  // merged
    EXPECT_NE(text.find("mocapd_http_ws_clients 2\n"), std::string::npos) << text;
    EXPECT_NE(text.find("# TYPE mocapd_stage_latency_seconds histogram\n"), std::string::npos);
    EXPECT_NE(text.find("mocapd_stage_latency_seconds_bucket{stage=\"filter\",le=\"5e-05\"} 2\n"), std::string::npos)
        << text;
    EXPECT_NE(text.find("mocapd_stage_latency_seconds_bucket{stage=\"filter\",le=\"0.001\"} 4\n"), std::string::npos)
        << text;
    EXPECT_NE(text.find("mocapd_stage_latency_seconds_bucket{stage=\"filter\",le=\"1\"} 5\n"), std::string::npos);
    EXPECT_NE(text.find("mocapd_stage_latency_seconds_bucket{stage=\"filter\",le=\"+Inf\"} 6\n"), std::string::npos);
    EXPECT_NE(text.find("mocapd_stage_latency_seconds_count{stage=\"filter\"} 6\n"), std::string::npos);
    EXPECT_NE(text.find("mocapd_stage_latency_seconds_sum{stage=\"filter\"} 2.005043\n"), std::string::npos) << text;
    EXPECT_NE(text.find("mocapd_stage_latency_negative_total{stage=\"filter\"} 1\n"), std::string::npos);

    // Every sample belongs to a family declared once with HELP and TYPE; names are valid;
    // counters end in _total.
    const std::regex name_re("^mocapd_[a-z0-9_]+$");
    std::map<std::string, std::string> types;
    std::set<std::string> helps;
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);) {
        ASSERT_FALSE(line.empty());
        std::istringstream ls(line);
        if (line.rfind("# HELP ", 0) == 0) {
            std::string hash, help, name;
            ls >> hash >> help >> name;
            EXPECT_TRUE(helps.insert(name).second) << "HELP twice: " << name;
        } else if (line.rfind("# TYPE ", 0) == 0) {
            std::string hash, type, name, kind;
            ls >> hash >> type >> name >> kind;
            EXPECT_TRUE(helps.count(name)) << "TYPE before HELP: " << name;
            EXPECT_TRUE(types.emplace(name, kind).second) << "TYPE twice: " << name;
            EXPECT_TRUE(std::regex_match(name, name_re)) << name;
            if (kind == "counter") {
                EXPECT_TRUE(name.ends_with("_total")) << name;
            }
        } else {
            const std::string sample = line.substr(0, line.find_first_of("{ "));
            EXPECT_TRUE(std::regex_match(sample, name_re)) << sample;
            std::string family = sample;
            for (const char* suffix : {"_bucket", "_sum", "_count"}) {
                if (!types.count(family) && family.ends_with(suffix)) family.resize(family.size() - strlen(suffix));
            }
            EXPECT_TRUE(types.count(family)) << "sample without TYPE: " << line;
        }
    }
    EXPECT_EQ(types.size(), helps.size());
}

}  // namespace
}  // namespace mocap::serve
