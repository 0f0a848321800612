#include "nats_harness.hpp"

#include <gtest/gtest.h>
#include <nats/nats.h>
#include <unistd.h>

#include <regex>
#include <sstream>

#include "mocap/v1/mocap.pb.h"
#include "pose_client.hpp"

namespace mocap::itest {

using namespace std::chrono_literals;

bool have_nats_server() {
    return ::access(NATS_SERVER_BIN, X_OK) == 0;
}

const char* nats_server_bin() {
    return NATS_SERVER_BIN;
}

std::unique_ptr<Process> start_nats(std::uint16_t port, const std::string& log, const std::vector<std::string>& extra) {
    return start_nats_as(port, kNatsUser, kNatsPassword, log, extra);
}

std::unique_ptr<Process> start_nats_as(std::uint16_t port, const std::string& user, const std::string& password,
                                       const std::string& log, const std::vector<std::string>& extra) {
    std::vector<std::string> argv{NATS_SERVER_BIN, "-a", "127.0.0.1", "-p",    std::to_string(port),
                                  "--user",        user, "--pass",    password};
    argv.insert(argv.end(), extra.begin(), extra.end());
    auto p = std::make_unique<Process>(argv, log);
    EXPECT_TRUE(wait_for_port(port, 15s)) << p->log();
    return p;
}

NatsSubscriber::NatsSubscriber(std::uint16_t port, const std::string& subject, const std::string& user,
                               const std::string& password) {
    natsOptions* o = nullptr;
    EXPECT_EQ(natsOptions_Create(&o), NATS_OK);
    const std::string url = "nats://127.0.0.1:" + std::to_string(port);
    natsOptions_SetURL(o, url.c_str());
    natsOptions_SetUserInfo(o, user.c_str(), password.c_str());
    natsOptions_SetMaxReconnect(o, -1);
    natsOptions_SetReconnectWait(o, 100);
    EXPECT_EQ(natsConnection_Connect(&nc_, o), NATS_OK);
    natsOptions_Destroy(o);
    EXPECT_EQ(natsConnection_SubscribeSync(&sub_, nc_, subject.c_str()), NATS_OK);
    natsSubscription_SetPendingLimits(sub_, 1 << 20, 1 << 30);
    EXPECT_EQ(natsConnection_FlushTimeout(nc_, 5000), NATS_OK);
}

NatsSubscriber::~NatsSubscriber() {
    // Close the connection first: its reader thread stops before the subscription it may be
    // delivering to is freed (libnats 3.4 crashed in natsConn_processMsg once, under ASan,
    // when the subscription went first while frames were still arriving).
    natsConnection_Close(nc_);
    natsSubscription_Destroy(sub_);
    natsConnection_Destroy(nc_);
}

std::optional<std::pair<std::string, std::string>> NatsSubscriber::next(std::chrono::milliseconds timeout) {
    natsMsg* m = nullptr;
    if (natsSubscription_NextMsg(&m, sub_, timeout.count()) != NATS_OK) return std::nullopt;
    std::pair<std::string, std::string> out{natsMsg_GetSubject(m),
                                            std::string(natsMsg_GetData(m), natsMsg_GetDataLength(m))};
    natsMsg_Destroy(m);
    return out;
}

v1::SkeletonFrame decode_pose_payload(const std::string& payload) {
    v1::ServerMessage m;
    EXPECT_TRUE(m.ParseFromString(payload)) << "payload must be a mocap.v1.ServerMessage without a prefix";
    EXPECT_TRUE(m.has_frame());
    return m.frame();
}

void OneHostClusterTest::SetUp() {
    if (!have_nats_server()) {
        GTEST_SKIP() << "no nats-server binary at " << nats_server_bin() << " (setup.sh installs it)";
    }
    nats_port_ = free_port();
    sink_port_ = free_port();
    pose_port_ = free_port();
}

void OneHostClusterTest::TearDown() {
    if (sim_) sim_->stop();
    if (!daemon_) return;
    if (HasFailure()) std::cerr << "--- mocapd log ---\n" << daemon_->log();
    EXPECT_EQ(daemon_->stop(10s), 0) << "mocapd must exit 0 on SIGTERM, cluster or not";
}

std::string daemon_config(const HostConfig& h) {
    std::ostringstream s;
    s << "[log]\nlevel = \"info\"\nstats_interval_s = 0\n"
      << "[ingest]\nsink_listen = \"127.0.0.1:" << h.sink_port << "\"\n"
      << h.ingest << "[pipeline]\nworkers = " << h.workers << "\nmax_subjects = 4\n"
      << "[skeleton]\ncalibration_dir = \"" << h.calibration_dir << "\"\n"
      << h.skeleton << "[serve]\npose_listen = \"127.0.0.1:" << h.pose_port << "\"\n"
      << h.serve << "[outputs]\n"
      << h.outputs << "[http]\n"
      << h.http << h.cluster;
    return s.str();
}

std::unique_ptr<Process> start_mocapd(const char* mocapd_bin, const HostConfig& host, const TempDir& dir,
                                      const std::string& name) {
    const std::string path = dir.file(name + ".toml");
    write_file(path, daemon_config(host));
    auto p = std::make_unique<Process>(std::vector<std::string>{mocapd_bin, "--config", path}, dir.file(name + ".log"),
                                       dir.path().string());
    EXPECT_TRUE(wait_for_port(host.pose_port, 10s)) << p->log();
    EXPECT_TRUE(wait_for_port(host.sink_port, 10s)) << p->log();
    return p;
}

std::string cluster_section(std::uint16_t nats_port, const std::string& site, const std::string& host_id,
                            const std::string& more, std::size_t queue_frames) {
    std::ostringstream s;
    s << "[cluster]\nnats_url = \"nats://127.0.0.1:" << nats_port << "\"\nsite = \"" << site << "\"\nhost_id = \""
      << host_id << "\"\n";
    if (queue_frames != kDefaultQueueFrames) s << "queue_frames = " << queue_frames << "\n";
    s << more;
    return s.str();
}

std::string cluster_credentials(const std::string& user, const std::string& password) {
    return "user = \"" + user + "\"\npassword = \"" + password + "\"\n";
}

std::unique_ptr<Process> stream_sim(const char* sim_bin, std::uint16_t sink_port, int subjects, int seconds,
                                    const std::string& log) {
    return std::make_unique<Process>(
        std::vector<std::string>{sim_bin, "stream", "--connect", "127.0.0.1:" + std::to_string(sink_port), "--rate",
                                 "100", "--subjects", std::to_string(subjects), "--duration", std::to_string(seconds),
                                 "--sink-rate-stats"},
        log);
}

std::uint64_t stats_counter(std::uint16_t pose_port, const std::string& name) {
    client::PoseClient c;
    std::string err;
    EXPECT_TRUE(c.connect("127.0.0.1", pose_port, 5s, err)) << err;
    v1::Stats s;
    EXPECT_TRUE(c.request_stats(s, 5s, err)) << err;
    for (const auto& kv : s.counters())
        if (kv.name() == name) return kv.value();
    ADD_FAILURE() << "no counter " << name;
    return 0;
}

std::uint64_t wait_stats_counter(std::uint16_t pose_port, const std::string& name,
                                 const std::function<bool(std::uint64_t)>& pred, std::chrono::milliseconds limit) {
    std::uint64_t v = 0;
    wait_until(
        [&] {
            v = stats_counter(pose_port, name);
            return pred(v);
        },
        limit);
    return v;
}

std::optional<std::uint64_t> replayed_samples(const std::string& log) {
    std::smatch m;
    static const std::regex re("replayed ([0-9]+) samples");
    if (!std::regex_search(log, m, re)) return std::nullopt;
    return std::stoull(m[1]);
}

std::vector<std::string> jetstream_replay_args(std::uint16_t nats_port, std::uint32_t subject) {
    return {"--jetstream", "nats://127.0.0.1:" + std::to_string(nats_port), "--subject", std::to_string(subject)};
}

}  // namespace mocap::itest
