// Takes on the real mocapd fed by the real mocap-sim (docs/client-protocol.md, "Takes"): a take
// started over HTTP and stopped by the pose service's control request, listed, downloaded as
// raw, BVH and joint-angle CSV over HTTP and with mocap-client, deleted only with the token;
// and a take whose daemon was killed lists and downloads after a restart.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <csignal>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <regex>

#include "harness.hpp"
#include "http_test_client.hpp"
#include "skeleton/bvh.hpp"

namespace mocap::itest {
namespace {

using namespace std::chrono_literals;
using boost::beast::http::verb;
using mocap::testing::http_request;
namespace fs = std::filesystem;

constexpr const char* kToken = "takes-s3cret-0123456789";
const std::map<std::string, std::string> kWithToken{{"X-Mocap-Token", kToken}};

std::string slurp(const fs::path& path) {
    return read_file(path.string());
}

class Takes : public ::testing::Test {
protected:
    void SetUp() override { start_daemon(); }
    void TearDown() override {
        if (sim_) sim_->stop();
        if (HasFailure()) std::cerr << "--- mocapd log ---\n" << daemon_->log();
        if (daemon_->running()) {
            EXPECT_EQ(daemon_->stop(30s), 0);
        }
    }
    /// Fresh ports every time (a restarted daemon must not wait for the old ones).
    void start_daemon() {
        ports_ = WebDaemon{};
        sink_port_ = ports_.sink_port;
        pose_port_ = ports_.pose_port;
        http_port_ = ports_.http_port;
        write_file(dir_.file("mocapd.toml"), ports_.config(dir_.path().string(), kToken));
        daemon_ =
            std::make_unique<Process>(std::vector<std::string>{MOCAPD_BIN, "--config", dir_.file("mocapd.toml")},
                                      dir_.file("mocapd-" + std::to_string(++starts_) + ".log"), dir_.path().string());
        ASSERT_TRUE(wait_for_port(http_port_, 30s)) << daemon_->log();
        ASSERT_TRUE(wait_for_port(sink_port_, 30s)) << daemon_->log();
    }
    void start_sim() { sim_ = std::make_unique<Process>(ports_.walk_sim(MOCAP_SIM_BIN, 120), dir_.file("sim.log")); }
    /// Starts take `name` over HTTP and waits until its raw file holds `bytes` (~82 B a sample,
    /// 1500 samples a second).
    void record(const std::string& name, std::uintmax_t bytes) {
        const auto started = http_request(http_port_, "/api/takes/start?name=" + name + "&notes=two+steps%2C+then+stop",
                                          verb::post, kWithToken);
        ASSERT_EQ(started.status, 200u) << started.body;
        EXPECT_NE(started.body.find("\"take\":\"" + name + "\""), std::string::npos) << started.body;
        const fs::path dir = dir_.path() / "takes" / name;
        ASSERT_TRUE(wait_until([&] { return take_raw_bytes(dir) >= bytes; }, 90s)) << take_raw_bytes(dir) << " bytes\n"
                                                                                   << daemon_->log();
    }
    /// Runs mocap-client; its exit status, its stdout in *out.
    int client(const std::vector<std::string>& args, std::string* out = nullptr) {
        std::vector<std::string> argv{MOCAP_CLIENT_BIN, "--connect", "127.0.0.1:" + std::to_string(pose_port_),
                                      "--http", "127.0.0.1:" + std::to_string(http_port_)};
        argv.insert(argv.end(), args.begin(), args.end());
        Process p(argv, dir_.file("client.log"), dir_.path().string());
        const int status = p.wait(180s).value_or(-1);
        if (out) *out = p.log();
        return status;
    }
    nlohmann::json list() {
        const auto reply = http_request(http_port_, "/api/takes");
        EXPECT_EQ(reply.status, 200u);
        EXPECT_EQ(reply.content_type, "application/json");
        return nlohmann::json::parse(reply.body, nullptr, false)["takes"];
    }

    TempDir dir_;
    WebDaemon ports_;
    std::uint16_t sink_port_ = 0, pose_port_ = 0, http_port_ = 0;
    int starts_ = 0;
    std::unique_ptr<Process> daemon_;
    std::unique_ptr<Process> sim_;
};

TEST_F(Takes, RecordListDownloadAndDeleteWithTheToken) {
    start_sim();
    EXPECT_EQ(http_request(http_port_, "/api/takes/start?name=walk", verb::post).status, 401u) << "no token";
    EXPECT_TRUE(list().empty());
    record("walk", 300'000);  // ~2.4 s of 15 nodes at 100 Hz
    EXPECT_TRUE(list().at(0).at("recording").get<bool>());
    EXPECT_EQ(http_request(http_port_, "/api/takes/walk", verb::delete_, kWithToken).status, 409u)
        << "a take being recorded is not deleted";
    // Stopped through the pose service's control request (ControlRequest.stop_recording.take).
    std::string out;
    ASSERT_EQ(client({"control", "--token", kToken, "record-stop", "--take"}, &out), 0) << out;
    EXPECT_NE(out.find("ok walk"), std::string::npos) << out;

    const auto takes = list();
    ASSERT_EQ(takes.size(), 1u) << takes.dump();
    const auto& take = takes[0];
    EXPECT_EQ(take.at("name"), "walk");
    EXPECT_EQ(take.at("notes"), "two steps, then stop");
    EXPECT_EQ(take.at("subjects"), nlohmann::json::array({1}));
    EXPECT_EQ(take.at("filter"), "mocap");
    EXPECT_FALSE(take.at("recording").get<bool>());
    EXPECT_GT(take.at("stop_us").get<std::int64_t>(), take.at("start_us").get<std::int64_t>());
    EXPECT_GE(take.at("samples").get<std::uint64_t>(), 300'000u / 100) << "at least ~82 B a sample";
    EXPECT_EQ(take.at("samples_lost").get<std::uint64_t>(), 0u);

    // Raw: the recorded file, byte for byte.
    const fs::path take_dir = dir_.path() / "takes" / "walk";
    std::string on_disk;
    for (const auto& f : fs::directory_iterator(take_dir)) {
        if (f.path().extension() == ".mocapraw") on_disk = slurp(f.path());
    }
    const auto raw = http_request(http_port_, "/api/takes/walk/download?format=raw");
    ASSERT_EQ(raw.status, 200u);
    EXPECT_EQ(raw.content_type, "application/octet-stream");
    EXPECT_EQ(raw.body.size(), take.at("raw_bytes").get<std::size_t>());
    EXPECT_TRUE(raw.body == on_disk) << "the download differs from the file";
    EXPECT_EQ(raw.body.substr(0, 8), "MOCAPRAW");

    // BVH re-solved from the raw file: parses, 15 joints, about 100 frames a second of take.
    const auto bvh = http_request(http_port_, "/api/takes/walk/download?format=bvh");
    ASSERT_EQ(bvh.status, 200u) << bvh.body;
    const auto parsed = skeleton::parse_bvh(bvh.body);
    ASSERT_TRUE(parsed) << parsed.error;
    EXPECT_EQ(parsed.clip->joints.size(), 15u);
    const double take_s = static_cast<double>(take.at("samples").get<std::uint64_t>()) / 1500.0;
    EXPECT_GT(static_cast<double>(parsed.clip->frame_count), 0.8 * 100 * take_s) << take_s << " s of take";
    // The rate the subject was sampled at: 100 Hz, or slower when the simulator ran late on a
    // loaded machine (measured 11.4 ms under a full test run), never faster.
    EXPECT_GT(parsed.clip->frame_time_s, 0.0099);
    EXPECT_LT(parsed.clip->frame_time_s, 0.02);

    // The joint-angle CSV with another filter: one row per frame, and other angles.
    const auto csv = http_request(http_port_, "/api/takes/walk/download?format=csv");
    const auto csv_madgwick = http_request(http_port_, "/api/takes/walk/download?format=csv&filter=madgwick");
    ASSERT_EQ(csv.status, 200u) << csv.body;
    ASSERT_EQ(csv_madgwick.status, 200u) << csv_madgwick.body;
    EXPECT_EQ(csv.content_type, "text/csv; charset=utf-8");
    EXPECT_TRUE(csv.body.starts_with("subject,sync,t_s,left_hip.flexion_deg,")) << csv.body.substr(0, 200);
    EXPECT_EQ(csv_syncs(csv.body).size(), parsed.clip->frame_count);
    EXPECT_EQ(csv_syncs(csv_madgwick.body), csv_syncs(csv.body));
    EXPECT_NE(csv_madgwick.body, csv.body) << "the filter was not applied";
    // The offline re-solve (mocapd --replay --offline): the same frames, other angles; the
    // same bytes from mocap-client --offline (the re-solve is deterministic).
    const auto csv_offline = http_request(http_port_, "/api/takes/walk/download?format=csv&offline=1");
    ASSERT_EQ(csv_offline.status, 200u) << csv_offline.body;
    EXPECT_EQ(csv_syncs(csv_offline.body), csv_syncs(csv.body));
    EXPECT_NE(csv_offline.body, csv.body) << "the offline re-solve was not applied";
    ASSERT_EQ(client({"takes", "download", "walk", "--format", "csv", "--offline", "-o", dir_.file("off.csv")}, &out),
              0)
        << out;
    EXPECT_TRUE(read_file(dir_.file("off.csv")) == csv_offline.body);
    EXPECT_EQ(http_request(http_port_, "/api/takes/walk/download?format=raw&offline=1").status, 400u);

    // `mocapd --replay` takes the take by name (its raw files in <record_dir>/takes): every
    // sample of it, the frames of the CSV download.
    {
        Process replay({MOCAPD_BIN, "--config", dir_.file("mocapd.toml"), "--replay", "walk", "--angles-out",
                        dir_.file("by_name.csv")},
                       dir_.file("replay.log"), dir_.path().string());
        ASSERT_EQ(replay.wait(60s).value_or(-1), 0) << replay.log();
        EXPECT_NE(replay.log().find("replayed " + std::to_string(take.at("samples").get<std::uint64_t>()) + " samples"),
                  std::string::npos)
            << replay.log();
        EXPECT_EQ(csv_syncs(read_file(dir_.file("by_name.csv"))), csv_syncs(csv.body));
    }
    EXPECT_EQ(http_request(http_port_, "/api/takes/walk/download?format=csv&offline=yes").status, 400u);

    // mocap-client: the list, and the same BVH (a re-solve is deterministic).
    ASSERT_EQ(client({"takes", "list"}, &out), 0) << out;
    EXPECT_NE(out.find("walk "), std::string::npos) << out;
    ASSERT_EQ(client({"takes", "download", "walk", "--format", "bvh", "-o", dir_.file("walk.bvh")}, &out), 0) << out;
    EXPECT_TRUE(read_file(dir_.file("walk.bvh")) == bvh.body);
    EXPECT_NE(client({"takes", "download", "walk", "--format", "bvh", "-o", dir_.file("walk.bvh")}), 0)
        << "an existing file is not overwritten";

    // Refusals: a bad filter, names that try to leave the store, a missing take.
    EXPECT_EQ(http_request(http_port_, "/api/takes/walk/download?format=bvh&filter=nope").status, 400u);
    EXPECT_EQ(http_request(http_port_, "/api/takes/walk/download?format=exe").status, 400u);
    EXPECT_EQ(http_request(http_port_, "/api/takes/..%2F..%2Fmocapd.toml/download?format=raw").status, 400u);
    EXPECT_EQ(http_request(http_port_, "/api/takes/.hidden").status, 400u);
    EXPECT_EQ(http_request(http_port_, "/api/takes/none/download?format=bvh").status, 404u);

    // Delete: refused without the token (HTTP and mocap-client), done with it.
    EXPECT_EQ(http_request(http_port_, "/api/takes/walk", verb::delete_).status, 401u);
    EXPECT_EQ(
        http_request(http_port_, "/api/takes/walk", verb::delete_, {{"X-Mocap-Token", "wrong-token-xxxxxxx"}}).status,
        401u);
    EXPECT_EQ(client({"takes", "delete", "walk"}), 1);
    EXPECT_EQ(list().size(), 1u);
    EXPECT_TRUE(fs::exists(take_dir));
    ASSERT_EQ(client({"takes", "--token", kToken, "delete", "walk"}, &out), 0) << out;
    EXPECT_TRUE(list().empty());
    EXPECT_FALSE(fs::exists(take_dir));
    EXPECT_EQ(http_request(http_port_, "/api/takes/walk/download?format=raw").status, 404u);
}

TEST_F(Takes, AKilledDaemonLeavesATakeThatListsAndDownloads) {
    start_sim();
    record("cut", 250'000);
    daemon_->signal(SIGKILL);
    ASSERT_TRUE(daemon_->wait(30s));
    sim_->stop();
    sim_.reset();

    start_daemon();
    const auto takes = list();
    ASSERT_EQ(takes.size(), 1u) << takes.dump();
    EXPECT_EQ(takes[0].at("name"), "cut");
    EXPECT_EQ(takes[0].at("stop_us"), 0) << "the sidecar of the start: the daemon never stopped the take";
    EXPECT_FALSE(takes[0].at("recording").get<bool>());
    EXPECT_GE(takes[0].at("raw_bytes").get<std::uint64_t>(), 250'000u);
    const auto bvh = http_request(http_port_, "/api/takes/cut/download?format=bvh");
    ASSERT_EQ(bvh.status, 200u) << bvh.body;
    const auto parsed = skeleton::parse_bvh(bvh.body);
    ASSERT_TRUE(parsed) << parsed.error;
    EXPECT_GT(parsed.clip->frame_count, 100u);
}

}  // namespace
}  // namespace mocap::itest
