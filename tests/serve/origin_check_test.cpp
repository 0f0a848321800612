// websocket_origin_allowed: Origin against Host and [http] allowed_origins; http_host_allowed:
// Host against the allowed names (DNS rebinding).
#include "serve/origin_check.hpp"

#include <gtest/gtest.h>

namespace mocap::serve {
namespace {

TEST(OriginCheck, SameHostAndPortOrNoOriginAreAllowed) {
    const std::vector<std::string> none;
    EXPECT_TRUE(websocket_origin_allowed("", "127.0.0.1:8080", none)) << "not a browser";
    EXPECT_TRUE(websocket_origin_allowed("http://127.0.0.1:8080", "127.0.0.1:8080", none));
    EXPECT_TRUE(websocket_origin_allowed("http://Viewer.Lab:8080", "viewer.lab:8080", none)) << "host case";
    EXPECT_TRUE(websocket_origin_allowed("http://viewer.lab", "viewer.lab", none)) << "both on port 80";
    EXPECT_TRUE(websocket_origin_allowed("http://viewer.lab:80", "viewer.lab", none));
    EXPECT_TRUE(websocket_origin_allowed("http://[::1]:8080", "[::1]:8080", none));
}

TEST(OriginCheck, ForeignOriginsAreRefused) {
    const std::vector<std::string> none;
    EXPECT_FALSE(websocket_origin_allowed("http://evil.example", "127.0.0.1:8080", none));
    EXPECT_FALSE(websocket_origin_allowed("http://127.0.0.1:8081", "127.0.0.1:8080", none)) << "other port";
    EXPECT_FALSE(websocket_origin_allowed("https://127.0.0.1:8080", "127.0.0.1", none)) << "443 is not 80";
    EXPECT_FALSE(websocket_origin_allowed("null", "127.0.0.1:8080", none));
    EXPECT_FALSE(websocket_origin_allowed("file://", "127.0.0.1:8080", none));
    EXPECT_FALSE(websocket_origin_allowed("http://127.0.0.1:8080@evil", "127.0.0.1:8080", none));
    EXPECT_FALSE(websocket_origin_allowed("http://127.0.0.1:8080", "", none)) << "no Host to compare with";
}

TEST(OriginCheck, TheAllowListAdmitsExactOrigins) {
    const std::vector<std::string> allowed{"https://dash.example:8443/", "null"};
    EXPECT_TRUE(websocket_origin_allowed("https://dash.example:8443", "10.0.0.5:8080", allowed));
    EXPECT_TRUE(websocket_origin_allowed("HTTPS://DASH.EXAMPLE:8443", "10.0.0.5:8080", allowed));
    EXPECT_TRUE(websocket_origin_allowed("null", "10.0.0.5:8080", allowed));
    EXPECT_FALSE(websocket_origin_allowed("https://dash.example", "10.0.0.5:8080", allowed)) << "other port";
}

// A page on evil.example rebound to 127.0.0.1 sends its own name as Host: refused, on any port.
TEST(HostCheck, NamesOutsideTheListAreRefused) {
    const std::vector<std::string> names{"localhost", "capture-host", "Mocap.Lab"};
    EXPECT_FALSE(http_host_allowed("evil.example", names));
    EXPECT_FALSE(http_host_allowed("evil.example:8080", names));
    EXPECT_FALSE(http_host_allowed("localhost.evil.example:8080", names));
    EXPECT_FALSE(http_host_allowed("mocap.lab.evil", names));
    EXPECT_FALSE(http_host_allowed("127.0.0.1.evil.example", names)) << "a name that starts like an address";
    EXPECT_FALSE(http_host_allowed("evil.example@127.0.0.1", names)) << "not host[:port]";
    EXPECT_FALSE(http_host_allowed("[::1", names)) << "unclosed bracket";
    EXPECT_FALSE(http_host_allowed("localhost:80:80", names));
}

TEST(HostCheck, ListedNamesIpLiteralsAndNoHostAreAllowed) {
    const std::vector<std::string> names{"localhost", "capture-host", "Mocap.Lab"};
    EXPECT_TRUE(http_host_allowed("localhost", names));
    EXPECT_TRUE(http_host_allowed("LOCALHOST:8080", names)) << "case and port do not matter";
    EXPECT_TRUE(http_host_allowed("mocap.lab:8080", names));
    EXPECT_TRUE(http_host_allowed("mocap.lab.", names)) << "a trailing dot is the same name";
    EXPECT_TRUE(http_host_allowed("capture-host", names));
    EXPECT_TRUE(http_host_allowed("127.0.0.1:8080", names));
    EXPECT_TRUE(http_host_allowed("10.20.0.5", names));
    EXPECT_TRUE(http_host_allowed("[::1]:8080", names));
    EXPECT_TRUE(http_host_allowed("", names)) << "no Host: not a browser";
    EXPECT_FALSE(http_host_allowed("localhost", {})) << "nothing is implied by the function";
}

}  // namespace
}  // namespace mocap::serve
