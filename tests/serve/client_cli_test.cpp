// mocap-client, the executable, against an in-process server: cat --json, stats,
// control with and without the right token, load --json. Every command is bounded by
// the client's own timeouts.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <nlohmann/json.hpp>

#include <atomic>
#include <cstdio>
#include <thread>

#include "pose_client.hpp"
#include "serve/pose_server.hpp"

namespace mocap::serve {
namespace {

struct CommandResult {
    int exit_code = -1;
    std::string out;
};

CommandResult run(const std::string& args) {
    const std::string cmd = std::string(MOCAP_CLIENT_BIN) + " " + args + " 2>/dev/null";
    CommandResult r;
    FILE* pipe = ::popen(cmd.c_str(), "r");
    if (pipe == nullptr) return r;
    char buf[4096];
    std::size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0)
        r.out.append(buf, n);
    const int status = ::pclose(pipe);
    r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return r;
}

class ClientCli : public ::testing::Test {
protected:
    void SetUp() override {
        ServeConfig config;
        config.bind_address = "127.0.0.1";
        config.port = 0;
        config.control_token = "tok-123";
        ControlHandlers handlers;
        handlers.calibrate = [this](std::uint32_t subject, CalibrationPose) {
            calibrated_subject_ = subject;
            return ControlResult::success();
        };
        server_ = std::make_unique<PoseServer>(config, handlers);
        ServeDescription d;
        d.segments = {{"pelvis", -1, {0, 0, 0}, 1}, {"head", 0, {0, 0, 0.5}, 2}};
        d.subjects = {{5, "carol"}};
        server_->set_description(d);
        std::string error;
        ASSERT_TRUE(server_->start(error)) << error;
        connect_ = "--connect 127.0.0.1:" + std::to_string(server_->port()) + " ";
        publisher_ = std::thread([this] {
            for (std::uint64_t sync = 1; !stop_.load() && sync < 100000; ++sync) {
                SubjectFrame f;
                f.subject_id = 5;
                f.sync = sync;
                f.segment_count = 2;
                f.times.sink_send_us = client::wall_clock_us();
                skeleton::SkeletonPose p;
                p.segment_count = 2;
                p.q_world_segment_wxyz[1] = {0.0, 1.0, 0.0, 0.0};
                p.position_m[1] = {0.0, 0.0, 0.5};
                server_->publish(f, p);
                std::this_thread::sleep_for(std::chrono::milliseconds(5));
            }
        });
    }
    void TearDown() override {
        stop_ = true;
        if (publisher_.joinable()) publisher_.join();
        server_->stop();
    }

    std::unique_ptr<PoseServer> server_;
    std::string connect_;
    std::thread publisher_;
    std::atomic<bool> stop_{false};
    std::atomic<std::uint32_t> calibrated_subject_{0};
};

TEST_F(ClientCli, CatJsonPrintsOneObjectPerFrameWithSegments) {
    const CommandResult r = run(connect_ + "cat --frames 3 --json --timeout 3");
    ASSERT_EQ(r.exit_code, 0) << r.out;
    std::size_t lines = 0;
    for (std::size_t at = 0; at < r.out.size();) {
        const std::size_t end = r.out.find('\n', at);
        const std::string line = r.out.substr(at, end - at);
        at = end == std::string::npos ? r.out.size() : end + 1;
        ++lines;
        EXPECT_EQ(line.front(), '{');
        EXPECT_EQ(line.back(), '}');
        EXPECT_NE(line.find("{\"subject\":5,"), std::string::npos) << line;  // subject first, for line filters
        // Parsed, not compared as text: numbers may print as 1 or 1.0.
        const auto frame = nlohmann::json::parse(line);
        EXPECT_EQ(frame["segments"], nlohmann::json::parse(R"([{"name":"pelvis","q":[1,0,0,0],"p":[0,0,0],"flags":2},)"
                                                           R"({"name":"head","q":[0,1,0,0],"p":[0,0,0.5],"flags":2}])"))
            << line;
    }
    EXPECT_EQ(lines, 3u);
}

TEST_F(ClientCli, CatTextNamesTheRootSegment) {
    const CommandResult r = run(connect_ + "cat --frames 1 --timeout 3");
    ASSERT_EQ(r.exit_code, 0);
    EXPECT_NE(r.out.find("subject 5 sync "), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("pelvis q=(1.000 0.000 0.000 0.000)"), std::string::npos) << r.out;
}

TEST_F(ClientCli, StatsJsonHasServeCounters) {
    const CommandResult r = run(connect_ + "stats --json");
    ASSERT_EQ(r.exit_code, 0);
    EXPECT_NE(r.out.find("\"serve.connections_accepted\":"), std::string::npos) << r.out;
}

TEST_F(ClientCli, ControlNeedsTheToken) {
    EXPECT_EQ(run(connect_ + "control calibrate --subject 5").exit_code, 1);
    EXPECT_EQ(run(connect_ + "control --token nope calibrate --subject 5").exit_code, 1);
    EXPECT_EQ(calibrated_subject_.load(), 0u);
    const CommandResult ok = run(connect_ + "control --token tok-123 calibrate --subject 5 --pose N");
    EXPECT_EQ(ok.exit_code, 0);
    EXPECT_EQ(ok.out, "ok\n");
    EXPECT_EQ(calibrated_subject_.load(), 5u);
}

TEST_F(ClientCli, LoadJsonReportsTheContractFields) {
    const CommandResult r = run(connect_ + "load --clients 3 --duration 0.5 --json");
    ASSERT_EQ(r.exit_code, 0) << r.out;
    for (const char* key : {"\"clients\":3", "\"frames\":", "\"gaps\":0", "\"drops\":0",
                            "\"p50_ms\":", "\"p90_ms\":", "\"p99_ms\":", "\"max_ms\":"}) {
        EXPECT_NE(r.out.find(key), std::string::npos) << key << " in " << r.out;
    }
    EXPECT_EQ(r.out.find("\"frames\":0,"), std::string::npos) << r.out;
}

TEST_F(ClientCli, BadEndpointIsAConnectionError) {
    EXPECT_EQ(run("--connect nohostport stats").exit_code, 2);
    EXPECT_EQ(run("--connect 127.0.0.1:1 --connect-timeout 0.5 stats").exit_code, 2);
}

}  // namespace
}  // namespace mocap::serve
