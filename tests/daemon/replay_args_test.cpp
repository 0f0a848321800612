#include <gtest/gtest.h>

#include "daemon/replay.hpp"

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

}  // namespace
}  // namespace mocap::daemon
