// The web endpoint on loopback (http_server.hpp): embedded viewer files, /metrics,
// /healthz, control with token and refusals, WebSocket poses and a stalled browser.
#include "serve/http_server.hpp"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <thread>
#include <vector>

#include "http_test_client.hpp"
#include "wait_until.hpp"

namespace mocap::serve {
namespace {

using namespace std::chrono_literals;
using boost::beast::http::verb;
using mocap::testing::http_request;
using mocap::testing::WsTestClient;

struct Fixture {
    std::atomic<bool> healthy{true};
    std::atomic<int> calibrations{0};
    std::atomic<std::uint32_t> calibrated_subject{0};
    // As in the daemon: one registry holds another component's counters and the server's own.
    Counter routed;
    CounterGroup route{"route"};
    MetricsRegistry registry;
    std::unique_ptr<HttpServer> server;

    explicit Fixture(std::string token, bool loopback_only = true, std::size_t queue = 4, std::size_t threads = 1) {
        HttpServerConfig c;
        c.bind_address = "127.0.0.1";
        c.port = 0;
        c.ws_queue_frames = queue;
        c.threads = threads;
        c.control_token = std::move(token);
        c.control_loopback_only = loopback_only;
        HttpDescription d;
        d.segments = {{"pelvis", -1, {0, 0, 0.2}}, {"trunk", 0, {0, 0, 0.5}}};
        d.subjects = {1, 2};
        HttpHandlers h;
        h.control.calibrate = [this](std::uint32_t subject, CalibrationPose) {
            calibrations++;
            calibrated_subject = subject;
            return ControlResult::success();
        };
        h.control.start_recording = [](const std::string&) { return ControlResult::failure("disk full"); };
        routed.add(42);
        route.add("samples_routed", routed);
        registry.add(route);
        h.metrics = [this] { return registry.snapshot(); };
        h.health = [this] { return HealthStatus{healthy.load(), healthy ? "ok" : "assembler thread stalled"}; };
        server = std::make_unique<HttpServer>(c, d, h);
        server->register_metrics(registry);
        std::string err;
        EXPECT_TRUE(server->start(err)) << err;
    }
    std::uint16_t port() const { return server->port(); }
};

SubjectFrame frame(std::uint32_t subject, std::uint64_t sync) {
    SubjectFrame f;
    f.subject_id = subject;
    f.sync = sync;
    f.segment_count = 2;
    f.segments[1].flags = kSegmentStale;
    f.times.sink_send_us = 1'000'000;
    return f;
}

skeleton::SkeletonPose pose(double x) {
    skeleton::SkeletonPose p;
    p.segment_count = 2;
    p.position_m[0] = {x, 0, 1};
    p.position_m[1] = {x, 0, 1.2};
    return p;
}

TEST(HttpServer, ServesEmbeddedViewer) {
    Fixture f("");
    const auto index = http_request(f.port(), "/");
    EXPECT_EQ(index.status, 200u);
    EXPECT_EQ(index.content_type, "text/html; charset=utf-8");
    EXPECT_NE(index.body.find("importmap"), std::string::npos);
    const auto js = http_request(f.port(), "/viewer.js");
    EXPECT_EQ(js.status, 200u);
    EXPECT_NE(js.body.find("OrbitControls"), std::string::npos);
    const auto three = http_request(f.port(), "/three/three.module.js");
    EXPECT_EQ(three.status, 200u) << "three.js not embedded: run npm ci in clients/viewer and reconfigure";
    EXPECT_GT(three.body.size(), 500'000u);
    EXPECT_EQ(http_request(f.port(), "/three/addons/controls/OrbitControls.js").status, 200u);
    const auto takes = http_request(f.port(), "/takes_panel.js");  // the Takes panel and its BVH parser
    EXPECT_EQ(takes.status, 200u);
    EXPECT_EQ(takes.content_type, js.content_type);
    EXPECT_NE(takes.body.find("BVHLoader"), std::string::npos);
    EXPECT_EQ(http_request(f.port(), "/three/addons/loaders/BVHLoader.js").status, 200u);
    EXPECT_EQ(http_request(f.port(), "/nope").status, 404u);
    EXPECT_EQ(http_request(f.port(), "/", verb::delete_).status, 405u);
}

TEST(HttpServer, MetricsAndHealth) {
    Fixture f("");
    const auto m = http_request(f.port(), "/metrics");
    EXPECT_EQ(m.status, 200u);
    EXPECT_EQ(m.content_type, "text/plain; version=0.0.4; charset=utf-8");
    EXPECT_NE(m.body.find("mocapd_route_samples_routed_total 42\n"), std::string::npos) << m.body;
    EXPECT_NE(m.body.find("# TYPE mocapd_http_requests_total counter\n"), std::string::npos) << m.body;
    EXPECT_NE(m.body.find("# TYPE mocapd_http_ws_clients gauge\n"), std::string::npos);

    auto h = http_request(f.port(), "/healthz");
    EXPECT_EQ(h.status, 200u);
    EXPECT_EQ(h.body, "ok\n");
    f.healthy = false;
    h = http_request(f.port(), "/healthz");
    EXPECT_EQ(h.status, 503u);
    EXPECT_EQ(h.body, "unhealthy: assembler thread stalled\n");
}

TEST(HttpServer, ControlNeedsTheToken) {
    Fixture f("s3cret");
    const std::map<std::string, std::string> good{{"X-Mocap-Token", "s3cret"}};
    EXPECT_EQ(http_request(f.port(), "/api/calibrate?subject=2&pose=t", verb::post).status, 401u);
    EXPECT_EQ(
        http_request(f.port(), "/api/calibrate?subject=2&pose=t", verb::post, {{"X-Mocap-Token", "s3cre"}}).status,
        401u);
    EXPECT_EQ(http_request(f.port(), "/api/calibrate?subject=2&pose=t", verb::get, good).status, 405u);
    EXPECT_EQ(f.calibrations.load(), 0);
    const auto ok = http_request(f.port(), "/api/calibrate?subject=2&pose=t", verb::post, good);
    EXPECT_EQ(ok.status, 200u);
    EXPECT_EQ(ok.body, "{\"ok\":true,\"error\":\"\"}\n");
    EXPECT_EQ(f.calibrations.load(), 1);
    EXPECT_EQ(f.calibrated_subject.load(), 2u);
    EXPECT_EQ(http_request(f.port(), "/api/calibrate?subject=x", verb::post, good).status, 400u);
    const auto failed = http_request(f.port(), "/api/record/start", verb::post, good);
    EXPECT_EQ(failed.status, 409u);
    EXPECT_EQ(failed.body, "{\"ok\":false,\"error\":\"disk full\"}\n");
    EXPECT_EQ(http_request(f.port(), "/api/record/stop", verb::post, good).status, 501u);  // no handler
    EXPECT_EQ(f.server->counters().control.refused_no_token.value(), 1u);
    EXPECT_EQ(f.server->counters().control.refused_bad_token.value(), 1u);
    EXPECT_EQ(f.server->counters().control.ok.value(), 1u);
    EXPECT_EQ(f.server->counters().control.failed.value(), 1u);
}

TEST(HttpServer, ControlRefusedWithoutConfiguredToken) {
    Fixture f("");
    EXPECT_EQ(http_request(f.port(), "/api/record/stop", verb::post, {{"X-Mocap-Token", ""}}).status, 403u);
    EXPECT_EQ(f.server->counters().control.refused_disabled.value(), 1u);
}

TEST(HttpServer, WebSocketStreamsTheChosenSubject) {
    Fixture f("");
    WsTestClient ws;
    ASSERT_TRUE(ws.connect(f.port(), "/ws?subject=2"));
    const auto hello = ws.read();
    ASSERT_TRUE(hello);
    EXPECT_NE(hello->find("\"type\":\"hello\",\"subject\":2,\"subjects\":[1,2]"), std::string::npos) << *hello;
    // Parsed, not compared as text: numbers may print as 0.5 or 0.5000.
    const auto hello_json = nlohmann::json::parse(*hello);
    EXPECT_EQ(hello_json["segments"][1], nlohmann::json::parse(R"({"name":"trunk","parent":0,"end_m":[0,0,0.5]})"))
        << *hello;
    ASSERT_TRUE(wait_until([&] { return f.server->ws_client_count() == 1; }));
    f.server->publish(frame(1, 10), pose(9.0));  // another subject: not sent
    f.server->publish(frame(2, 11), pose(0.5));
    const auto m = ws.read();
    ASSERT_TRUE(m);
    EXPECT_NE(m->find("\"type\":\"frame\",\"subject\":2,\"sync\":11,"), std::string::npos) << *m;
    EXPECT_NE(m->find("\"sink_send_us\":1000000,"), std::string::npos) << *m;
    const auto frame_json = nlohmann::json::parse(*m);
    EXPECT_EQ(frame_json["pos"], nlohmann::json::parse("[0.5,0,1,0.5,0,1.2]")) << *m;
    ASSERT_EQ(frame_json["q"].size(), 8u) << *m;
    EXPECT_EQ(frame_json["q"][0], 1.0) << *m;
    EXPECT_EQ(frame_json["q"][4], 1.0) << *m;
    EXPECT_EQ(frame_json["flags"], nlohmann::json::parse("[2,1]")) << *m;  // never seen, stale
    EXPECT_EQ(m->back(), '}');
    EXPECT_EQ(f.server->active_subjects(10'000'000), 2u);
}

TEST(HttpServer, StalledBrowserDropsOldestAndOthersKeepUp) {
    Fixture f("", true, 4);
    WsTestClient stalled, reader;
    ASSERT_TRUE(stalled.connect(f.port(), "/ws?subject=1"));
    ASSERT_TRUE(reader.connect(f.port(), "/ws?subject=1"));
    ASSERT_TRUE(reader.read());  // hello
    ASSERT_TRUE(wait_until([&] { return f.server->ws_client_count() == 2; }));
    // ~2 KB frames (32 segments): 12 MB fill the stalled client's kernel buffers, then
    // its queue drops.
    SubjectFrame big_frame = frame(1, 0);
    big_frame.segment_count = kMaxSegments;
    skeleton::SkeletonPose big = pose(1.0);
    big.segment_count = kMaxSegments;
    constexpr int kFrames = 6000;
    int received = 0;
    for (int i = 0; i < kFrames; ++i) {
        big_frame.sync = static_cast<std::uint64_t>(i);
        f.server->publish(big_frame, big);
        // A browser that keeps up: after every 3 frames (below its queue of 4, so its own
        // queue never has to drop) it reads everything up to the last one sent.
        if (i % 3 == 2 || i == kFrames - 1) {
            while (const auto m = reader.read(2000ms)) {
                if (m->find("\"type\":\"frame\"") != std::string::npos) ++received;
                if (m->find("\"sync\":" + std::to_string(i) + ",") != std::string::npos) break;
            }
        }
    }
    EXPECT_EQ(received, kFrames) << "the reading browser must not lose a frame to the stalled one";
    EXPECT_TRUE(wait_until([&] { return f.server->counters().ws_frames_dropped.value() > 0; }))
        << "the stalled browser's queue must drop its oldest frames";
    EXPECT_EQ(f.server->counters().ws_backlog_dropped.value(), 0u);
}

TEST(HttpServer, WebSocketsOnSeveralServeThreadsEachGetEveryFrameInOrder) {
    constexpr std::size_t kThreads = 2;
    constexpr std::size_t kClients = 4;
    constexpr int kFrames = 200;
    // Queues hold every frame: a browser that reads late must still see them all.
    Fixture f("", true, kFrames + 16, kThreads);
    std::vector<std::unique_ptr<WsTestClient>> clients;
    for (std::size_t i = 0; i < kClients; ++i) {
        clients.push_back(std::make_unique<WsTestClient>());
        ASSERT_TRUE(clients.back()->connect(f.port(), "/ws?subject=1"));
        ASSERT_TRUE(clients.back()->read());  // hello
    }
    ASSERT_TRUE(wait_until([&] { return f.server->ws_client_count() == kClients; }));
    for (std::size_t lane = 0; lane < kThreads; ++lane)
        EXPECT_EQ(f.server->lane_client_count(lane), kClients / kThreads) << "round-robin over the lanes";
    for (int i = 0; i < kFrames; ++i)
        f.server->publish(frame(1, static_cast<std::uint64_t>(i)), pose(0.01 * i));
    for (auto& client : clients) {
        for (int i = 0; i < kFrames; ++i) {
            const auto m = client->read(5000ms);
            ASSERT_TRUE(m) << "frame " << i;
            ASSERT_NE(m->find("\"type\":\"frame\",\"subject\":1,\"sync\":" + std::to_string(i) + ","),
                      std::string::npos)
                << "every frame, in order, no gaps: " << *m;
        }
    }
    // Encoded once per frame, however many threads and browsers.
    EXPECT_EQ(f.server->counters().ws_frames_encoded.value(), static_cast<std::uint64_t>(kFrames));
    EXPECT_TRUE(wait_until([&] { return f.server->counters().ws_frames_sent.value() == kFrames * kClients; }));
    EXPECT_EQ(f.server->counters().ws_frames_dropped.value(), 0u);
    EXPECT_EQ(f.server->counters().ws_backlog_dropped.value(), 0u);

    // stop() with every browser connected: each lane closes its own, the threads join.
    f.server->stop();
    EXPECT_EQ(f.server->client_count(), 0u);
    EXPECT_EQ(f.server->ws_client_count(), 0u);
    for (auto& client : clients)
        EXPECT_FALSE(client->read(5000ms)) << "closed";
}

}  // namespace
}  // namespace mocap::serve
