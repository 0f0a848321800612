// serve_loadgen — the pose server alone, fed synthetic frames at a fixed rate, so the
// serve path (encode, fan-out, per-client queues, sockets) can be measured with
// `mocap-client load` without the rest of the daemon:
//
//   serve_loadgen --port 7101 --subjects 10 --segments 15 --rate 100 --duration 12 &
//   mocap-client --connect 127.0.0.1:7101 load --clients 1000 --duration 10 --json
//
// Frames carry sink_send_us = the time of publish(), so the load client's latency is
// publish -> client receive. Prints the server's counters as JSON when it ends.
#include <CLI/CLI.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <thread>

#include "pose_client.hpp"
#include "serve/pose_server.hpp"

int main(int argc, char** argv) {
    using namespace mocap;
    CLI::App app{"serve_loadgen: PoseServer fed with synthetic frames"};
    serve::ServeConfig config;
    config.bind_address = "127.0.0.1";
    config.port = 7101;
    config.max_clients = 2000;
    std::uint32_t subjects = 10;
    std::uint16_t segments = 15;
    double rate_hz = 100.0, duration_s = 10.0;
    app.add_option("--bind", config.bind_address)->capture_default_str();
    app.add_option("--port", config.port)->capture_default_str();
    app.add_option("--threads", config.io_threads)->capture_default_str();
    app.add_option("--max-clients", config.max_clients)->capture_default_str();
    app.add_option("--queue", config.queue_frames)->capture_default_str();
    app.add_option("--max-subscribe-subjects", config.max_subscribe_subjects)->capture_default_str();
    app.add_option("--requests-per-turn", config.requests_per_turn)->capture_default_str();
    app.add_option("--subjects", subjects)->capture_default_str();
    app.add_option("--segments", segments)->check(CLI::Range(1, 32))->capture_default_str();
    app.add_option("--rate", rate_hz)->check(CLI::Range(1.0, 10000.0))->capture_default_str();
    app.add_option("--duration", duration_s)->capture_default_str();
    CLI11_PARSE(app, argc, argv);

    serve::PoseServer server(config);
    serve::ServeDescription description;
    for (std::uint16_t i = 0; i < segments; ++i) {
        description.segments.push_back({"segment" + std::to_string(i), i - 1, {0, 0, 0.1}, i});
    }
    for (std::uint32_t s = 1; s <= subjects; ++s)
        description.subjects.push_back({s, ""});
    server.set_description(description);
    std::string error;
    if (!server.start(error)) {
        std::fprintf(stderr, "serve_loadgen: %s\n", error.c_str());
        return 2;
    }

    const auto period = std::chrono::duration<double>(1.0 / rate_hz);
    const auto start = std::chrono::steady_clock::now();
    const auto end = start + std::chrono::duration<double>(duration_s);
    SubjectFrame frame;
    skeleton::SkeletonPose pose;
    frame.segment_count = pose.segment_count = segments;
    double publish_s = 0;
    for (std::uint64_t tick = 1;; ++tick) {
        const auto due =
            start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(period * static_cast<double>(tick));
        if (due > end) break;
        std::this_thread::sleep_until(due);
        const auto t0 = std::chrono::steady_clock::now();
        for (std::uint32_t s = 1; s <= subjects; ++s) {
            frame.subject_id = s;
            frame.sync = tick;
            frame.sample_us = static_cast<std::int64_t>(tick * 1e6 / rate_hz);
            const double a = 0.01 * static_cast<double>(tick + s);
            for (std::uint16_t i = 0; i < segments; ++i) {
                pose.q_world_segment_wxyz[i] = {std::cos(a), 0.0, 0.0, std::sin(a)};
                pose.position_m[i] = {0.0, 0.0, 0.1 * i};
            }
            frame.times.sink_send_us = client::wall_clock_us();
            server.publish(frame, pose);
        }
        publish_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }
    MetricsRegistry registry;
    server.register_metrics(registry);
    const auto counters = registry.snapshot().counters;
    server.stop();
    std::printf("{\"publish_cpu_s\":%.3f", publish_s);
    for (const auto& c : counters) {
        std::printf(",\"%s\":%llu", c.name.c_str(), static_cast<unsigned long long>(c.value));
    }
    std::printf("}\n");
    return 0;
}
