// wire_expect.hpp — field-by-field GoogleTest comparisons of decoded wire messages, shared by
// the round-trip and golden tests.
#pragma once

#include <gtest/gtest.h>

#include <cstring>

#include "mocap_wire/mw_can.h"

inline void expect_same_config(const mw_config& a, const mw_config& b) {
    EXPECT_EQ(a.node_id, b.node_id);
    EXPECT_EQ(a.rate_hz, b.rate_hz);
    EXPECT_EQ(a.accel_range, b.accel_range);
    EXPECT_EQ(a.gyro_range, b.gyro_range);
    EXPECT_EQ(a.mode, b.mode);
    EXPECT_EQ(a.status_period_s, b.status_period_s);
}

inline void expect_same_raw(const mw_raw& a, const mw_raw& b) {
    EXPECT_EQ(a.kind, b.kind);
    EXPECT_EQ(a.node_id, b.node_id);
    EXPECT_EQ(std::memcmp(a.xyz, b.xyz, sizeof a.xyz), 0);
    EXPECT_EQ(a.counter_low, b.counter_low);
}

inline void expect_same_status(const mw_status& a, const mw_status& b) {
    EXPECT_EQ(a.node_id, b.node_id);
    EXPECT_EQ(a.state, b.state);
    EXPECT_EQ(a.mode, b.mode);
    EXPECT_EQ(a.mag_present, b.mag_present);
    EXPECT_EQ(a.accel_range, b.accel_range);
    EXPECT_EQ(a.gyro_range, b.gyro_range);
    EXPECT_EQ(a.error_flags, b.error_flags);
    EXPECT_EQ(a.protocol_version, b.protocol_version);
    EXPECT_EQ(a.uptime_s, b.uptime_s);
    EXPECT_EQ(a.tx_overflows, b.tx_overflows);
    EXPECT_EQ(a.sync_missed, b.sync_missed);
}
