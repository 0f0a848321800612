#include "core/parse_number.hpp"

#include <gtest/gtest.h>

#include <cstdint>

namespace mocap::core {
namespace {

TEST(ParseNumber, AcceptsWholeTokensOnly) {
    double d = -1;
    EXPECT_TRUE(parse_number("1.5", d));
    EXPECT_EQ(d, 1.5);
    EXPECT_TRUE(parse_number("+2e3", d));
    EXPECT_EQ(d, 2000.0);
    EXPECT_TRUE(parse_number("-0.25", d));
    EXPECT_EQ(d, -0.25);
    for (const char* bad : {"", "+", "1.5x", " 1", "1 ", "+-1", "++1", "nan", "inf", "-inf", "1e999", "0x10"}) {
        d = 7;
        EXPECT_FALSE(parse_number(bad, d)) << bad;
        EXPECT_EQ(d, 7) << "output changed on failure: " << bad;
    }
}

TEST(ParseNumber, IntegersMustFitTheirType) {
    int i = 0;
    EXPECT_TRUE(parse_number("-2147483648", i));
    EXPECT_EQ(i, -2147483648);
    EXPECT_FALSE(parse_number("2147483648", i));
    EXPECT_FALSE(parse_number("4294967300", i));
    EXPECT_FALSE(parse_number("1.0", i));
    std::uint32_t u = 0;
    EXPECT_TRUE(parse_number("+4294967295", u));
    EXPECT_EQ(u, 4294967295u);
    EXPECT_FALSE(parse_number("-1", u));
    EXPECT_FALSE(parse_number("4294967296", u));
    std::uint8_t b = 0;
    EXPECT_FALSE(parse_number("256", b));
}

TEST(SplitFields, KeepsEmptyFields) {
    EXPECT_EQ(split_fields("a:b:c", ':'), (std::vector<std::string_view>{"a", "b", "c"}));
    EXPECT_EQ(split_fields("", ':'), (std::vector<std::string_view>{""}));
    EXPECT_EQ(split_fields("a::", ':'), (std::vector<std::string_view>{"a", "", ""}));
}

}  // namespace
}  // namespace mocap::core
