// The load client against an in-process server: counts frames per client, finds a
// SYNC gap the test makes on purpose, reports no drops for fast clients, and measures
// latency from the frames' sink_send_us.
#include "load_client.hpp"

#include <gtest/gtest.h>

#include <future>
#include <thread>

#include "pose_client.hpp"
#include "serve/pose_server.hpp"

namespace mocap::serve {
namespace {

using namespace std::chrono_literals;

TEST(LoadClient, CountsFramesGapsAndLatency) {
    ServeConfig config;
    config.bind_address = "127.0.0.1";
    config.port = 0;
    PoseServer server(config);
    std::string error;
    ASSERT_TRUE(server.start(error)) << error;

    constexpr std::size_t kClients = 6;
    client::LoadOptions options;
    options.port = server.port();
    options.clients = kClients;
    options.duration = 1500ms;
    options.subject_ids = {3};
    options.stalled = 1;  // subscribed, never read: must not disturb the measured clients
    auto run = std::async(std::launch::async, [&] { return client::run_load(options); });

    // Publish only once every load connection has subscribed.
    const auto deadline = std::chrono::steady_clock::now() + 3s;
    while (server.counters().subscriptions.value() < kClients + 1) {
        ASSERT_LT(std::chrono::steady_clock::now(), deadline);
        std::this_thread::sleep_for(1ms);
    }
    std::uint64_t published = 0;
    for (std::uint64_t sync = 1; sync <= 60; ++sync) {
        if (sync == 30 || sync == 31) continue;  // a two-frame gap every client must see
        SubjectFrame f;
        f.subject_id = 3;
        f.sync = sync;
        f.segment_count = 1;
        f.times.sink_send_us = client::wall_clock_us();
        skeleton::SkeletonPose p;
        p.segment_count = 1;
        server.publish(f, p);
        f.subject_id = 4;  // not subscribed: must not be counted
        server.publish(f, p);
        ++published;
        std::this_thread::sleep_for(2ms);
    }
    const client::LoadResult r = run.get();
    EXPECT_EQ(r.clients, kClients);
    EXPECT_EQ(r.connected, kClients);
    EXPECT_EQ(r.stalled, 1u);
    EXPECT_EQ(r.closed_early, 0u);
    EXPECT_EQ(r.frames, kClients * published);
    EXPECT_EQ(r.frames_per_client_min, published);
    EXPECT_EQ(r.frames_per_client_max, published);
    EXPECT_EQ(r.gaps, kClients);
    EXPECT_EQ(r.missing_frames, 2 * kClients);
    EXPECT_EQ(r.drops, 0u);
    // Subject 4 is published too but nobody subscribed to it: never encoded.
    EXPECT_EQ(server.counters().frames_encoded.value(), published);
    EXPECT_EQ(server.counters().frames_published.value(), 2 * published);
    EXPECT_EQ(r.latency_samples, kClients * published);
    ASSERT_TRUE(r.p50_ms && r.p99_ms && r.max_ms);
    EXPECT_LE(*r.p50_ms, *r.p99_ms);
    EXPECT_LE(*r.p99_ms, *r.max_ms);
    EXPECT_LT(*r.max_ms, 1000.0);

    const std::string json = client::load_result_json(r);
    for (const char* key : {"\"clients\":6", "\"frames\":", "\"gaps\":6", "\"drops\":0",
                            "\"p50_ms\":", "\"p90_ms\":", "\"p99_ms\":", "\"max_ms\":"}) {
        EXPECT_NE(json.find(key), std::string::npos) << key << " in " << json;
    }
}

TEST(LoadClient, ReportsConnectionFailure) {
    client::LoadOptions options;
    options.port = 1;  // nothing listens on port 1
    options.clients = 2;
    options.duration = 100ms;
    options.connect_timeout = 500ms;
    const client::LoadResult r = client::run_load(options);
    EXPECT_EQ(r.connected, 0u);
    EXPECT_FALSE(r.error.empty());
    EXPECT_NE(client::load_result_json(r).find("\"p50_ms\":null"), std::string::npos);
}

}  // namespace
}  // namespace mocap::serve
