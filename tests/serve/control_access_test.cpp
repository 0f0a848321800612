// control_access_test.cpp — the control rules shared by the pose service and HTTP: the
// loopback rule for every address family, the token comparison, the order of the checks
// and which counter each refusal lands in.
#include "serve/control_access.hpp"

#include <gtest/gtest.h>

#include <map>

#include "serve/serve_counters.hpp"

namespace mocap::serve {
namespace {

TEST(ControlAccess, LoopbackRuleCoversIpv4Ipv6AndMappedIpv4) {
    auto loop = [](const char* a) { return is_loopback(asio::ip::make_address(a)); };
    EXPECT_TRUE(loop("127.0.0.1"));
    EXPECT_TRUE(loop("127.200.3.4"));  // all of 127/8
    EXPECT_TRUE(loop("::1"));
    EXPECT_TRUE(loop("::ffff:127.0.0.1"));
    EXPECT_TRUE(loop("::ffff:127.9.9.9"));
    EXPECT_FALSE(loop("10.0.0.1"));
    EXPECT_FALSE(loop("192.168.1.20"));
    EXPECT_FALSE(loop("0.0.0.0"));
    EXPECT_FALSE(loop("::"));
    EXPECT_FALSE(loop("fe80::1"));
    EXPECT_FALSE(loop("::ffff:10.0.0.1"));
    EXPECT_FALSE(loop("::ffff:128.0.0.1"));
}

TEST(ControlAccess, PeerOnLoopbackNeedsAConnectedPeer) {
    asio::io_context io;
    asio::ip::tcp::socket unconnected(io);
    EXPECT_FALSE(peer_on_loopback(unconnected));

    asio::ip::tcp::acceptor acceptor(io, {asio::ip::make_address("127.0.0.1"), 0});
    asio::ip::tcp::socket client(io);
    client.connect(acceptor.local_endpoint());
    asio::ip::tcp::socket server_side = acceptor.accept();
    EXPECT_TRUE(peer_on_loopback(server_side));
    EXPECT_TRUE(peer_on_loopback(client));
}

TEST(ControlAccess, TokenEqual) {
    EXPECT_TRUE(token_equal("s3cret", "s3cret"));
    EXPECT_TRUE(token_equal("", ""));
    EXPECT_FALSE(token_equal("s3cret", "s3cre"));    // prefix
    EXPECT_FALSE(token_equal("s3cret", "s3cretX"));  // longer
    EXPECT_FALSE(token_equal("s3cret", "S3cret"));   // first byte
    EXPECT_FALSE(token_equal("s3cret", "s3creT"));   // last byte
    EXPECT_FALSE(token_equal("s3cret", ""));
    // Shorter strings compare as if padded with zero bytes, but the length still differs.
    EXPECT_FALSE(token_equal(std::string_view("ab\0", 3), "ab"));
}

struct Counts {
    std::map<std::string, std::uint64_t> by_name;
    explicit Counts(const ControlCounters& c) {
        CounterGroup group("x");
        c.register_in(group);
        for (const CounterValue& n : group.snapshot())
            by_name["x." + n.name] = n.value;
    }
};

TEST(ControlAccess, RulesApplyInOrderAndCountEachRefusalOnce) {
    ControlCounters c;
    LogLimiter log;
    auto check = [&](std::string_view token, bool loopback_only, bool peer_loopback, std::string_view given) {
        return authorize_control({token, loopback_only}, peer_loopback, given, c, log, "test: control request");
    };
    // No token configured: refused before anything else, even the right-looking token.
    auto r = check("", true, true, "");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->kind, ControlRefusal::kDisabled);
    EXPECT_STREQ(r->reason, "control disabled (no token configured)");
    // A remote peer is refused before its token is looked at.
    r = check("s3cret", true, false, "s3cret");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->kind, ControlRefusal::kNotLoopback);
    EXPECT_STREQ(r->reason, "control only from loopback");
    r = check("s3cret", true, true, "");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->kind, ControlRefusal::kNoToken);
    EXPECT_STREQ(r->reason, "token required");
    r = check("s3cret", true, true, "s3cre");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->kind, ControlRefusal::kBadToken);
    EXPECT_STREQ(r->reason, "bad token");
    // Authorised: on loopback, or from anywhere when loopback_only is off.
    EXPECT_FALSE(check("s3cret", true, true, "s3cret"));
    EXPECT_FALSE(check("s3cret", false, false, "s3cret"));

    c.count_result(ControlResult::success());
    c.count_result(ControlResult::failure("disk full"));
    c.count_result(ControlResult::failure("busy"));
    const Counts n(c);
    EXPECT_EQ(n.by_name.size(), 6u);
    EXPECT_EQ(n.by_name.at("x.control_refused_disabled"), 1u);
    EXPECT_EQ(n.by_name.at("x.control_refused_not_loopback"), 1u);
    EXPECT_EQ(n.by_name.at("x.control_refused_no_token"), 1u);
    EXPECT_EQ(n.by_name.at("x.control_refused_bad_token"), 1u);
    EXPECT_EQ(n.by_name.at("x.control_ok"), 1u);
    EXPECT_EQ(n.by_name.at("x.control_failed"), 2u);
}

TEST(ControlAccess, OwnersKeepTheirExposedNames) {
    // Dashboards read these names: serve.control_* in Stats, http.control_* in /metrics.
    ServeCounters serve;
    std::vector<std::string> names;
    for (const CounterValue& n : serve.group.snapshot())
        if (n.name.find("control_") != std::string::npos) names.push_back(serve.group.component() + "." + n.name);
    EXPECT_EQ(names, (std::vector<std::string>{"serve.control_ok", "serve.control_failed",
                                               "serve.control_refused_disabled", "serve.control_refused_not_loopback",
                                               "serve.control_refused_no_token", "serve.control_refused_bad_token"}));
}

}  // namespace
}  // namespace mocap::serve
