#include <gtest/gtest.h>

#include "daemon/replay_args.hpp"

namespace mocap::daemon {
namespace {

TEST(ReplayArgs, CalibrateAtTakesSecondsSubjectAndPose) {
    ReplayCalibration c;
    std::string error;
    ASSERT_TRUE(parse_replay_calibration("0.8", &c, &error)) << error;
    EXPECT_EQ(c.at_s, 0.8);
    EXPECT_EQ(c.subject, 1u);
    EXPECT_EQ(c.pose, skeleton::CalibrationPose::kTPose);
    ASSERT_TRUE(parse_replay_calibration("2:3:N", &c, &error)) << error;
    EXPECT_EQ(c.at_s, 2.0);
    EXPECT_EQ(c.subject, 3u);
    EXPECT_EQ(c.pose, skeleton::CalibrationPose::kNPose);
    ASSERT_TRUE(parse_replay_calibration("0.5:2:t", &c, &error)) << error;
    EXPECT_EQ(c.pose, skeleton::CalibrationPose::kTPose);
}

TEST(ReplayArgs, CalibrateAtRejectsWhatSscanfAccepted) {
    ReplayCalibration c;
    std::string error;
    for (const char* bad :
         {"", "x", "1x", "-1", "nan", "1:0", "1:-1", "1:4294967296", "1:2:X", "1:2:TT", "1:2:T:4", "1:", "1e999"}) {
        error.clear();
        EXPECT_FALSE(parse_replay_calibration(bad, &c, &error)) << bad;
        EXPECT_NE(error.find("SECONDS[:SUBJECT[:T|N]]"), std::string::npos) << bad;
    }
}

TEST(ReplayArgs, TimesAreEpochSecondsOrRfc3339) {
    std::int64_t us = 0;
    std::string error;
    ASSERT_TRUE(parse_replay_time("1764648000", &us, &error)) << error;
    EXPECT_EQ(us, 1'764'648'000'000'000);
    ASSERT_TRUE(parse_replay_time("1764648000.25", &us, &error)) << error;
    EXPECT_EQ(us, 1'764'648'000'250'000);
    ASSERT_TRUE(parse_replay_time("2025-12-02T04:00:00Z", &us, &error)) << error;
    EXPECT_EQ(us, 1'764'648'000'000'000);
    ASSERT_TRUE(parse_replay_time("2025-12-02T05:30:00.5+01:30", &us, &error)) << error;
    EXPECT_EQ(us, 1'764'648'000'500'000);
    ASSERT_TRUE(parse_replay_time("2025-12-02t03:00:00.000001-01:00", &us, &error)) << error;
    EXPECT_EQ(us, 1'764'648'000'000'001);
    for (const char* bad :
         {"", "x", "-1", "1.", ".5", "1e9", "2025-12-02T04:00:00", "2025-12-02T04:00:00+0100", "2025-13-02T04:00:00Z",
          "2025-12-02T04:00Z", "2025-12-02T04:00:00Zx", "2025-12-02T04:00:00.Z"}) {
        error.clear();
        EXPECT_FALSE(parse_replay_time(bad, &us, &error)) << bad;
        EXPECT_NE(error.find("RFC 3339"), std::string::npos) << bad;
    }
}

}  // namespace
}  // namespace mocap::daemon
