#include "daemon/endpoint.hpp"

#include <gtest/gtest.h>

namespace mocap::daemon {
namespace {

TEST(Endpoint, Parsing) {
    std::string err;
    auto v6 = parse_endpoint("[::1]:7001", &err);
    ASSERT_TRUE(v6);
    EXPECT_EQ(v6->host, "::1");
    EXPECT_EQ(v6->str(), "[::1]:7001");
    EXPECT_FALSE(parse_endpoint("1.2.3.4:", &err));
    EXPECT_FALSE(parse_endpoint(":80", &err));
}

TEST(Endpoint, DestinationMayNameAHostAListenerMayNot) {
    std::string err;
    const auto named = parse_destination("receiver.local:39539", &err);
    ASSERT_TRUE(named) << err;
    EXPECT_EQ(named->host, "receiver.local");
    EXPECT_EQ(named->port, 39539);
    EXPECT_FALSE(parse_endpoint("receiver.local:39539", &err));
    EXPECT_NE(err.find("names are not resolved"), std::string::npos) << err;
    EXPECT_FALSE(parse_destination("host:70000", &err));
    EXPECT_EQ(err, "port must be 1..65535");
}

}  // namespace
}  // namespace mocap::daemon
