// The output registry (daemon/outputs.hpp): which outputs a config and a replay command
// line register, in frame order. Nothing is started: no socket is bound.
#include <gtest/gtest.h>

#include <filesystem>

#include "daemon/outputs.hpp"
#include "daemon/pipeline_config.hpp"
#include "daemon/wall_clock.hpp"

namespace mocap::daemon {
namespace {

std::vector<std::string> registered(const DaemonConfig& config, const ReplayOptions* replay,
                                    std::shared_ptr<serve::TakeStore> takes = nullptr) {
    WallClock clock;
    std::string error;
    auto pc = pipeline_config_from_config(config, &error);
    EXPECT_TRUE(pc) << error;
    if (!pc) return {};
    auto p = pipeline::Pipeline::create(std::move(*pc), clock, &error);
    EXPECT_TRUE(p) << error;
    if (!p) return {};
    add_outputs({config, *p, clock, {}, {}, {}, replay, nullptr, std::move(takes)}, *p);
    std::vector<std::string> names;
    for (const auto& o : p->outputs())
        names.emplace_back(o->name());
    return names;
}

DaemonConfig default_config() {
    std::string error;
    auto c = parse_config(embedded_default_config(), "<embedded>", &error);
    EXPECT_TRUE(c) << error;
    DaemonConfig config = c ? *c : DaemonConfig{};
    config.max_subjects = 2;
    return config;
}

using Names = std::vector<std::string>;

TEST(OutputRegistry, ConfigSectionsTurnLiveOutputsOnAndOff) {
    DaemonConfig c = default_config();
    c.bvh_live = false;
    c.raw_record = false;
    c.http_enabled = false;
    EXPECT_EQ(registered(c, nullptr), (Names{"pose", "bvh_record"}));
    c.bvh_live = true;
    c.raw_record = true;
    c.http_enabled = true;
    EXPECT_EQ(registered(c, nullptr), (Names{"pose", "bvh_live", "bvh_record", "raw_record", "http"}));
    // [cluster].nats_url: the publisher only exists with a URL (creating it opens nothing).
    c.cluster_nats_url = "nats://127.0.0.1:4222";
    c.cluster_allow_anonymous = true;
    EXPECT_EQ(registered(c, nullptr), (Names{"pose", "bvh_live", "bvh_record", "raw_record", "http", "cluster"}));
    // [vmc].enabled: the sender exists only when asked for (creating it sends nothing).
    c.vmc_enabled = true;
    EXPECT_EQ(registered(c, nullptr),
              (Names{"pose", "bvh_live", "bvh_record", "raw_record", "http", "cluster", "vmc"}));
    // Takes: recorded whenever the daemon gives a take store (creating it writes nothing).
    const auto takes = std::make_shared<serve::TakeStore>("never-created");
    EXPECT_EQ(registered(c, nullptr, takes),
              (Names{"pose", "bvh_live", "bvh_record", "raw_record", "take_record", "http", "cluster", "vmc"}));
    EXPECT_FALSE(std::filesystem::exists("never-created"));
}

TEST(OutputRegistry, ReplayRegistersOnlyTheFilesItsCommandLineAsksFor) {
    DaemonConfig c = default_config();
    c.bvh_live = true;
    c.raw_record = true;
    c.http_enabled = true;
    c.cluster_nats_url = "nats://127.0.0.1:4222";
    ReplayOptions none;
    EXPECT_EQ(registered(c, &none), Names{});
    ReplayOptions both;
    both.bvh_out = "out.bvh";
    both.angles_out = "angles.csv";
    EXPECT_EQ(registered(c, &both), (Names{"bvh_record", "angles_csv"}));
    EXPECT_EQ(registered(c, &both, std::make_shared<serve::TakeStore>("never-created")),
              (Names{"bvh_record", "angles_csv"}))
        << "a replay records no take";
}

TEST(OutputRegistry, EveryEntryHasAUniqueName) {
    std::vector<std::string> names;
    for (const auto& e : output_registry()) {
        ASSERT_NE(e.make, nullptr);
        for (const auto& n : names)
            EXPECT_NE(n, e.name);
        names.emplace_back(e.name);
    }
    EXPECT_EQ(names.size(), 9u);
}

}  // namespace
}  // namespace mocap::daemon
