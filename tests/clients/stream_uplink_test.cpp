// stream_uplink_test.cpp — the simulator's TCP uplink: the --connect host list, dialling the
// host the sink core asks for, and reading what the daemon sends (its keepalives).
#include "sim/stream_uplink.hpp"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <thread>

namespace mocap::sim {
namespace {

using namespace std::chrono_literals;

// A listening socket on a free loopback port.
struct Listener {
    int fd = -1;
    std::uint16_t port = 0;
    Listener() {
        fd = ::socket(AF_INET, SOCK_STREAM, 0);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        EXPECT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
        EXPECT_EQ(::listen(fd, 4), 0);
        socklen_t len = sizeof a;
        ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
        port = ntohs(a.sin_port);
    }
    ~Listener() { ::close(fd); }
};

template <typename Done>
bool wait_until(Done done) {
    for (auto end = std::chrono::steady_clock::now() + 5s; std::chrono::steady_clock::now() < end;) {
        if (done()) return true;
        std::this_thread::sleep_for(2ms);
    }
    return done();
}

TEST(StreamUplink, HostListParsesInOrderAndRefusesBadEntries) {
    std::vector<sockaddr_in> hosts;
    std::string error;
    ASSERT_TRUE(resolve_host_list("127.0.0.1:7000,127.0.0.2:7001", 8, &hosts, &error)) << error;
    ASSERT_EQ(hosts.size(), 2u);
    EXPECT_EQ(ntohs(hosts[0].sin_port), 7000);
    EXPECT_EQ(ntohs(hosts[1].sin_port), 7001);
    EXPECT_EQ(hosts[1].sin_addr.s_addr, htonl(0x7F000002));
    ASSERT_TRUE(resolve_host_list("127.0.0.1:7000", 8, &hosts, &error)) << "one host, as before";
    EXPECT_EQ(hosts.size(), 1u);
    EXPECT_FALSE(resolve_host_list("127.0.0.1:7000,", 8, &hosts, &error));
    EXPECT_FALSE(resolve_host_list("127.0.0.1:7000,nocolon", 8, &hosts, &error));
    EXPECT_NE(error.find("nocolon"), std::string::npos) << error;
    EXPECT_FALSE(resolve_host_list("127.0.0.1:1,127.0.0.1:2,127.0.0.1:3", 2, &hosts, &error));
    EXPECT_NE(error.find("at most 2"), std::string::npos) << error;
}

TEST(StreamUplink, DialsTheAskedHostAndReadsWhatItSends) {
    Listener a, b;
    std::vector<sockaddr_in> hosts;
    std::string error;
    ASSERT_TRUE(resolve_host_list("127.0.0.1:" + std::to_string(a.port) + ",127.0.0.1:" + std::to_string(b.port), 8,
                                  &hosts, &error));
    PosixUplink up(hosts);
    ASSERT_EQ(up.connect(1), 0);
    ASSERT_TRUE(wait_until([&] { return up.state() == SINK_UPLINK_UP; }));
    const int peer = ::accept(b.fd, nullptr, nullptr);
    ASSERT_GE(peer, 0) << "host 1 is the second address";
    std::uint8_t buf[64];
    EXPECT_EQ(up.read(buf, sizeof buf), 0) << "nothing sent yet: none pending, no block";
    const std::uint8_t hello[5] = {1, 2, 3, 4, 5};
    ASSERT_EQ(::send(peer, hello, sizeof hello, 0), 5);
    int n = 0;
    ASSERT_TRUE(wait_until([&] { return (n = up.read(buf, sizeof buf)) != 0; }));
    EXPECT_EQ(n, 5);
    ::close(peer);
    ASSERT_TRUE(wait_until([&] { return up.read(buf, sizeof buf) < 0; })) << "a closed peer reads as failed";
    EXPECT_EQ(up.state(), SINK_UPLINK_DOWN);
    EXPECT_EQ(up.connect(2), -1) << "no third host";
}

}  // namespace
}  // namespace mocap::sim
