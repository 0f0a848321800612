#include "nats_harness.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

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
    std::vector<std::string> argv{NATS_SERVER_BIN, "-a",      "127.0.0.1", "-p",         std::to_string(port),
                                  "--user",        kNatsUser, "--pass",    kNatsPassword};
    argv.insert(argv.end(), extra.begin(), extra.end());
    auto p = std::make_unique<Process>(argv, log);
    EXPECT_TRUE(wait_for_port(port, 15s)) << p->log();
    return p;
}

std::string cluster_section(std::uint16_t nats_port, const std::string& site, const std::string& host_id,
                            const std::string& more) {
    std::ostringstream s;
    s << "[cluster]\nnats_url = \"nats://127.0.0.1:" << nats_port << "\"\nsite = \"" << site << "\"\nhost_id = \""
      << host_id << "\"\nqueue_frames = 64\n"
      << more;
    return s.str();
}

std::string cluster_credentials() {
    return std::string("user = \"") + kNatsUser + "\"\npassword = \"" + kNatsPassword + "\"\n";
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

}  // namespace mocap::itest
