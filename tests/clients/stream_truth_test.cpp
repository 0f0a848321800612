// mocap-sim stream --truth: the true joint angles in the format of `mocap-client angles`,
// from the daemon's joint-angle code, keyed by the sync value the daemon gives the instant.
#include <gtest/gtest.h>

#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "serve/angles_csv.hpp"
#include "sim/stream_motion.hpp"
#include "sim/stream_truth.hpp"
#include "skeleton/joint_angles.hpp"

namespace mocap::sim {
namespace {

std::vector<std::string> split(const std::string& line) {
    std::vector<std::string> out;
    std::stringstream ss(line);
    for (std::string cell; std::getline(ss, cell, ',');)
        out.push_back(cell);
    return out;
}

TEST(StreamTruth, HeaderIsTheAnglesCsvOfTheDaemonsJoints) {
    const auto model = skeleton::default_body_model();
    const TruthAngles truth(model);
    const auto joints = skeleton::default_joint_specs(model);
    ASSERT_EQ(joints.size(), 10u);
    ASSERT_EQ(truth.names().size(), 30u);
    const std::string header = truth.header();
    EXPECT_EQ(header.rfind("subject,sync,t_s,left_hip.flexion_deg,left_hip.abduction_deg,left_hip.rotation_deg,", 0),
              0u)
        << header;
    EXPECT_EQ(header.back(), '\n');
    const auto cols = split(header.substr(0, header.size() - 1));
    ASSERT_EQ(cols.size(), 33u);
    for (std::size_t j = 0; j < joints.size(); ++j) {
        EXPECT_EQ(cols[3 + 3 * j], joints[j].name + ".flexion_deg");
        EXPECT_EQ(cols[4 + 3 * j], joints[j].name + ".abduction_deg");
        EXPECT_EQ(cols[5 + 3 * j], joints[j].name + ".rotation_deg");
    }
}

TEST(StreamTruth, RowHoldsEachJointsAnatomicalAnglesOfTheTruePose) {
    const auto model = skeleton::default_body_model();
    const StreamMotion walk = StreamMotion::walk(model, 1.0);
    BodyPose pose;
    walk.pose(3.37, 0.8, Vec3(10, 0, 0), pose);
    TruthAngles truth(model);
    std::string row;
    truth.append_row(2, (std::uint64_t{1} << 32) + 337, 1'700'000'000'123'456,
                     std::span(pose.q_earth_segment.data(), 15), row);
    ASSERT_EQ(row.back(), '\n');
    const auto c = split(row.substr(0, row.size() - 1));
    ASSERT_EQ(c.size(), 33u);
    EXPECT_EQ(c[0], "2");
    EXPECT_EQ(c[1], "4294967633");
    EXPECT_EQ(c[2], "1700000000.123456");
    // Each joint on its own, through joint_angles() of its parent and child segment.
    const auto joints = skeleton::default_joint_specs(model);
    double largest = 0.0;
    for (std::size_t j = 0; j < joints.size(); ++j) {
        const auto& s = joints[j];
        const auto a = skeleton::joint_angles(s.kind, s.side, pose.q_earth_segment[s.parent_segment],
                                              pose.q_earth_segment[s.child_segment]);
        const double deg = 180.0 / M_PI;
        EXPECT_NEAR(std::stod(c[3 + 3 * j]), a.flexion_rad * deg, 6e-4) << s.name;
        EXPECT_NEAR(std::stod(c[4 + 3 * j]), a.abduction_rad * deg, 6e-4) << s.name;
        EXPECT_NEAR(std::stod(c[5 + 3 * j]), a.rotation_rad * deg, 6e-4) << s.name;
        largest = std::max(largest, std::abs(a.flexion_rad * deg));
    }
    EXPECT_GT(largest, 20.0) << "mid-stride: the knees and hips are flexed";
}

TEST(StreamTruth, SyncIsTheDaemonsExtendedCounterAcrossTheWrap) {
    SyncExtender s;
    const std::uint64_t base = std::uint64_t{1} << 32;
    EXPECT_EQ(s.extend(4294967294u), base + 4294967294u);
    EXPECT_EQ(s.extend(4294967295u), base + 4294967295u);
    EXPECT_EQ(s.extend(0u), 2 * base);
    EXPECT_EQ(s.extend(1u), 2 * base + 1);
    SyncExtender first;
    EXPECT_EQ(first.extend(0u), base) << "a fresh sink's first instant";
}

}  // namespace
}  // namespace mocap::sim
