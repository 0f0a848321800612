// The cluster publisher against a nats-server that refuses it or is not there (docs/cluster.md,
// "What happens when things fail"): the log names the reason, the local pose service serves
// every frame meanwhile, and the host connects by itself once the server takes it. A server
// whose permissions refuse the calibration bucket is named as such. A fake server written
// here (it speaks just enough of the NATS protocol) that floods PINGs and never reads is
// dropped and reconnected, and does not hold up a stop; one that never says a word does not
// hold up the start.
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <iostream>
#include <mutex>
#include <sstream>
#include <thread>

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

/// A TCP server on a free loopback port that takes NATS clients and misbehaves: kFlood sends
/// INFO, answers the client's CONNECT + PING with PONG, then sends PINGs as fast as the
/// socket takes them and never reads again; kSilent accepts and never sends a byte.
class FakeNatsServer {
public:
    enum class Mode { kFlood, kSilent };
    explicit FakeNatsServer(Mode mode) : mode_(mode) {
        listener_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        EXPECT_EQ(::bind(listener_, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
        socklen_t len = sizeof a;
        ::getsockname(listener_, reinterpret_cast<sockaddr*>(&a), &len);
        port_ = ntohs(a.sin_port);
        EXPECT_EQ(::listen(listener_, 16), 0);
        accept_thread_ = std::thread([this] { accept_loop(); });
    }
    ~FakeNatsServer() {
        stop_ = true;
        ::shutdown(listener_, SHUT_RDWR);
        {
            std::lock_guard lock(mutex_);
            for (const int fd : fds_)
                ::shutdown(fd, SHUT_RDWR);  // unblocks a flooding send
        }
        accept_thread_.join();
        for (auto& t : threads_)
            t.join();
        for (const int fd : fds_)
            ::close(fd);
        ::close(listener_);
    }
    FakeNatsServer(const FakeNatsServer&) = delete;
    FakeNatsServer& operator=(const FakeNatsServer&) = delete;

    [[nodiscard]] std::uint16_t port() const { return port_; }
    /// Clients that got through the handshake (kFlood) or connected (kSilent).
    [[nodiscard]] int clients() const { return clients_.load(); }

private:
    void accept_loop() {
        while (!stop_) {
            const int fd = ::accept4(listener_, nullptr, nullptr, SOCK_CLOEXEC);
            if (fd < 0) continue;
            std::lock_guard lock(mutex_);
            if (stop_) {
                ::close(fd);
                break;
            }
            fds_.push_back(fd);
            threads_.emplace_back([this, fd] { serve(fd); });
        }
    }
    void serve(int fd) {
        if (mode_ == Mode::kSilent) {
            ++clients_;
            return;  // the socket stays open and silent until the test ends
        }
        const std::string info =
            "INFO {\"server_id\":\"fake\",\"version\":\"2.9.10\",\"proto\":1,\"max_payload\":1048576}\r\n";
        if (!send_all(fd, info)) return;
        std::string got;
        char buf[4096];
        while (got.find("PING\r\n") == std::string::npos) {
            const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
            if (n <= 0) return;
            got.append(buf, static_cast<std::size_t>(n));
        }
        if (!send_all(fd, "PONG\r\n")) return;
        ++clients_;
        std::string flood;
        for (int i = 0; i < 1000; ++i)
            flood += "PING\r\n";
        while (!stop_ && send_all(fd, flood)) {
        }
    }
    static bool send_all(int fd, const std::string& s) {
        for (std::size_t off = 0; off < s.size();) {
            const ssize_t n = ::send(fd, s.data() + off, s.size() - off, MSG_NOSIGNAL);
            if (n <= 0) return false;
            off += static_cast<std::size_t>(n);
        }
        return true;
    }

    Mode mode_;
    int listener_ = -1;
    std::uint16_t port_ = 0;
    std::atomic<bool> stop_{false};
    std::atomic<int> clients_{0};
    std::mutex mutex_;
    std::vector<int> fds_;  // guarded by mutex_
    std::vector<std::thread> threads_;
    std::thread accept_thread_;
};

TEST_F(ClusterFaults, AServerThatFloodsPingsAndNeverReadsIsDroppedAndDoesNotHoldUpTheStop) {
    FakeNatsServer fake(FakeNatsServer::Mode::kFlood);
    nats_port_ = fake.port();
    start_host("pw");
    const auto started = std::chrono::steady_clock::now();
    // The client's PONGs fill the socket the server never reads: the write deadline fails the
    // connection, the host counts it lost and connects again (to the same fake).
    EXPECT_GE(wait_stats_counter(
                  pose_port_, "cluster.disconnects", [](auto v) { return v >= 1; }, 60s),
              1u)
        << "a stalled connection must be dropped";
    const auto dropped = std::chrono::steady_clock::now();
    EXPECT_TRUE(wait_until([&] { return fake.clients() >= 2; }, 60s)) << "and opened again";
    EXPECT_TRUE(local_frames_flow(100)) << "the local pose service serves meanwhile";
    // SIGTERM ends the daemon, cleanly, whatever the server does.
    const auto stopping = std::chrono::steady_clock::now();
    EXPECT_EQ(daemon_->stop(30s), 0) << "a stop must not wait on the stalled server";
    const auto ms = [](auto d) { return std::chrono::duration_cast<std::chrono::milliseconds>(d).count(); };
    std::cout << "[ metrics  ] PING flood: first disconnect seen " << ms(dropped - started) << " ms after the start, "
              << fake.clients() << " connections, SIGTERM to exit " << ms(std::chrono::steady_clock::now() - stopping)
              << " ms\n";
    sim_->stop();
}

TEST_F(ClusterFaults, AServerThatNeverSpeaksDoesNotHoldUpTheStart) {
    FakeNatsServer silent(FakeNatsServer::Mode::kSilent);
    nats_port_ = silent.port();
    start_host("pw");
    ASSERT_TRUE(wait_until([&] { return silent.clients() >= 1; }, 30s));
    // The client waits for the server's INFO up to its connect timeout, and only then logs
    // that it cannot connect; the daemon is ready before that.
    EXPECT_TRUE(wait_until([&] { return daemon_->log().find("cannot connect to") != std::string::npos; }, 30s));
    const std::string log = daemon_->log();
    const auto ready = log.find("mocapd ready:");
    ASSERT_NE(ready, std::string::npos) << log;
    EXPECT_LT(ready, log.find("cannot connect to")) << "the start must not wait for the silent server:\n" << log;
}

TEST_F(ClusterFaults, APublishTheServersPermissionsRefuseIsNamedAsOne) {
    // The host's user may publish the site's subjects and use the JetStream API, but not put
    // to the calibration bucket ($KV.mocap_calibration.>): the shipped config before it said so.
    const std::string conf = dir_.file("nats.conf");
    write_file(conf, "listen: 127.0.0.1:" + std::to_string(nats_port_) + "\njetstream { store_dir: \"" +
                         dir_.file("js") + "\" }\nauthorization { users = [ { user: " + kUser +
                         ", password: pw, permissions: { publish: [\"mocap." + kSite +
                         ".>\", \"$JS.API.>\", \"_INBOX.>\"], subscribe: [\"_INBOX.>\"] } } ] }\n");
    nats_ = std::make_unique<Process>(std::vector<std::string>{nats_server_bin(), "-c", conf}, dir_.file("nats.log"));
    ASSERT_TRUE(wait_for_port(nats_port_, 15s)) << nats_->log();
    start_host("pw");  // auto_calibrate: subject 1 is calibrated from the simulator's T-pose
    EXPECT_GE(wait_stats_counter(
                  pose_port_, "calibration_kv.permission_errors", [](auto v) { return v >= 1; }, 60s),
              1u);
    const std::string refused =
        std::string("Permissions Violation for Publish to \"$KV.mocap_calibration.") + kSite + ".1\"";
    EXPECT_TRUE(wait_until(
        [&] {
            return daemon_->log().find(std::string("cannot put ") + kSite +
                                       ".1: the NATS server refused it: " + refused) != std::string::npos;
        },
        30s))
        << "the failed put is named for what it is, not as a timeout";
    EXPECT_EQ(stats_counter(pose_port_, "calibration_kv.puts"), 0u);
}

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
