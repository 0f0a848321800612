#include "daemon/config_table_reader.hpp"

#include <gtest/gtest.h>

#include <functional>
#include <string>

namespace mocap::daemon {
namespace {

// The ConfigError `f` throws; a test failure if it throws none.
ConfigError error_of(const std::function<void()>& f) {
    try {
        f();
    } catch (const ConfigError& e) {
        return e;
    }
    ADD_FAILURE() << "no ConfigError";
    return {};
}

TEST(ConfigTableReader, ReadsTypedValuesWithinTheirRanges) {
    const toml::table t = toml::parse("name = \"a\"\nrate = 2\nn = 7\nlisten = \"127.0.0.1:7000\"\noff = 0\n");
    TableReader r(t, "sec");
    std::string name;
    double rate = 0.0;
    int n = 0;
    Endpoint listen;
    double off = 5.0;
    double absent = 3.5;
    r.read("name", name);
    r.read("rate", rate, 0.0, 10.0);
    r.read("n", n, 1, 10);
    r.read("listen", listen);
    r.read_zero_or("off", off, 0.1, 1.0);
    r.read("absent", absent, 0.0, 10.0);
    r.finish();
    EXPECT_EQ(name, "a");
    EXPECT_EQ(rate, 2.0);  // an integer where a number is asked for
    EXPECT_EQ(n, 7);
    EXPECT_EQ(listen.str(), "127.0.0.1:7000");
    EXPECT_EQ(off, 0.0);
    EXPECT_EQ(absent, 3.5) << "an absent key keeps the default";
}

TEST(ConfigTableReader, UnknownKeyNamesItsPathAndLine) {
    const toml::table t = toml::parse("a = 1\nb = 2\n");
    TableReader r(t, "sec");
    int a = 0;
    r.read("a", a, 0, 5);
    const ConfigError e = error_of([&] { r.finish(); });
    EXPECT_EQ(e.key, "sec.b");
    EXPECT_EQ(e.line, 2u);
    EXPECT_EQ(e.message, "unknown key");
}

TEST(ConfigTableReader, TypeAndRangeErrorsNameTheKeyAndLine) {
    const toml::table t = toml::parse("x = 11\ny = \"s\"\nz = 0.001\nw = 1.5\nh = \"name:80\"\n");
    TableReader r(t, "");
    int x = 0;
    double y = 0.0, z = 0.0;
    int w = 0;
    Endpoint h;
    ConfigError e = error_of([&] { r.read("x", x, 0, 10); });
    EXPECT_EQ(e.key, "x");
    EXPECT_EQ(e.line, 1u);
    EXPECT_EQ(e.message, "must be between 0 and 10");
    e = error_of([&] { r.read("y", y, 0.0, 1.0); });
    EXPECT_EQ(e.line, 2u);
    EXPECT_EQ(e.message, "expected a number");
    e = error_of([&] { r.read_zero_or("z", z, 0.1, 1.0); });
    EXPECT_EQ(e.message, "must be 0 (off) or between 0.1 and 1");
    e = error_of([&] { r.read("w", w, 0, 10); });
    EXPECT_EQ(e.message, "expected an integer");
    e = error_of([&] { r.read("h", h); });
    EXPECT_EQ(e.line, 5u);
    EXPECT_NE(e.message.find("must be an IPv4 or IPv6 address"), std::string::npos) << e.message;
    EXPECT_EQ(x, 0) << "a refused value is not stored";
}

TEST(ConfigTableReader, SubTablesAndArraysAreTypeChecked) {
    const toml::table t = toml::parse("s = 1\na = [1, 2]\n[t]\nk = 1\n");
    TableReader r(t, "sec");
    EXPECT_EQ(error_of([&] { r.sub_table("s"); }).message, "expected a table");
    EXPECT_EQ(error_of([&] { r.array("t"); }).message, "expected an array");
    ASSERT_NE(r.array("a"), nullptr);
    EXPECT_EQ(r.array("a")->size(), 2u);
    ASSERT_NE(r.sub_table("t"), nullptr);
    EXPECT_EQ(r.sub_table("missing"), nullptr);
    EXPECT_EQ(TableReader(*r.sub_table("t"), r.key_path("t")).key_path("k"), "sec.t.k");
}

}  // namespace
}  // namespace mocap::daemon
