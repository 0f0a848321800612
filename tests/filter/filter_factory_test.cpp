#include "filter/filter_factory.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>

#include "filter/madgwick.hpp"
#include "filter/mocap_filter.hpp"

namespace mocap::filter {
namespace {

TEST(FilterFactory, EveryNameBuildsAndReportsItsName) {
    const auto names = filter_names();
    ASSERT_FALSE(names.empty());
    EXPECT_EQ(names.front(), "mocap");
    for (const std::string_view n : {"mocap", "madgwick", "mahony", "csmo", "pf"}) {
        EXPECT_NE(std::find(names.begin(), names.end(), n), names.end()) << n;
    }
    for (const std::string_view name : names) {
        std::string error;
        const auto f = make_filter(name, {}, &error);
        ASSERT_NE(f, nullptr) << name << ": " << error;
        EXPECT_EQ(f->name(), name);
        EXPECT_TRUE(error.empty());
    }
}

TEST(FilterFactory, EveryListedKeyAcceptsItsDefault) {
    for (const std::string_view name : filter_names()) {
        const auto keys = filter_keys(name);
        EXPECT_FALSE(keys.empty()) << name;
        for (const FilterKey& k : keys) {
            std::string error;
            const auto f = make_filter(name, {{std::string(k.key), k.default_value}}, &error);
            EXPECT_NE(f, nullptr) << name << " " << k.key << "=" << k.default_value << ": " << error;
        }
    }
}

// The keys documented in a Params struct of a header: every `key "..."` between
// `struct <params> {` and the closing `};`.
std::set<std::string> documented_keys(const std::string& header, const std::string& params) {
    std::ifstream in(std::string(MOCAP_SOURCE_DIR) + "/server/filter/" + header);
    std::stringstream ss;
    ss << in.rdbuf();
    const std::string text = ss.str();
    const auto begin = text.find("struct " + params + " {");
    const auto end = text.find("\n};", begin);
    std::set<std::string> keys;
    if (begin == std::string::npos || end == std::string::npos) return keys;
    const std::string body = text.substr(begin, end - begin);
    const std::regex re("key \"([a-z0-9_]+)\"");
    for (auto it = std::sregex_iterator(body.begin(), body.end(), re); it != std::sregex_iterator(); ++it) {
        keys.insert((*it)[1].str());
    }
    return keys;
}

TEST(FilterFactory, ListedKeysAreExactlyTheDocumentedOnes) {
    const std::pair<std::string_view, std::pair<std::string, std::string>> headers[] = {
        {"mocap", {"mocap_filter.hpp", "MocapFilterParams"}},
        {"madgwick", {"madgwick.hpp", "MadgwickParams"}},
        {"mahony", {"mahony.hpp", "MahonyParams"}},
        {"csmo", {"csmo.hpp", "CsmoParams"}},
        {"pf", {"particle_filter.hpp", "ParticleFilterParams"}},
    };
    for (const auto& [name, where] : headers) {
        const std::set<std::string> documented = documented_keys(where.first, where.second);
        EXPECT_FALSE(documented.empty()) << where.first;
        std::set<std::string> listed;
        for (const FilterKey& k : filter_keys(name))
            listed.insert(std::string(k.key));
        EXPECT_EQ(listed, documented) << name;
    }
}

TEST(FilterFactory, ValuesAreApplied) {
    std::string error;
    auto f = make_filter("madgwick", {{"beta", "0.25"}, {"init_from_first_sample", "off"}}, &error);
    ASSERT_NE(f, nullptr) << error;
    const auto* m = dynamic_cast<const MadgwickFilter*>(f.get());
    ASSERT_NE(m, nullptr);
    EXPECT_DOUBLE_EQ(m->params().beta, 0.25);
    EXPECT_FALSE(m->params().init_from_first_sample);

    f = make_filter("mocap", {{"tau_mag_s", "20"}, {"tau_mag_s", "30"}, {"mag_guard", "false"}}, &error);
    ASSERT_NE(f, nullptr) << error;
    const auto* v = dynamic_cast<const MocapFilter*>(f.get());
    ASSERT_NE(v, nullptr);
    EXPECT_DOUBLE_EQ(v->params().tau_mag_s, 30.0);  // last value wins
    EXPECT_FALSE(v->params().mag_guard);
}

TEST(FilterFactory, RejectsUnknownNamesKeysAndBadValues) {
    std::string error;
    EXPECT_EQ(make_filter("kalman", {}, &error), nullptr);
    EXPECT_NE(error.find("kalman"), std::string::npos) << error;
    EXPECT_NE(error.find("mocap"), std::string::npos) << error;  // lists the known ones

    EXPECT_EQ(make_filter("madgwick", {{"gain", "0.1"}}, &error), nullptr);
    EXPECT_NE(error.find("\"gain\""), std::string::npos) << error;

    for (const char* bad : {"", "abc", "0.1x", "1e", " 0.1", "0,1"}) {
        EXPECT_EQ(make_filter("madgwick", {{"beta", bad}}, &error), nullptr) << bad;
        EXPECT_NE(error.find("\"beta\""), std::string::npos) << error;
    }
    EXPECT_EQ(make_filter("mocap", {{"mag_guard", "maybe"}}, &error), nullptr);
    EXPECT_NE(error.find("mag_guard"), std::string::npos) << error;
    EXPECT_EQ(make_filter("csmo", {{"lm_iterations", "2.5"}}, &error), nullptr);
    EXPECT_NE(error.find("lm_iterations"), std::string::npos) << error;

    EXPECT_EQ(make_filter("pf", {{"seed", "-1"}}, &error), nullptr);
    EXPECT_NE(error.find("seed"), std::string::npos) << error;

    // Parsed but out of range: the filter's own check names the key.
    EXPECT_EQ(make_filter("mocap", {{"tau_acc_s", "-1"}}, &error), nullptr);
    EXPECT_NE(error.find("tau_acc_s"), std::string::npos) << error;
    EXPECT_EQ(make_filter("mocap", {{"tau_acc_s", "nan"}}, &error), nullptr);
    EXPECT_NE(error.find("tau_acc_s"), std::string::npos) << error;
    EXPECT_EQ(make_filter("csmo", {{"rho", "0"}}, &error), nullptr);
    EXPECT_NE(error.find("rho"), std::string::npos) << error;
    EXPECT_EQ(make_filter("pf", {{"particles", "0"}}, &error), nullptr);
    EXPECT_NE(error.find("particles"), std::string::npos) << error;

    // No error pointer: still nullptr, no crash.
    EXPECT_EQ(make_filter("nope", {}), nullptr);
}

TEST(FilterFactory, UnknownNameHasNoKeys) {
    EXPECT_TRUE(filter_keys("nope").empty());
}

TEST(FilterFactory, CostWeightSetsTheParticleFilterApart) {
    EXPECT_EQ(filter_cost_weight("pf"), 20u);
    for (std::string_view name : filter_names()) {
        if (name == "pf") continue;
        EXPECT_EQ(filter_cost_weight(name), 1u) << name;
    }
    EXPECT_EQ(filter_cost_weight("nope"), 1u) << "an unknown name weighs as a plain filter";
}

// Every number a filter takes has a finite range (the seed and booleans excepted); a value
// beyond it is refused naming the key, and so is every non-finite one. Before, only lower
// bounds were checked: `beta = 1e308` built a filter whose every output was NaN.
TEST(FilterParamRanges, EveryNumberHasAFiniteRangeHoldingItsDefault) {
    for (const std::string_view name : filter_names()) {
        for (const FilterKey& k : filter_keys(name)) {
            const bool boolean = k.default_value == "true" || k.default_value == "false";
            if (boolean || k.key == "seed") continue;
            EXPECT_TRUE(std::isfinite(k.min) && std::isfinite(k.max)) << name << " " << k.key;
            EXPECT_LT(k.min, k.max) << name << " " << k.key;
            if (k.default_value != "nan") {
                const double d = std::stod(k.default_value);
                EXPECT_TRUE(d >= k.min && d <= k.max) << name << " " << k.key << "=" << k.default_value;
            }
        }
    }
}

TEST(FilterParamRanges, ValuesBeyondTheRangeAreRefusedNamingTheKey) {
    for (const std::string_view name : filter_names()) {
        for (const FilterKey& k : filter_keys(name)) {
            const bool boolean = k.default_value == "true" || k.default_value == "false";
            if (boolean || k.key == "seed") continue;
            for (const std::string value : {"1e308", "-1e308", "inf", "-inf"}) {
                std::string error;
                EXPECT_EQ(make_filter(name, {{std::string(k.key), value}}, &error), nullptr)
                    << name << " " << k.key << "=" << value;
                EXPECT_NE(error.find(std::string(1, '"').append(k.key).append(1, '"')), std::string::npos) << error;
            }
            std::string error;
            const bool nan_ok = k.default_value == "nan";
            EXPECT_EQ(make_filter(name, {{std::string(k.key), "nan"}}, &error) != nullptr, nan_ok)
                << name << " " << k.key << ": " << error;
        }
    }
    std::string error;
    EXPECT_EQ(make_filter("madgwick", {{"beta", "1e308"}}, &error), nullptr);
    EXPECT_EQ(error, "parameter \"beta\" of filter \"madgwick\": 1e308 is outside 0..10");
    EXPECT_NE(make_filter("madgwick", {{"beta", "10"}}, &error), nullptr) << "the bounds are inclusive: " << error;
    EXPECT_EQ(make_filter("pf", {{"particles", "65537"}}, &error), nullptr);
    EXPECT_EQ(make_filter("csmo", {{"dip_deg", "90.5"}}, &error), nullptr);
    EXPECT_NE(make_filter("csmo", {{"dip_deg", "60"}}, &error), nullptr) << error;
}

}  // namespace
}  // namespace mocap::filter
