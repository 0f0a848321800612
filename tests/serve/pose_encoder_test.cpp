// Encoder round trip: encode -> parse -> same values, for each field selection.
#include "serve/pose_encoder.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "mocap/v1/mocap.pb.h"
#include "serve/framing.hpp"

namespace mocap::serve {
namespace {

struct Sample {
    SubjectFrame frame;
    skeleton::SkeletonPose pose;
};

Sample make_sample(std::uint16_t segments) {
    Sample s;
    s.frame.subject_id = 42;
    s.frame.sync = (1ull << 33) + 17;  // beyond 32 bits: extended SYNC counter
    s.frame.sample_us = 1'700'000'000'123'456;
    s.frame.times = {1'700'000'000'100'000, 1'700'000'000'100'050, 1'700'000'000'100'070, 1'700'000'000'100'090, 0};
    s.frame.segment_count = segments;
    s.pose.segment_count = segments;
    for (std::uint16_t i = 0; i < segments; ++i) {
        const double a = 0.1 * i;
        s.frame.segments[i].q_earth_sensor_wxyz = {std::cos(a), std::sin(a), 0.0, 0.0};
        s.frame.segments[i].flags = (i % 3 == 0) ? kSegmentStale : 0;
        s.pose.q_world_segment_wxyz[i] = {std::cos(a), 0.0, std::sin(a), 0.0};
        s.pose.position_m[i] = {0.01 * i, -0.02 * i, 1.0 + 0.03 * i};
        s.pose.extra_flags[i] = kSegmentCalibrated;
    }
    s.pose.joint_angle_count = 5;
    for (std::uint16_t j = 0; j < 5; ++j)
        s.pose.joint_angles_rad[j] = -0.5 + 0.25 * j;
    return s;
}

v1::ServerMessage parse(const SharedBytes& bytes) {
    EXPECT_TRUE(bytes);
    DelimitedReader reader(1 << 20);
    auto area = reader.write_area();
    EXPECT_GE(area.size(), bytes->size());
    std::copy(bytes->begin(), bytes->end(), area.begin());
    reader.commit(bytes->size());
    FrameResult r = reader.next();
    EXPECT_EQ(r.status, FrameStatus::kMessage);
    EXPECT_EQ(reader.buffered(), 0u);  // exactly one message, prefix included
    v1::ServerMessage msg;
    EXPECT_TRUE(msg.ParseFromArray(r.payload.data(), static_cast<int>(r.payload.size())));
    return msg;
}

TEST(PoseEncoder, RoundTripAllFields) {
    const Sample s = make_sample(15);
    PoseEncoder encoder;
    const v1::ServerMessage msg = parse(encoder.encode_frame(s.frame, s.pose, kFieldAll, 99));
    ASSERT_TRUE(msg.has_frame());
    const v1::SkeletonFrame& f = msg.frame();
    EXPECT_EQ(f.subject_id(), 42u);
    EXPECT_EQ(f.sync(), s.frame.sync);
    EXPECT_EQ(f.sample_us(), s.frame.sample_us);
    EXPECT_EQ(f.times().sink_send_us(), s.frame.times.sink_send_us);
    EXPECT_EQ(f.times().received_us(), s.frame.times.received_us);
    EXPECT_EQ(f.times().filtered_us(), s.frame.times.filtered_us);
    EXPECT_EQ(f.times().assembled_us(), s.frame.times.assembled_us);
    EXPECT_EQ(f.times().encoded_us(), 99);
    ASSERT_EQ(f.segment_count(), 15u);
    ASSERT_EQ(f.flags_size(), 15);
    ASSERT_EQ(f.q_world_segment_wxyz_size(), 60);
    ASSERT_EQ(f.position_m_size(), 45);
    ASSERT_EQ(f.q_earth_sensor_wxyz_size(), 60);
    ASSERT_EQ(f.joint_angles_rad_size(), 5);
    for (int i = 0; i < 15; ++i) {
        const auto u = static_cast<std::size_t>(i);
        EXPECT_EQ(f.flags(i), s.frame.segments[u].flags | kSegmentCalibrated);
        for (int c = 0; c < 4; ++c) {
            EXPECT_FLOAT_EQ(f.q_world_segment_wxyz(4 * i + c),
                            static_cast<float>(s.pose.q_world_segment_wxyz[u][std::size_t(c)]));
            EXPECT_FLOAT_EQ(f.q_earth_sensor_wxyz(4 * i + c),
                            static_cast<float>(s.frame.segments[u].q_earth_sensor_wxyz[std::size_t(c)]));
        }
        for (int c = 0; c < 3; ++c) {
            EXPECT_FLOAT_EQ(f.position_m(3 * i + c), static_cast<float>(s.pose.position_m[u][std::size_t(c)]));
        }
    }
    for (int j = 0; j < 5; ++j) {
        EXPECT_FLOAT_EQ(f.joint_angles_rad(j), static_cast<float>(s.pose.joint_angles_rad[std::size_t(j)]));
    }
}

TEST(PoseEncoder, FieldSelectionLeavesOtherArraysEmpty) {
    const Sample s = make_sample(4);
    PoseEncoder encoder;
    // Encode a full frame first so the reused message has filled arrays to clear.
    (void)encoder.encode_frame(s.frame, s.pose, kFieldAll, 1);
    const v1::SkeletonFrame f = parse(encoder.encode_frame(s.frame, s.pose, kFieldOrientations, 2)).frame();
    EXPECT_EQ(f.q_world_segment_wxyz_size(), 16);
    EXPECT_EQ(f.position_m_size(), 0);
    EXPECT_EQ(f.joint_angles_rad_size(), 0);
    EXPECT_EQ(f.q_earth_sensor_wxyz_size(), 0);
    EXPECT_EQ(f.flags_size(), 4);  // flags always travel

    const v1::SkeletonFrame d = parse(encoder.encode_frame(s.frame, s.pose, 0, 3)).frame();
    EXPECT_EQ(d.q_world_segment_wxyz_size(), 16);  // 0 = orientations + positions
    EXPECT_EQ(d.position_m_size(), 12);
    EXPECT_EQ(d.q_earth_sensor_wxyz_size(), 0);
}

TEST(PoseEncoder, RawOnlyNeedsNoSkeletonPose) {
    Sample s = make_sample(3);
    s.pose = skeleton::SkeletonPose{};  // no calibrated pose yet
    PoseEncoder encoder;
    const v1::SkeletonFrame f = parse(encoder.encode_frame(s.frame, s.pose, kFieldRaw, 5)).frame();
    EXPECT_EQ(f.q_earth_sensor_wxyz_size(), 12);
    EXPECT_EQ(f.flags(0), kSegmentStale);
}

TEST(PoseEncoder, BuffersAreIndependentAndImmutable) {
    Sample s = make_sample(2);
    PoseEncoder encoder;
    const SharedBytes a = encoder.encode_frame(s.frame, s.pose, kFieldAll, 1);
    const std::string copy = *a;
    s.frame.sync += 1;
    const SharedBytes b = encoder.encode_frame(s.frame, s.pose, kFieldAll, 1);
    EXPECT_EQ(*a, copy);  // encoding the next frame did not touch the shared one
    EXPECT_NE(*a, *b);
}

}  // namespace
}  // namespace mocap::serve
