// Sensor-node core against a register model of the MPU9250 and a fake CAN bus.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <vector>

#include "mpu9250_model.hpp"
#include "sensor_node/sensor_node.h"

namespace mocap::test {
namespace {

struct fake_node_hal {
    mpu9250_model imu;
    uint64_t now_us = 1000;
    uint64_t tick_us = 5;          // every clock read advances time (busy waits terminate)
    std::deque<mw_can_frame> rx;   // frames the node will receive
    std::vector<mw_can_frame> tx;  // frames the controller accepted
    bool tx_busy = false;

    sensor_node_hal hal() {
        sensor_node_hal h{};
        h.user = this;
        h.spi_transfer = [](void* u, const uint8_t* t, uint8_t* r, size_t n) {
            return static_cast<fake_node_hal*>(u)->imu.transfer(t, r, n);
        };
        h.can_transmit = [](void* u, const mw_can_frame* f) {
            auto* self = static_cast<fake_node_hal*>(u);
            if (self->tx_busy) {
                return 1;
            }
            self->tx.push_back(*f);
            return 0;
        };
        h.can_receive = [](void* u, mw_can_frame* f) {
            auto* self = static_cast<fake_node_hal*>(u);
            if (self->rx.empty()) {
                return 0;
            }
            *f = self->rx.front();
            self->rx.pop_front();
            return 1;
        };
        h.time_us = [](void* u) {
            auto* self = static_cast<fake_node_hal*>(u);
            self->now_us += self->tick_us;
            return self->now_us;
        };
        return h;
    }

    void send_sync(uint32_t counter) {
        mw_sync s{counter};
        mw_can_frame f{};
        ASSERT_EQ(mw_sync_encode(&s, &f), MW_OK);
        rx.push_back(f);
    }

    void send_config(const mw_config& config) {
        mw_can_frame f{};
        ASSERT_EQ(mw_config_encode(&config, &f), MW_OK);
        rx.push_back(f);
    }

    std::vector<mw_can_frame> take_tx() {
        std::vector<mw_can_frame> out;
        out.swap(tx);
        return out;
    }
};

std::vector<mw_status> statuses(const std::vector<mw_can_frame>& frames) {
    std::vector<mw_status> out;
    for (const auto& f : frames) {
        if (mw_can_id_function(f.id) == MW_FN_STATUS) {
            mw_status s{};
            EXPECT_EQ(mw_status_decode(&f, &s), MW_OK);
            out.push_back(s);
        }
    }
    return out;
}

std::vector<mw_can_frame> samples(const std::vector<mw_can_frame>& frames) {
    std::vector<mw_can_frame> out;
    for (const auto& f : frames) {
        if (mw_can_id_function(f.id) != MW_FN_STATUS) {
            out.push_back(f);
        }
    }
    return out;
}

class SensorNodeTest : public ::testing::Test {
protected:
    fake_node_hal fake;
    sensor_node node{};

    void start(uint8_t id = 5) {
        const sensor_node_hal h = fake.hal();
        ASSERT_EQ(sensor_node_init(&node, &h, id), MW_OK);
        sensor_node_poll(&node);
    }
};

TEST_F(SensorNodeTest, InitConfiguresSensorAndMagnetometer) {
    start();
    EXPECT_EQ(fake.imu.resets, 2);  // power-on state + H_RESET
    EXPECT_EQ(fake.imu.reg(0x1B), 0x18) << "GYRO_CONFIG: +-2000 dps";
    EXPECT_EQ(fake.imu.reg(0x1C), 0x18) << "ACCEL_CONFIG: +-16 g";
    EXPECT_EQ(fake.imu.reg(0x1A), 3) << "DLPF 41 Hz for 100 Hz sampling";
    EXPECT_EQ(fake.imu.reg(0x1D), 3);
    EXPECT_EQ(fake.imu.reg(0x6B), 0x01) << "PLL clock";
    EXPECT_TRUE(fake.imu.reg(0x6A) & 0x20) << "I2C master on";
    EXPECT_EQ(fake.imu.ak_reg(0x0A), 0x16) << "AK8963 16-bit continuous 100 Hz";
    EXPECT_EQ(fake.imu.reg(0x25), 0x8C) << "slave 0 reads the AK8963";
    EXPECT_EQ(fake.imu.reg(0x26), 0x02) << "from ST1";
    EXPECT_EQ(fake.imu.reg(0x27), 0x88) << "8 bytes: ST1..ST2";
    EXPECT_EQ(node.imu.mag_present, 1);

    const auto st = statuses(fake.take_tx());
    ASSERT_EQ(st.size(), 1u);
    EXPECT_EQ(st[0].node_id, 5);
    EXPECT_EQ(st[0].state, MW_NODE_WAITING);
    EXPECT_TRUE(st[0].mag_present);
    EXPECT_EQ(st[0].error_flags, MW_ERRF_RESET);
    EXPECT_EQ(st[0].accel_range, MW_ACCEL_16G);
    EXPECT_EQ(st[0].gyro_range, MW_GYRO_2000DPS);
}

TEST_F(SensorNodeTest, SyncProducesGoldenRawFrames) {
    fake.imu.accel = {1000, -2000, 16384};
    fake.imu.gyro = {-1, 32767, 0x0102};
    fake.imu.mag_raw = {100, -200, 300};
    fake.imu.mag_asa = {128, 192, 64};  // adjustment x1.0, x1.25, x0.75
    start(5);
    fake.take_tx();

    fake.send_sync(0x12345678u);
    sensor_node_poll(&node);
    const auto out = samples(fake.take_tx());
    ASSERT_EQ(out.size(), 3u);

    const std::array<uint16_t, 3> ids{0x085, 0x0C5, 0x105};
    const std::array<std::array<uint8_t, 8>, 3> bytes{{
        {0xE8, 0x03, 0x30, 0xF8, 0x00, 0x40, 0x78, 0x56},  // accel 1000, -2000, 16384, counter 0x5678
        {0xFF, 0xFF, 0xFF, 0x7F, 0x02, 0x01, 0x78, 0x56},  // gyro -1, 32767, 258
        // mag in MPU axes: x = adj(hy) = -250, y = adj(hx) = 100, z = -adj(hz) = -225
        {0x06, 0xFF, 0x64, 0x00, 0x1F, 0xFF, 0x78, 0x56},
    }};
    for (std::size_t i = 0; i < 3; ++i) {
        EXPECT_EQ(out[i].id, ids[i]) << i;
        ASSERT_EQ(out[i].dlc, 8) << i;
        for (std::size_t b = 0; b < 8; ++b) {
            EXPECT_EQ(out[i].data[b], bytes[i][b]) << "frame " << i << " byte " << b;
        }
    }
    EXPECT_EQ(node.counters.samples, 1u);
    EXPECT_EQ(node.state, MW_NODE_RUNNING);
}

TEST_F(SensorNodeTest, SyncsThatWaitedThroughTheSensorStartAreNotSampled) {
    // A node reset mid-stream: while it brings its sensor up (144 ms), SYNCs pile up in the
    // controller's receive FIFO. Sampling them after the start would tag a sample read now
    // with the counters of instants long past.
    fake.send_sync(7);
    fake.send_sync(8);
    mw_config config{};
    config.node_id = MW_NODE_ID_BROADCAST;
    config.rate_hz = 100;
    config.accel_range = MW_ACCEL_8G;
    config.gyro_range = MW_GYRO_1000DPS;
    config.mode = MW_MODE_RAW;
    config.status_period_s = 1;
    fake.send_config(config);
    start(2);
    const auto sent = fake.take_tx();
    EXPECT_TRUE(samples(sent).empty()) << "no sample for a SYNC that waited";
    EXPECT_EQ(node.counters.syncs_stale, 2u);
    EXPECT_EQ(node.config.accel_range, MW_ACCEL_8G) << "a CONFIG that waited still applies";
    const auto st = statuses(sent);
    ASSERT_FALSE(st.empty());
    EXPECT_TRUE(st[0].error_flags & MW_ERRF_RESET);

    fake.send_sync(9);
    sensor_node_poll(&node);
    const auto out = samples(fake.take_tx());
    ASSERT_EQ(out.size(), 3u);
    for (const auto& f : out) {
        EXPECT_EQ(f.data[6] | (f.data[7] << 8), 9) << "the sample of the SYNC it was read for";
    }
}

TEST_F(SensorNodeTest, ConfigChangesRangeRegistersAndIsAcknowledged) {
    start(7);
    fake.take_tx();
    fake.send_config({9, 100, MW_ACCEL_2G, MW_GYRO_250DPS, MW_MODE_RAW, 1});
    sensor_node_poll(&node);
    EXPECT_EQ(fake.imu.reg(0x1C), 0x18) << "a CONFIG for node 9 leaves node 7 alone";

    fake.send_config({0, 200, MW_ACCEL_4G, MW_GYRO_500DPS, MW_MODE_RAW, 2});
    sensor_node_poll(&node);
    EXPECT_EQ(fake.imu.reg(0x1C), 0x08) << "ACCEL_CONFIG: +-4 g";
    EXPECT_EQ(fake.imu.reg(0x1B), 0x08) << "GYRO_CONFIG: +-500 dps";
    EXPECT_EQ(fake.imu.reg(0x1A), 2) << "DLPF 92 Hz for 200 Hz sampling";
    EXPECT_EQ(node.config.status_period_s, 2);
    EXPECT_EQ(node.counters.configs_applied, 1u);

    const auto st = statuses(fake.take_tx());
    ASSERT_EQ(st.size(), 1u) << "the new ranges are acknowledged at once";
    EXPECT_EQ(st[0].accel_range, MW_ACCEL_4G);
    EXPECT_EQ(st[0].gyro_range, MW_GYRO_500DPS);
}

// Sensor-frame readings for an orientation q_enu_sensor (w, x, y, z): specific force of a
// node at rest (+1 g up) and an earth field of 20 uT north, 40 uT down, as model counts.
void set_static_pose(mpu9250_model& imu, const std::array<double, 4>& q) {
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    const double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                            {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                            {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
    const double up[3] = {0, 0, 1};
    const double field_ut[3] = {0, 20, -40};
    for (int i = 0; i < 3; ++i) {  // sensor = R^T earth
        double a = 0, m = 0;
        for (int k = 0; k < 3; ++k) {
            a += r[k][i] * up[k];
            m += r[k][i] * field_ut[k];
        }
        imu.accel[i] = static_cast<int16_t>(std::lround(a * 2048.0));  // +-16 g
        const auto counts = static_cast<int16_t>(std::lround(m / 0.15));
        // AK8963 axes: x_ak = y, y_ak = x, z_ak = -z (ASA neutral).
        if (i == 0) imu.mag_raw[1] = counts;
        if (i == 1) imu.mag_raw[0] = counts;
        if (i == 2) imu.mag_raw[2] = static_cast<int16_t>(-counts);
    }
    imu.gyro = {0, 0, 0};
}

double angle_deg(const float a[4], const std::array<double, 4>& b) {
    const double dot = std::fabs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]);
    return 2.0 * std::acos(std::min(1.0, dot)) * 180.0 / M_PI;
}

TEST_F(SensorNodeTest, AttitudeModeSendsTheNodesOrientation) {
    const double h = std::sqrt(0.5);
    // Level, x axis pointing north: a +90 deg turn about up from the ENU axes.
    const std::array<double, 4> north{h, 0, 0, h};
    // Rolled 30 deg about x, then turned 40 deg about up.
    const double r2 = 15.0 * M_PI / 180.0, y2 = 20.0 * M_PI / 180.0;
    const std::array<double, 4> tilted{std::cos(y2) * std::cos(r2), std::cos(y2) * std::sin(r2),
                                       std::sin(y2) * std::sin(r2), std::sin(y2) * std::cos(r2)};
    for (const auto& pose : {north, tilted}) {
        fake.imu = mpu9250_model{};
        set_static_pose(fake.imu, pose);
        start(3);
        fake.take_tx();
        fake.send_config({0, 100, MW_ACCEL_16G, MW_GYRO_2000DPS, MW_MODE_ATTITUDE, 1});
        sensor_node_poll(&node);
        fake.take_tx();
        for (uint32_t c = 0; c < 100; ++c) {
            fake.send_sync(c);
            sensor_node_poll(&node);
            const auto out = samples(fake.take_tx());
            ASSERT_EQ(out.size(), 1u) << "attitude mode: ATT only";
            mw_attitude att{};
            ASSERT_EQ(mw_attitude_decode(&out[0], &att), MW_OK);
            EXPECT_EQ(att.node_id, 3);
            EXPECT_EQ(att.counter_low, c);
            EXPECT_LT(angle_deg(att.q, pose), 1.0) << "sample " << c << " (initialised from the first)";
        }
    }
}

TEST_F(SensorNodeTest, AttitudeIntegratesGyroWithoutMagnetometer) {
    fake.imu.mag_present = false;
    set_static_pose(fake.imu, {1, 0, 0, 0});
    start(3);
    fake.send_config({0, 100, MW_ACCEL_16G, MW_GYRO_2000DPS, MW_MODE_RAW_ATTITUDE, 1});
    sensor_node_poll(&node);
    fake.take_tx();
    fake.imu.gyro = {0, 0, 1475};  // 1475 / 16.384 = 90.03 deg/s about up
    float last_q[4] = {0, 0, 0, 0};
    for (uint32_t c = 0; c <= 100; ++c) {
        fake.send_sync(c);
        sensor_node_poll(&node);
        const auto out = samples(fake.take_tx());
        ASSERT_EQ(out.size(), 4u) << "raw + attitude";
        mw_attitude att{};
        ASSERT_EQ(mw_attitude_decode(&out[3], &att), MW_OK);
        std::copy(att.q, att.q + 4, last_q);
    }
    // 100 periods of 10 ms at 90.03 deg/s after the first (initialising) sample.
    const double yaw = 90.03 * M_PI / 180.0;
    EXPECT_LT(angle_deg(last_q, {std::cos(yaw / 2), 0, 0, std::sin(yaw / 2)}), 0.5);
}

TEST_F(SensorNodeTest, MissingSensorFaultsThenRecovers) {
    fake.imu.present = false;
    start(2);
    EXPECT_EQ(node.state, MW_NODE_FAULT);
    auto st = statuses(fake.take_tx());
    ASSERT_EQ(st.size(), 1u);
    EXPECT_TRUE(st[0].error_flags & MW_ERRF_IMU);
    EXPECT_EQ(st[0].state, MW_NODE_FAULT);

    fake.send_sync(1);
    sensor_node_poll(&node);
    EXPECT_TRUE(samples(fake.take_tx()).empty()) << "no samples without a sensor";

    fake.imu.present = true;
    fake.now_us += SENSOR_NODE_IMU_RETRY_US;
    sensor_node_poll(&node);
    EXPECT_EQ(node.state, MW_NODE_WAITING);
    st = statuses(fake.take_tx());
    ASSERT_EQ(st.size(), 1u);
    EXPECT_EQ(st[0].error_flags & MW_ERRF_IMU, 0);
    fake.send_sync(2);
    sensor_node_poll(&node);
    EXPECT_EQ(samples(fake.take_tx()).size(), 3u);
}

TEST_F(SensorNodeTest, SensorLostMidStreamSendsNoSamplesAndIsInitialisedAgain) {
    start(2);
    fake.send_sync(1);
    sensor_node_poll(&node);
    ASSERT_EQ(samples(fake.take_tx()).size(), 3u);

    fake.imu.present = false;  // MISO floats high: every byte reads 0xFF
    fake.send_sync(2);
    sensor_node_poll(&node);
    auto sent = fake.take_tx();
    EXPECT_TRUE(samples(sent).empty()) << "0xFF bytes are no sample";
    EXPECT_EQ(node.state, MW_NODE_FAULT);
    auto st = statuses(sent);
    ASSERT_EQ(st.size(), 1u);
    EXPECT_EQ(st[0].state, MW_NODE_FAULT);
    EXPECT_TRUE(st[0].error_flags & MW_ERRF_IMU);

    fake.imu.present = true;  // back, possibly after a power cycle: initialised again first
    fake.now_us += SENSOR_NODE_IMU_RETRY_US;
    sensor_node_poll(&node);
    EXPECT_EQ(node.state, MW_NODE_WAITING);
    fake.send_sync(3);
    sensor_node_poll(&node);
    EXPECT_EQ(samples(fake.take_tx()).size(), 3u);
}

TEST_F(SensorNodeTest, MissingMagnetometerKeepsAccelAndGyro) {
    fake.imu.mag_present = false;
    fake.imu.accel = {1, 2, 3};
    start(4);
    EXPECT_EQ(node.state, MW_NODE_WAITING);
    auto st = statuses(fake.take_tx());
    ASSERT_EQ(st.size(), 1u);
    EXPECT_FALSE(st[0].mag_present);
    EXPECT_TRUE(st[0].error_flags & MW_ERRF_MAG);

    fake.send_sync(10);
    sensor_node_poll(&node);
    const auto out = samples(fake.take_tx());
    ASSERT_EQ(out.size(), 3u);
    mw_raw mag{};
    ASSERT_EQ(mw_raw_decode(&out[2], &mag), MW_OK);
    EXPECT_EQ(mag.kind, MW_FN_MAG);
    EXPECT_EQ(mag.xyz[0], MW_MAG_INVALID);
    EXPECT_EQ(mag.xyz[1], MW_MAG_INVALID);
    EXPECT_EQ(mag.xyz[2], MW_MAG_INVALID);
    mw_raw acc{};
    ASSERT_EQ(mw_raw_decode(&out[0], &acc), MW_OK);
    EXPECT_EQ(acc.xyz[2], 3);
}

TEST_F(SensorNodeTest, MagnetometerOverflowSendsInvalidMarker) {
    fake.imu.mag_raw = {5000, 5000, 5000};
    fake.imu.mag_overflow = true;
    start(4);
    fake.take_tx();
    fake.send_sync(1);
    sensor_node_poll(&node);
    const auto all = fake.take_tx();
    const auto out = samples(all);
    ASSERT_EQ(out.size(), 3u);
    mw_raw mag{};
    ASSERT_EQ(mw_raw_decode(&out[2], &mag), MW_OK);
    EXPECT_EQ(mag.xyz[0], MW_MAG_INVALID);
    // The overflow event changes the flags, so a STATUS reports it right away.
    const auto st = statuses(all);
    ASSERT_FALSE(st.empty());
    EXPECT_TRUE(st.back().error_flags & MW_ERRF_MAG);
}

TEST_F(SensorNodeTest, BusyBusOverflowsQueueCountedAndReported) {
    start(6);
    fake.take_tx();
    fake.tx_busy = true;
    for (uint32_t c = 0; c < 8; ++c) {  // 8 samples x 3 frames > 16 queue slots
        fake.send_sync(c);
        sensor_node_poll(&node);
    }
    EXPECT_EQ(node.counters.samples, 8u);
    EXPECT_GT(node.counters.tx_overflows, 0u);
    const uint32_t overflows = node.counters.tx_overflows;
    fake.tx_busy = false;
    sensor_node_poll(&node);
    sensor_node_poll(&node);
    const auto all = fake.take_tx();
    // 24 sample frames + the STATUS announcing RUNNING competed for 16 slots.
    EXPECT_EQ(overflows, 9u);
    EXPECT_EQ(samples(all).size(), SENSOR_NODE_TX_QUEUE_LEN - 1u);
    // Queue order is preserved: the first frames on the bus are sample 0's.
    mw_raw first{};
    ASSERT_EQ(mw_raw_decode(&all.front(), &first), MW_OK);
    EXPECT_EQ(first.counter_low, 0u);
    const auto st = statuses(all);
    ASSERT_FALSE(st.empty());
    EXPECT_TRUE(st.back().error_flags & MW_ERRF_CAN_TX_OVERFLOW);
    EXPECT_EQ(st.back().tx_overflows, static_cast<uint8_t>(overflows));
}

TEST_F(SensorNodeTest, SyncGapsAndTimeoutAreReported) {
    start(8);
    fake.take_tx();
    fake.send_sync(100);
    fake.send_sync(101);
    fake.send_sync(105);  // 102..104 missed
    sensor_node_poll(&node);
    EXPECT_EQ(node.counters.sync_missed, 3u);
    EXPECT_EQ(node.state, MW_NODE_RUNNING);
    fake.take_tx();

    fake.now_us += 31000;  // > 3 periods at 100 Hz
    sensor_node_poll(&node);
    EXPECT_EQ(node.state, MW_NODE_WAITING);
    const auto st = statuses(fake.take_tx());
    ASSERT_EQ(st.size(), 1u);
    EXPECT_TRUE(st[0].error_flags & MW_ERRF_SYNC_TIMEOUT);
    EXPECT_EQ(st[0].sync_missed, 3u);
}

TEST_F(SensorNodeTest, PeriodicStatusFollowsConfiguredPeriod) {
    start(9);
    fake.take_tx();
    int count = 0;
    for (int ms = 0; ms < 3500; ++ms) {
        fake.now_us += 1000;
        sensor_node_poll(&node);
        count += static_cast<int>(statuses(fake.take_tx()).size());
    }
    EXPECT_EQ(count, 3) << "one STATUS per second";
}

TEST_F(SensorNodeTest, MalformedConfigIsCountedNotApplied) {
    start(5);
    fake.take_tx();
    mw_can_frame f{};
    f.id = MW_CAN_ID(MW_FN_CONFIG, 5);
    f.dlc = 2;  // CONFIG needs 5 bytes
    fake.rx.push_back(f);
    sensor_node_poll(&node);
    EXPECT_EQ(node.counters.malformed_frames, 1u);
    EXPECT_EQ(node.counters.configs_rejected, 1u);
    EXPECT_EQ(fake.imu.reg(0x1C), 0x18);
}

TEST_F(SensorNodeTest, CanBusErrorIsReported) {
    static int bus_error = 0;
    bus_error = 0;
    sensor_node_hal h = fake.hal();
    h.can_bus_error = [](void*) { return bus_error; };
    ASSERT_EQ(sensor_node_init(&node, &h, 5), MW_OK);
    sensor_node_poll(&node);
    fake.take_tx();
    bus_error = 1;
    sensor_node_poll(&node);
    const auto st = statuses(fake.take_tx());
    ASSERT_EQ(st.size(), 1u);
    EXPECT_TRUE(st[0].error_flags & MW_ERRF_CAN_BUS);
}

TEST(SensorNodeInit, RejectsBadArguments) {
    fake_node_hal fake;
    sensor_node node{};
    sensor_node_hal h = fake.hal();
    EXPECT_EQ(sensor_node_init(&node, &h, 0), MW_ERR_ARGUMENT);
    EXPECT_EQ(sensor_node_init(&node, &h, 64), MW_ERR_ARGUMENT);
    h.can_receive = nullptr;
    EXPECT_EQ(sensor_node_init(&node, &h, 1), MW_ERR_ARGUMENT);
}

TEST(Mpu9250Dlpf, StaysUnderNyquist) {
    EXPECT_EQ(mpu9250_dlpf_for_rate(1000), 0);
    EXPECT_EQ(mpu9250_dlpf_for_rate(200), 2);
    EXPECT_EQ(mpu9250_dlpf_for_rate(100), 3);
    EXPECT_EQ(mpu9250_dlpf_for_rate(50), 4);
    EXPECT_EQ(mpu9250_dlpf_for_rate(5), 6);
}

}  // namespace
}  // namespace mocap::test
