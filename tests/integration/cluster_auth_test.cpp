// Credentials and TLS against a real nats-server (docs/cluster.md, "Credentials and TLS"):
// mocapd joins a server that knows only an nkey's public key (nkey_seed_file), a server that
// speaks TLS only (tls_ca_file), and one that also demands a client certificate
// (tls_cert_file + tls_key_file); a server whose certificate another CA signed is refused,
// the log names the TLS failure and the local pose service keeps serving. The certificates
// are made by openssl in the test (a throwaway CA, 127.0.0.1); the nkey is the test-only key
// committed beside this file (nats_test_user.nk).
#include <gtest/gtest.h>
#include <nats/nats.h>
#include <unistd.h>

#include <fstream>
#include <sstream>

#include "harness.hpp"
#include "nats_harness.hpp"
#include "pose_client.hpp"

namespace mocap::itest {
namespace {

using namespace std::chrono_literals;

constexpr const char* kSite = "auth";
constexpr const char* kOpenssl = "/usr/bin/openssl";

/// The public key ("U...") of the test nkey file.
std::string test_nkey_public_key() {
    std::ifstream in(NATS_TEST_NKEY);
    for (std::string line; std::getline(in, line);)
        if (line.size() == 56 && line.front() == 'U') return line;
    return {};
}

class ClusterAuth : public OneHostClusterTest {
protected:
    /// nats-server with `conf` (listen and anything else) from a config file.
    void start_server(const std::string& conf) {
        const std::string path = dir_.file("nats.conf");
        write_file(path, "listen: 127.0.0.1:" + std::to_string(nats_port_) + "\n" + conf);
        nats_ =
            std::make_unique<Process>(std::vector<std::string>{nats_server_bin(), "-c", path}, dir_.file("nats.log"));
        ASSERT_TRUE(wait_for_port(nats_port_, 15s)) << nats_->log();
    }

    /// mocapd with `cluster` lines (credentials, TLS) in [cluster], fed by one subject.
    void start_host(const std::string& cluster) {
        HostConfig h{.sink_port = sink_port_, .pose_port = pose_port_, .calibration_dir = dir_.path().string()};
        h.cluster = cluster_section(nats_port_, kSite, "h", cluster);
        daemon_ = start_mocapd(MOCAPD_BIN, h, dir_);
        ASSERT_FALSE(HasFailure());
        sim_ = stream_sim(MOCAP_SIM_BIN, sink_port_, 1, 60, dir_.file("sim.log"));
    }

    /// Frames reach the cluster: the host connected and publishes.
    bool publishes() {
        return wait_stats_counter(
                   pose_port_, "cluster.frames_published", [](auto v) { return v >= 50; }, 20s) >= 50;
    }

    /// `openssl ARGS` in the test directory; a test failure if it fails.
    void openssl(std::vector<std::string> args) {
        args.insert(args.begin(), kOpenssl);
        Process p(args, dir_.file("openssl.log"), dir_.path().string());
        ASSERT_EQ(p.wait(60s).value_or(-1), 0) << p.log();
    }

    /// A throwaway CA `name`.pem / `name`.key.
    void make_ca(const std::string& name) {
        openssl({"req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes", "-keyout",
                 name + ".key", "-out", name + ".pem", "-days", "1", "-subj", "/CN=mocapd test " + name});
    }

    /// `name`.pem / `name`.key signed by CA `ca`, for 127.0.0.1, with extended key usage `usage`.
    void make_cert(const std::string& name, const std::string& ca, const std::string& usage) {
        openssl({"req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes", "-keyout", name + ".key",
                 "-out", name + ".csr", "-subj", "/CN=" + name});
        write_file(dir_.file(name + ".ext"), "subjectAltName=IP:127.0.0.1\nextendedKeyUsage=" + usage + "\n");
        openssl({"x509", "-req", "-in", name + ".csr", "-CA", ca + ".pem", "-CAkey", ca + ".key", "-CAcreateserial",
                 "-out", name + ".pem", "-days", "1", "-extfile", name + ".ext"});
    }

    std::string tls_block(bool verify_clients) const {
        return "tls {\n  cert_file: \"" + dir_.file("server.pem") + "\"\n  key_file: \"" + dir_.file("server.key") +
               "\"\n  ca_file: \"" + dir_.file("ca.pem") + "\"\n  verify: " + (verify_clients ? "true" : "false") +
               "\n  timeout: 5\n}\nauthorization {\n  user: \"" + kNatsUser + "\"\n  password: \"" + kNatsPassword +
               "\"\n}\n";
    }

    bool have_openssl() const { return ::access(kOpenssl, X_OK) == 0; }
};

TEST_F(ClusterAuth, AnNkeyUserConnectsWithItsSeedFile) {
    const std::string pub = test_nkey_public_key();
    ASSERT_EQ(pub.size(), 56u) << "no public key in " << NATS_TEST_NKEY;
    start_server("authorization {\n  users = [ { nkey: \"" + pub + "\" } ]\n}\n");
    start_host(std::string("nkey_seed_file = \"") + NATS_TEST_NKEY + "\"\n");
    EXPECT_TRUE(publishes()) << "mocapd signs the server's nonce with the seed";
    // The server lets nobody in without the key.
    natsConnection* anonymous = nullptr;
    const std::string url = "nats://127.0.0.1:" + std::to_string(nats_port_);
    EXPECT_NE(natsConnection_ConnectTo(&anonymous, url.c_str()), NATS_OK);
    natsConnection_Destroy(anonymous);
    EXPECT_NE(daemon_->log().find("cluster: connected to nats://127.0.0.1:"), std::string::npos) << daemon_->log();
}

TEST_F(ClusterAuth, TlsWithTheSitesCaAndWithAClientCertificate) {
    if (!have_openssl()) GTEST_SKIP() << "no openssl at " << kOpenssl;
    make_ca("ca");
    make_cert("server", "ca", "serverAuth");
    make_cert("mocapd", "ca", "clientAuth");
    // The server verifies clients: without a certificate mocapd would be refused.
    start_server(tls_block(true));
    start_host(cluster_credentials() + "tls_ca_file = \"" + dir_.file("ca.pem") + "\"\ntls_cert_file = \"" +
               dir_.file("mocapd.pem") + "\"\ntls_key_file = \"" + dir_.file("mocapd.key") + "\"\n");
    EXPECT_TRUE(publishes()) << "TLS with the site's CA and mocapd's client certificate";
}

TEST_F(ClusterAuth, TlsWithTheSitesCaOnly) {
    if (!have_openssl()) GTEST_SKIP() << "no openssl at " << kOpenssl;
    make_ca("ca");
    make_cert("server", "ca", "serverAuth");
    start_server(tls_block(false));
    start_host(cluster_credentials() + "tls_ca_file = \"" + dir_.file("ca.pem") + "\"\n");
    EXPECT_TRUE(publishes()) << "TLS with the site's CA";
}

TEST_F(ClusterAuth, AServerCertificateFromAnotherCaIsRefusedAndNamed) {
    if (!have_openssl()) GTEST_SKIP() << "no openssl at " << kOpenssl;
    make_ca("ca");
    make_ca("other");
    make_cert("server", "ca", "serverAuth");
    start_server(tls_block(false));
    start_host(cluster_credentials() + "tls_ca_file = \"" + dir_.file("other.pem") + "\"\n");
    EXPECT_TRUE(wait_until([&] { return daemon_->log().find("cluster: cannot connect to") != std::string::npos; }, 15s))
        << daemon_->log();
    const std::string log = daemon_->log();
    EXPECT_NE(log.find("SSL"), std::string::npos) << "the log names the TLS failure: " << log;
    const auto at = log.find("cluster: cannot connect to");
    std::cout << "[ log      ] " << log.substr(at, log.find('\n', at) - at) << "\n";
    // The local pose service serves meanwhile, and nothing reached the cluster.
    client::PoseClient c;
    std::string err;
    ASSERT_TRUE(c.connect("127.0.0.1", pose_port_, 5s, err)) << err;
    client::SubscribeOptions o;
    ASSERT_TRUE(c.subscribe(o, 5s, err)) << err;
    v1::SkeletonFrame f;
    EXPECT_EQ(c.next_frame(f, 10s), client::ReadStatus::kMessage) << "local clients are served";
    EXPECT_EQ(stats_counter(pose_port_, "cluster.frames_published"), 0u);
}

}  // namespace
}  // namespace mocap::itest
