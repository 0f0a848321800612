// The cluster publisher against a nats-server that refuses it or is not there (docs/cluster.md,
// "What happens when things fail"): the log names the reason, the local pose service serves
// every frame meanwhile, and the host connects by itself once the server takes it.
#include <gtest/gtest.h>

#include <sstream>

#include "harness.hpp"
#include "nats_harness.hpp"
#include "pose_client.hpp"

namespace mocap::itest {
namespace {

using namespace std::chrono_literals;

constexpr const char* kUser = kNatsUser;
constexpr const char* kSite = "faults";

class ClusterFaults : public OneHostClusterTest {
protected:
    /// mocapd with the cluster at nats_port_ as `password`, and a simulator feeding it.
    void start_host(const std::string& password) {
        HostConfig h{.sink_port = sink_port_, .pose_port = pose_port_, .calibration_dir = dir_.path().string()};
        h.workers = 1;
        h.cluster = cluster_section(nats_port_, kSite, "h", cluster_credentials(kUser, password), kDefaultQueueFrames);
        daemon_ = start_mocapd(MOCAPD_BIN, h, dir_);
        ASSERT_FALSE(HasFailure());
        sim_ = std::make_unique<Process>(
            std::vector<std::string>{MOCAP_SIM_BIN, "stream", "--connect", "127.0.0.1:" + std::to_string(sink_port_),
                                     "--subjects", "1", "--nodes", "15", "--mode", "quat", "--rate", "100",
                                     "--duration", "90"},
            dir_.file("sim.log"));
    }

    /// A pose-service client of subject 1 receives `n` frames.
    bool local_frames_flow(std::size_t n) {
        client::PoseClient c;
        std::string err;
        if (!c.connect("127.0.0.1", pose_port_, 5s, err) || !c.subscribe({.subject_ids = {1}}, 5s, err)) {
            ADD_FAILURE() << "subscribe: " << err;
            return false;
        }
        std::size_t got = 0;
        v1::SkeletonFrame f;
        for (auto end = std::chrono::steady_clock::now() + 30s; got < n && std::chrono::steady_clock::now() < end;)
            if (c.next_frame(f, 200ms) == client::ReadStatus::kMessage) ++got;
        return got >= n;
    }
};

TEST_F(ClusterFaults, WrongCredentialsAreNamedAndTheHostConnectsOnceTheServerAcceptsThem) {
    nats_ = start_nats_as(nats_port_, kUser, "the-servers-password", dir_.file("nats.log"));
    start_host("an-old-password");
    EXPECT_TRUE(wait_until([&] { return daemon_->log().find("Authorization Violation") != std::string::npos; }, 20s))
        << "the log must say that the server refused the credentials";
    EXPECT_TRUE(local_frames_flow(100)) << "the local pose service serves while the cluster refuses the host";

    // The operator puts the host's password on the server: the host gets in by itself.
    nats_->stop();
    nats_ = start_nats_as(nats_port_, kUser, "an-old-password", dir_.file("nats2.log"));
    NatsSubscriber poses(nats_port_, std::string("mocap.") + kSite + ".1.pose", kUser, "an-old-password");
    std::optional<std::pair<std::string, std::string>> m;
    for (auto end = std::chrono::steady_clock::now() + 30s; !m && std::chrono::steady_clock::now() < end;)
        m = poses.next(1000ms);
    ASSERT_TRUE(m) << "the host must connect on its own and publish";
    EXPECT_EQ(decode_pose_payload(m->second).subject_id(), 1u);
}

TEST_F(ClusterFaults, AClusterDownAtStartIsNamedAndJoinedWhenItComesUp) {
    start_host("pw");  // nothing listens on nats_port_ yet
    EXPECT_TRUE(wait_until([&] { return daemon_->log().find("cannot connect to nats://") != std::string::npos; }, 20s));
    EXPECT_NE(daemon_->log().find("No server available"), std::string::npos) << daemon_->log();
    EXPECT_TRUE(local_frames_flow(100));
    nats_ = start_nats_as(nats_port_, kUser, "pw", dir_.file("nats.log"));
    NatsSubscriber poses(nats_port_, std::string("mocap.") + kSite + ".1.pose", kUser, "pw");
    std::optional<std::pair<std::string, std::string>> m;
    for (auto end = std::chrono::steady_clock::now() + 30s; !m && std::chrono::steady_clock::now() < end;)
        m = poses.next(1000ms);
    ASSERT_TRUE(m) << "the host must join the cluster once it is up";
}

}  // namespace
}  // namespace mocap::itest
