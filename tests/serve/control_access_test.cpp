// control_access_test.cpp — the control rules shared by the pose service and HTTP: the
// loopback rule for every address family, the token comparison, the order of the checks
// and which counter each refusal lands in.
#include "serve/control_access.hpp"

#include <gtest/gtest.h>

#include <functional>
#include <map>
#include <string>

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
    ControlAttemptLimiter attempts;
    auto check = [&](std::string_view token, bool loopback_only, bool peer_loopback, std::string_view given) {
        const auto peer = asio::ip::make_address(peer_loopback ? "127.0.0.1" : "10.0.0.1");
        return authorize_control({token, loopback_only, &attempts}, peer, given, c, log, "test: control request");
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
    EXPECT_EQ(n.by_name.size(), 7u);
    EXPECT_EQ(n.by_name.at("x.control_refused_disabled"), 1u);
    EXPECT_EQ(n.by_name.at("x.control_refused_not_loopback"), 1u);
    EXPECT_EQ(n.by_name.at("x.control_refused_no_token"), 1u);
    EXPECT_EQ(n.by_name.at("x.control_refused_bad_token"), 1u);
    EXPECT_EQ(n.by_name.at("x.control_refused_throttled"), 0u);
    EXPECT_EQ(n.by_name.at("x.control_ok"), 1u);
    EXPECT_EQ(n.by_name.at("x.control_failed"), 2u);
}

TEST(ControlAccess, OwnersKeepTheirExposedNames) {
    // Dashboards read these names: serve.control_* in Stats, http.control_* in /metrics.
    ServeCounters serve;
    std::vector<std::string> names;
    for (const CounterValue& n : serve.group.snapshot())
        if (n.name.find("control_") != std::string::npos) names.push_back(serve.group.component() + "." + n.name);
    EXPECT_EQ(names,
              (std::vector<std::string>{"serve.control_ok", "serve.control_failed", "serve.control_refused_disabled",
                                        "serve.control_refused_not_loopback", "serve.control_refused_no_token",
                                        "serve.control_refused_bad_token", "serve.control_refused_throttled"}));
}

// A manual clock for the failed-attempt limiter (docs/style.md, "Inject time").
struct ManualClock {
    std::int64_t now_us = 1'000'000;
    std::function<std::int64_t()> fn() {
        return [this] { return now_us; };
    }
};

asio::ip::address addr(const char* text) {
    return asio::ip::make_address(text);
}

// Issue 13, item 8: the token could be guessed at ~40 000 tries a second by reconnecting,
// because the only limit was per connection. Failures are now limited per address.
TEST(ControlAttemptLimiter, FailuresArePerAddressAndRefillWithTime) {
    ManualClock clock;
    ControlAttemptLimiter limiter({3.0, 0.5, 100.0, 100.0, 8}, clock.fn());
    const auto a = addr("10.0.0.1");
    for (int i = 0; i < 3; ++i)
        EXPECT_TRUE(limiter.try_begin(a)) << i;
    EXPECT_FALSE(limiter.try_begin(a)) << "the burst is used up";
    EXPECT_TRUE(limiter.try_begin(addr("10.0.0.2"))) << "another address has its own bucket";
    clock.now_us += 1'999'999;
    EXPECT_FALSE(limiter.try_begin(a)) << "0.5 per second: not yet 2 s";
    clock.now_us += 1;
    EXPECT_TRUE(limiter.try_begin(a));
    EXPECT_FALSE(limiter.try_begin(a));
}

TEST(ControlAttemptLimiter, TheRightTokenIsGivenBack) {
    ManualClock clock;
    ControlAttemptLimiter limiter({2.0, 0.5, 2.0, 0.5, 8}, clock.fn());
    const auto a = addr("127.0.0.1");
    for (int i = 0; i < 50; ++i) {  // an operator using the right token, many times
        ASSERT_TRUE(limiter.try_begin(a)) << i;
        limiter.succeeded(a);
    }
}

TEST(ControlAttemptLimiter, TheGlobalBucketBoundsManyAddresses) {
    ManualClock clock;
    ControlAttemptLimiter limiter({5.0, 0.5, 4.0, 1.0, 1000}, clock.fn());
    for (int i = 1; i <= 4; ++i)
        EXPECT_TRUE(limiter.try_begin(addr(("10.1.0." + std::to_string(i)).c_str())));
    EXPECT_FALSE(limiter.try_begin(addr("10.1.0.5"))) << "a fresh address meets the global limit";
    clock.now_us += 1'000'000;
    EXPECT_TRUE(limiter.try_begin(addr("10.1.0.6")));
    EXPECT_FALSE(limiter.try_begin(addr("10.1.0.7")));
}

TEST(ControlAttemptLimiter, TableIsBoundedAndIpv6CountsByItsSlash64) {
    ManualClock clock;
    ControlAttemptLimiter limiter({2.0, 0.001, 1e9, 1e9, 4}, clock.fn());
    for (int i = 1; i <= 40; ++i)
        EXPECT_TRUE(limiter.try_begin(addr(("10.2.0." + std::to_string(i)).c_str())));
    EXPECT_EQ(limiter.tracked_addresses(), 4u);

    EXPECT_TRUE(limiter.try_begin(addr("2001:db8:0:1::1")));
    EXPECT_TRUE(limiter.try_begin(addr("2001:db8:0:1::2")));
    EXPECT_FALSE(limiter.try_begin(addr("2001:db8:0:1:ffff::9"))) << "same /64";
    EXPECT_TRUE(limiter.try_begin(addr("2001:db8:0:2::1"))) << "another /64";

    EXPECT_TRUE(limiter.try_begin(addr("10.3.0.1")));
    EXPECT_TRUE(limiter.try_begin(addr("::ffff:10.3.0.1")));
    EXPECT_FALSE(limiter.try_begin(addr("10.3.0.1"))) << "IPv4 mapped into IPv6 is the same address";
}

// Over the limit the token is not compared: the right token is refused too (counted as
// throttled, logged on its own line), until the window has passed; another address is
// unaffected.
TEST(ControlAccess, ThrottledAttemptsAreRefusedWithoutComparingTheToken) {
    ManualClock clock;
    ControlAttemptLimiter limiter({2.0, 0.5, 100.0, 100.0, 8}, clock.fn());
    ControlCounters c;
    LogLimiter log;
    const ControlPolicy policy{"0123456789abcdef", true, &limiter};
    auto check = [&](const char* peer, std::string_view given) {
        return authorize_control(policy, addr(peer), given, c, log, "test: control request");
    };
    for (int i = 0; i < 2; ++i) {
        const auto r = check("127.0.0.1", "wrong-guess");
        ASSERT_TRUE(r);
        EXPECT_EQ(r->kind, ControlRefusal::kBadToken);
    }
    auto r = check("127.0.0.1", "0123456789abcdef");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->kind, ControlRefusal::kThrottled);
    EXPECT_STREQ(r->reason, "too many failed control attempts, try again later");
    EXPECT_FALSE(check("127.0.0.2", "0123456789abcdef")) << "another address";
    clock.now_us += 2'000'000;
    EXPECT_FALSE(check("127.0.0.1", "0123456789abcdef")) << "after the window";
    EXPECT_EQ(c.refused_bad_token.value(), 2u);
    EXPECT_EQ(c.refused_throttled.value(), 1u);
}

}  // namespace
}  // namespace mocap::serve
