#include "ingest/frame_reassembler.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "mocap_wire/mw_scale.h"

namespace mocap::ingest {
namespace {

mw_can_frame sync_frame(std::uint32_t counter) {
    mw_sync s{counter};
    mw_can_frame f{};
    EXPECT_EQ(mw_sync_encode(&s, &f), MW_OK);
    return f;
}

mw_can_frame raw_frame(mw_function kind, std::uint8_t node, std::int16_t x, std::int16_t y, std::int16_t z,
                       std::uint32_t counter) {
    mw_raw r{};
    r.kind = kind;
    r.node_id = node;
    r.xyz[0] = x;
    r.xyz[1] = y;
    r.xyz[2] = z;
    r.counter_low = static_cast<std::uint16_t>(counter & 0xFFFF);
    mw_can_frame f{};
    EXPECT_EQ(mw_raw_encode(&r, &f), MW_OK);
    return f;
}

class Reassembler : public ::testing::Test {
protected:
    Reassembler() : r_(7, {}, counters_, [this](const SegmentSample& s) { out_.push_back(s); }) {}

    void feed(const mw_can_frame& f, std::int64_t t_us = 1000) { r_.on_frame(f, t_us, 900, 5000); }
    void node_sample(std::uint8_t node, std::uint32_t counter) {
        feed(raw_frame(MW_FN_ACCEL, node, 0, 0, 2048, counter));
        feed(raw_frame(MW_FN_GYRO, node, 100, 0, -100, counter));
        feed(raw_frame(MW_FN_MAG, node, 200, 0, -300, counter));
    }

    ReassemblyCounters counters_;
    std::vector<SegmentSample> out_;
    FrameReassembler r_;
};

TEST_F(Reassembler, ThreePartsMakeOneScaledSample) {
    feed(sync_frame(41), 123456);
    node_sample(3, 41);
    ASSERT_EQ(out_.size(), 1u);
    const SegmentSample& s = out_[0];
    EXPECT_EQ(s.subject_id, 7u);
    EXPECT_EQ(s.node_id, 3);
    EXPECT_EQ(s.sync, (1ull << 32) + 41u);
    EXPECT_EQ(s.imu.t_us, 123456);  // the SYNC's sink time, not the frames'
    EXPECT_EQ(s.times.sink_send_us, 900);
    EXPECT_EQ(s.times.received_us, 5000);
    // ±16 g default: 2048 counts = 1 g.
    EXPECT_NEAR(s.imu.accel_m_s2[2], 9.80665, 1e-4);
    EXPECT_NEAR(s.imu.gyro_rad_s[0], 100 * 2000.0 * M_PI / 180.0 / 32768.0, 1e-6);
    EXPECT_NEAR(s.imu.mag_ut[2], -300 * 0.15, 1e-4);
    EXPECT_TRUE(s.imu.has_mag());
    EXPECT_FALSE(s.has_node_quat);
    EXPECT_EQ(counters_.samples.value(), 1u);
}

TEST_F(Reassembler, StatusRangesChangeScaling) {
    mw_status st{};
    st.node_id = 3;
    st.state = MW_NODE_RUNNING;
    st.mode = MW_MODE_RAW;
    st.accel_range = MW_ACCEL_2G;
    st.gyro_range = MW_GYRO_250DPS;
    st.protocol_version = MW_CAN_PROTOCOL_VERSION;
    mw_can_frame f{};
    ASSERT_EQ(mw_status_encode(&st, &f), MW_OK);
    feed(f);
    feed(sync_frame(1));
    node_sample(3, 1);
    ASSERT_EQ(out_.size(), 1u);
    EXPECT_NEAR(out_[0].imu.accel_m_s2[2], 2048 * 2 * 9.80665 / 32768.0, 1e-4);
    ASSERT_NE(r_.node_status(3), nullptr);
    EXPECT_EQ(r_.node_status(3)->accel_range, MW_ACCEL_2G);
}

TEST_F(Reassembler, InterleavedNodesAndOutOfOrderParts) {
    feed(sync_frame(10));
    feed(raw_frame(MW_FN_MAG, 2, 1, 1, 1, 10));
    feed(raw_frame(MW_FN_ACCEL, 1, 1, 1, 1, 10));
    feed(raw_frame(MW_FN_GYRO, 2, 1, 1, 1, 10));
    feed(raw_frame(MW_FN_GYRO, 1, 1, 1, 1, 10));
    feed(raw_frame(MW_FN_ACCEL, 2, 1, 1, 1, 10));
    ASSERT_EQ(out_.size(), 1u);
    EXPECT_EQ(out_[0].node_id, 2);
    feed(raw_frame(MW_FN_MAG, 1, 1, 1, 1, 10));
    ASSERT_EQ(out_.size(), 2u);
    EXPECT_EQ(out_[1].node_id, 1);
}

TEST_F(Reassembler, DuplicateLateAndIncompleteAreCountedNotEmitted) {
    feed(sync_frame(100));
    feed(raw_frame(MW_FN_ACCEL, 1, 0, 0, 0, 100));
    feed(raw_frame(MW_FN_ACCEL, 1, 0, 0, 0, 100));  // duplicate part
    EXPECT_EQ(counters_.duplicate_frames.value(), 1u);
    feed(sync_frame(101));
    node_sample(1, 101);  // completes 101: 100 can never be emitted now
    ASSERT_EQ(out_.size(), 1u);
    EXPECT_EQ(out_[0].sync & 0xFFFFFFFFu, 101u);
    EXPECT_EQ(counters_.incomplete_samples.value(), 1u);
    feed(raw_frame(MW_FN_GYRO, 1, 0, 0, 0, 100));  // part of an instant older than emitted
    EXPECT_EQ(counters_.late_frames.value(), 1u);
    feed(raw_frame(MW_FN_GYRO, 1, 0, 0, 0, 101));  // repeat of an emitted instant
    EXPECT_EQ(counters_.duplicate_frames.value(), 2u);
    EXPECT_EQ(out_.size(), 1u);
}

TEST_F(Reassembler, MalformedFramesCounted) {
    mw_can_frame bad = raw_frame(MW_FN_ACCEL, 1, 0, 0, 0, 1);
    bad.dlc = 5;
    feed(bad);
    mw_can_frame reserved{};
    reserved.id = MW_CAN_ID(20, 1);
    reserved.dlc = 8;
    feed(reserved);
    EXPECT_EQ(counters_.malformed_frames.value(), 2u);
    EXPECT_TRUE(out_.empty());
}

TEST_F(Reassembler, InvalidMagnetometerFlagsSample) {
    feed(sync_frame(5));
    feed(raw_frame(MW_FN_ACCEL, 4, 0, 0, 2048, 5));
    feed(raw_frame(MW_FN_GYRO, 4, 0, 0, 0, 5));
    feed(raw_frame(MW_FN_MAG, 4, MW_MAG_INVALID, MW_MAG_INVALID, MW_MAG_INVALID, 5));
    ASSERT_EQ(out_.size(), 1u);
    EXPECT_FALSE(out_[0].imu.has_mag());
    EXPECT_EQ(counters_.samples_no_mag.value(), 1u);
}

TEST_F(Reassembler, SyncCounterWrapsKeepSyncMonotonic) {
    // Across the 16-bit wrap of the low counter bits and the 32-bit wrap of SYNC.
    std::uint32_t c = 0xFFFFFFF0u;
    std::uint64_t prev = 0;
    for (int i = 0; i < 40; ++i, ++c) {
        feed(sync_frame(c));
        node_sample(1, c);
        ASSERT_EQ(out_.size(), static_cast<std::size_t>(i + 1));
        if (i > 0) {
            EXPECT_EQ(out_.back().sync, prev + 1) << "at counter " << c;
        }
        prev = out_.back().sync;
    }
    EXPECT_EQ(counters_.sync_wraps.value(), 1u);
    EXPECT_EQ(counters_.late_frames.value(), 0u);
}

TEST_F(Reassembler, FramesOfAFewInstantsInFlightStillAssemble) {
    // A bus that delivers two instants interleaved (out-of-order arbitration/queues).
    feed(sync_frame(20));
    feed(sync_frame(21));
    feed(raw_frame(MW_FN_ACCEL, 1, 0, 0, 0, 20));
    feed(raw_frame(MW_FN_ACCEL, 1, 0, 0, 0, 21));
    feed(raw_frame(MW_FN_GYRO, 1, 0, 0, 0, 20));
    feed(raw_frame(MW_FN_GYRO, 1, 0, 0, 0, 21));
    feed(raw_frame(MW_FN_MAG, 1, 0, 0, 0, 20));
    feed(raw_frame(MW_FN_MAG, 1, 0, 0, 0, 21));
    ASSERT_EQ(out_.size(), 2u);
    EXPECT_EQ(out_[1].sync, out_[0].sync + 1);
}

TEST_F(Reassembler, ReconnectContinuesSyncLine) {
    feed(sync_frame(500));
    node_sample(1, 500);
    r_.reset_stream();
    feed(sync_frame(0));  // the sink restarted its counter
    node_sample(1, 0);
    feed(sync_frame(1));
    node_sample(1, 1);
    ASSERT_EQ(out_.size(), 3u);
    EXPECT_GT(out_[1].sync, out_[0].sync);
    EXPECT_EQ(out_[2].sync, out_[1].sync + 1);
}

TEST_F(Reassembler, CounterGoingBackwardsWithoutReconnectStartsNewStream) {
    feed(sync_frame(1000));
    node_sample(1, 1000);
    feed(sync_frame(3));  // sink rebooted behind our back
    node_sample(1, 3);
    ASSERT_EQ(out_.size(), 2u);
    EXPECT_GT(out_[1].sync, out_[0].sync);
}

TEST_F(Reassembler, AttitudeFrameGivesNodeQuaternion) {
    feed(sync_frame(77), 4242);
    mw_attitude a{};
    a.node_id = 9;
    const float h = std::sqrt(0.5f);
    a.q[0] = h;
    a.q[1] = 0;
    a.q[2] = 0;
    a.q[3] = h;
    a.counter_low = 77;
    mw_can_frame f{};
    ASSERT_EQ(mw_attitude_encode(&a, &f), MW_OK);
    feed(f);
    ASSERT_EQ(out_.size(), 1u);
    EXPECT_TRUE(out_[0].has_node_quat);
    EXPECT_EQ(out_[0].sync & 0xFFFFFFFFu, 77u);
    EXPECT_EQ(out_[0].imu.t_us, 4242);
    EXPECT_NEAR(out_[0].node_q_wxyz[0], h, 1e-4);
    EXPECT_NEAR(out_[0].node_q_wxyz[3], h, 1e-4);
    feed(f);
    EXPECT_EQ(counters_.duplicate_frames.value(), 1u);
}

}  // namespace
}  // namespace mocap::ingest
