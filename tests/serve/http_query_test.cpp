// Query strings of the web endpoint (serve/http_query.hpp).
#include "serve/http_query.hpp"

#include <gtest/gtest.h>

namespace mocap::serve {
namespace {

TEST(HttpQuery, FindsAValueByItsWholeKey) {
    EXPECT_EQ(query_value("a=1&name=walk&b", "name"), "walk");
    EXPECT_EQ(query_value("a=1&b", "b"), "");
    EXPECT_EQ(query_value("names=x", "name"), std::nullopt);
    EXPECT_EQ(query_value("", "name"), std::nullopt);
}

TEST(HttpQuery, DecodesPercentEscapesAndPlus) {
    EXPECT_EQ(percent_decode("first+take%21%0Aline%2fx"), "first take!\nline/x");
    EXPECT_EQ(percent_decode("%E2%9C%93"), "\xE2\x9C\x93");
    EXPECT_EQ(percent_decode(""), "");
    for (const char* bad : {"%", "%4", "%G1", "a%zz", "%%"})
        EXPECT_EQ(percent_decode(bad), std::nullopt) << bad;
}

TEST(HttpQuery, ParsesOnlyWholeUnsignedNumbers) {
    EXPECT_EQ(parse_u32("7"), 7u);
    EXPECT_EQ(parse_u32("4294967295"), 4294967295u);
    for (const char* bad : {"", "-1", "4294967296", "7x", " 7"})
        EXPECT_EQ(parse_u32(bad), std::nullopt) << bad;
}

}  // namespace
}  // namespace mocap::serve
