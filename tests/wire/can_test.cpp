// can_test.cpp — CAN message set: round trips, every malformed frame, the ID table, counters.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <string>

#include "mocap_wire/mw_can.h"
#include "wire_expect.hpp"

namespace {

mw_can_frame frame_of(uint16_t id, uint8_t dlc) {
    mw_can_frame f{};
    f.id = id;
    f.dlc = dlc;
    return f;
}

mw_raw raw_of(mw_function kind, uint8_t node, int16_t x, int16_t y, int16_t z, uint16_t counter) {
    mw_raw r{};
    r.kind = kind;
    r.node_id = node;
    r.xyz[0] = x;
    r.xyz[1] = y;
    r.xyz[2] = z;
    r.counter_low = counter;
    return r;
}

mw_config config_of(uint8_t node, uint16_t rate_hz, mw_mode mode) {
    mw_config c{};
    c.node_id = node;
    c.rate_hz = rate_hz;
    c.accel_range = MW_ACCEL_16G;
    c.gyro_range = MW_GYRO_2000DPS;
    c.mode = mode;
    c.status_period_s = 1;
    return c;
}

mw_status status_of(uint8_t node) {
    mw_status s{};
    s.node_id = node;
    s.state = MW_NODE_RUNNING;
    s.mode = MW_MODE_RAW;
    s.mag_present = true;
    s.accel_range = MW_ACCEL_4G;
    s.gyro_range = MW_GYRO_500DPS;
    s.error_flags = MW_ERRF_SATURATED;
    s.protocol_version = MW_CAN_PROTOCOL_VERSION;
    s.uptime_s = 1234;
    s.tx_overflows = 2;
    s.sync_missed = 3;
    return s;
}

// Rotation angle between two unit quaternions (q and -q are the same rotation), degrees:
// 2 atan2(|vec(conj(a) b)|, |scalar(conj(a) b)|), well conditioned for tiny angles (acos is not).
double angle_deg(const float a[4], const float b[4]) {
    const double aw = a[0], ax = a[1], ay = a[2], az = a[3];
    const double bw = b[0], bx = b[1], by = b[2], bz = b[3];
    const double w = aw * bw + ax * bx + ay * by + az * bz;
    const double x = aw * bx - bw * ax - (ay * bz - az * by);
    const double y = aw * by - bw * ay - (az * bx - ax * bz);
    const double z = aw * bz - bw * az - (ax * by - ay * bx);
    return 2.0 * std::atan2(std::sqrt(x * x + y * y + z * z), std::fabs(w)) * 180.0 / M_PI;
}

TEST(WireCan, IdLayoutPutsSyncFirstAndNodesInTheLowBits) {
    EXPECT_EQ(MW_CAN_ID_SYNC, 0x000u);
    EXPECT_EQ(MW_CAN_ID(MW_FN_CONFIG, 0), 0x040u);
    EXPECT_EQ(MW_CAN_ID(MW_FN_ACCEL, 1), 0x081u);
    EXPECT_EQ(MW_CAN_ID(MW_FN_GYRO, 63), 0x0FFu);
    EXPECT_EQ(MW_CAN_ID(MW_FN_MAG, 17), 0x111u);
    EXPECT_EQ(MW_CAN_ID(MW_FN_ATTITUDE, 2), 0x142u);
    EXPECT_EQ(MW_CAN_ID(MW_FN_STATUS, 0), 0x180u);
    EXPECT_EQ(mw_can_id_function(0x13F), MW_FN_MAG);
    EXPECT_EQ(mw_can_id_node(0x13F), 63u);
    // Every sample ID of every node loses arbitration to SYNC and CONFIG.
    for (unsigned node = MW_NODE_ID_MIN; node <= MW_NODE_ID_MAX; ++node) {
        EXPECT_GT(MW_CAN_ID(MW_FN_ACCEL, node), MW_CAN_ID(MW_FN_CONFIG, MW_NODE_ID_MAX));
    }
}

TEST(WireCan, SyncRoundTripsIncludingWrap) {
    for (uint32_t c : {0u, 1u, 0x7FFFFFFFu, 0x80000000u, 0xFFFFFFFEu, 0xFFFFFFFFu}) {
        mw_sync in{c};
        mw_can_frame f{};
        ASSERT_EQ(mw_sync_encode(&in, &f), MW_OK);
        mw_sync out{};
        ASSERT_EQ(mw_sync_decode(&f, &out), MW_OK);
        EXPECT_EQ(out.counter, c);
    }
}

TEST(WireCan, RawRoundTripsRandomValues) {
    std::mt19937 rng(12345);
    std::uniform_int_distribution<int> value(INT16_MIN, INT16_MAX);
    std::uniform_int_distribution<int> mag(-MW_MAG_COUNTS_MAX, MW_MAG_COUNTS_MAX);
    std::uniform_int_distribution<int> node(MW_NODE_ID_MIN, MW_NODE_ID_MAX);
    std::uniform_int_distribution<int> counter(0, 0xFFFF);
    for (int i = 0; i < 3000; ++i) {
        const mw_function kind = static_cast<mw_function>(MW_FN_ACCEL + i % 3);
        auto& dist = kind == MW_FN_MAG ? mag : value;
        const mw_raw in = raw_of(kind, static_cast<uint8_t>(node(rng)), static_cast<int16_t>(dist(rng)),
                                 static_cast<int16_t>(dist(rng)), static_cast<int16_t>(dist(rng)),
                                 static_cast<uint16_t>(counter(rng)));
        mw_can_frame f{};
        ASSERT_EQ(mw_raw_encode(&in, &f), MW_OK);
        mw_message m{};
        ASSERT_EQ(mw_can_decode(&f, &m), MW_OK);
        ASSERT_EQ(m.function, kind);
        expect_same_raw(m.u.raw, in);
    }
}

TEST(WireCan, ConfigAndStatusRoundTripEveryEnumValue) {
    for (unsigned mode = 0; mode < MW_MODE_COUNT; ++mode) {
        for (unsigned a = 0; a <= MW_ACCEL_16G; ++a) {
            for (unsigned g = 0; g <= MW_GYRO_2000DPS; ++g) {
                mw_config c = config_of(static_cast<uint8_t>(a * 4 + g), 1000, static_cast<mw_mode>(mode));
                c.accel_range = static_cast<mw_accel_range>(a);
                c.gyro_range = static_cast<mw_gyro_range>(g);
                mw_can_frame f{};
                ASSERT_EQ(mw_config_encode(&c, &f), MW_OK);
                mw_config back{};
                ASSERT_EQ(mw_config_decode(&f, &back), MW_OK);
                expect_same_config(back, c);
            }
        }
    }
    for (unsigned state = 0; state < MW_NODE_STATE_COUNT; ++state) {
        for (unsigned mode = 0; mode < MW_MODE_COUNT; ++mode) {
            mw_status s = status_of(static_cast<uint8_t>(state * 3 + mode));
            s.state = static_cast<mw_node_state>(state);
            s.mode = static_cast<mw_mode>(mode);
            s.mag_present = (state & 1u) != 0u;
            mw_can_frame f{};
            ASSERT_EQ(mw_status_encode(&s, &f), MW_OK);
            mw_status b{};
            ASSERT_EQ(mw_status_decode(&f, &b), MW_OK);
            expect_same_status(b, s);
        }
    }
}

TEST(WireCan, AttitudeRoundTripIsWithinHundredthOfADegreeEverywhere) {
    std::mt19937 rng(777);
    std::normal_distribution<float> n(0.0f, 1.0f);
    double worst = 0.0;
    for (int i = 0; i < 20000; ++i) {
        mw_attitude in{};
        in.node_id = 5;
        float norm = 0.0f;
        for (float& c : in.q) {
            c = n(rng);
            norm += c * c;
        }
        norm = std::sqrt(norm);
        for (float& c : in.q)
            c /= norm;
        in.counter_low = static_cast<uint16_t>(i);
        mw_can_frame f{};
        ASSERT_EQ(mw_attitude_encode(&in, &f), MW_OK);
        mw_attitude out{};
        ASSERT_EQ(mw_attitude_decode(&f, &out), MW_OK);
        EXPECT_EQ(out.counter_low, i & 0x3FFF);
        float out_norm = 0.0f;
        for (float c : out.q)
            out_norm += c * c;
        EXPECT_NEAR(out_norm, 1.0f, 1e-6f);
        worst = std::max(worst, angle_deg(in.q, out.q));
    }
    RecordProperty("worst_deg", std::to_string(worst));
    EXPECT_LT(worst, 0.01);
}

TEST(WireCan, AttitudeKeepsPrecisionAtHalfTurns) {
    // A subject facing south: q = (0, 0, 0, 1) plus small tilts. Dropping w would lose ~1 deg here.
    for (float tilt : {0.0f, 1e-4f, 1e-3f, 0.01f}) {
        mw_attitude in{};
        in.node_id = 1;
        in.q[0] = tilt;
        in.q[1] = tilt;
        in.q[3] = std::sqrt(1.0f - 2.0f * tilt * tilt);
        mw_can_frame f{};
        ASSERT_EQ(mw_attitude_encode(&in, &f), MW_OK);
        mw_attitude out{};
        ASSERT_EQ(mw_attitude_decode(&f, &out), MW_OK);
        EXPECT_LT(angle_deg(in.q, out.q), 0.005) << "tilt " << tilt;
    }
}

TEST(WireCan, AttitudeEncoderNormalisesAndRejectsDegenerateInput) {
    mw_attitude in{};
    in.node_id = 3;
    in.q[0] = 2.0f;  // not unit: normalised by the encoder
    mw_can_frame f{};
    ASSERT_EQ(mw_attitude_encode(&in, &f), MW_OK);
    mw_attitude out{};
    ASSERT_EQ(mw_attitude_decode(&f, &out), MW_OK);
    EXPECT_FLOAT_EQ(out.q[0], 1.0f);
    // Negative largest component: the same rotation comes back (sign may flip).
    const mw_attitude neg{3, {-0.9f, 0.1f, 0.3f, std::sqrt(1.0f - 0.81f - 0.01f - 0.09f)}, 0};
    ASSERT_EQ(mw_attitude_encode(&neg, &f), MW_OK);
    ASSERT_EQ(mw_attitude_decode(&f, &out), MW_OK);
    EXPECT_LT(angle_deg(neg.q, out.q), 0.01);
    EXPECT_GT(out.q[0], 0.0f);

    mw_attitude zero{};
    zero.node_id = 3;
    EXPECT_EQ(mw_attitude_encode(&zero, &f), MW_ERR_RANGE);
    mw_attitude nan = zero;
    nan.q[0] = std::nanf("");
    nan.q[1] = 1.0f;
    EXPECT_EQ(mw_attitude_encode(&nan, &f), MW_ERR_RANGE);
    mw_attitude inf = zero;
    inf.q[2] = INFINITY;
    EXPECT_EQ(mw_attitude_encode(&inf, &f), MW_ERR_RANGE);
}

TEST(WireCan, EveryIdDecodesToItsTableEntryOrIsRejected) {
    // Give each ID the DLC its function expects, so only the ID decides.
    for (unsigned id = 0; id <= MW_CAN_ID_MAX + 1; ++id) {
        const unsigned fn = (id >> 6) & 0x1Fu;
        const unsigned node = id & 0x3Fu;
        mw_can_frame f = frame_of(static_cast<uint16_t>(id), 8);
        bool known = true;
        switch (fn) {
            case MW_FN_SYNC:
                f.dlc = MW_DLC_SYNC;
                known = node == 0;
                break;
            case MW_FN_CONFIG:
                f.dlc = MW_DLC_CONFIG;
                f.data[0] = 100;  // rate 100 Hz
                break;
            case MW_FN_ACCEL:
            case MW_FN_GYRO:
            case MW_FN_MAG:
            case MW_FN_ATTITUDE:
                known = node != 0;
                break;
            case MW_FN_STATUS:
                break;
            default:
                known = false;
        }
        if (id > MW_CAN_ID_MAX) known = false;
        mw_message m{};
        const int rc = mw_can_decode(&f, &m);
        if (known) {
            EXPECT_EQ(rc, MW_OK) << "id " << id;
            EXPECT_EQ(static_cast<unsigned>(m.function), fn) << "id " << id;
        } else {
            EXPECT_EQ(rc, MW_ERR_ID) << "id " << id;
        }
    }
}

TEST(WireCan, EveryWrongDlcIsRejected) {
    struct Case {
        uint16_t id;
        uint8_t dlc;
    };
    const Case cases[] = {{0x000, MW_DLC_SYNC}, {0x041, MW_DLC_CONFIG},   {0x081, MW_DLC_RAW},   {0x0C1, MW_DLC_RAW},
                          {0x101, MW_DLC_RAW},  {0x141, MW_DLC_ATTITUDE}, {0x181, MW_DLC_STATUS}};
    for (const Case& c : cases) {
        for (unsigned dlc = 0; dlc < 16; ++dlc) {
            if (dlc == c.dlc) continue;
            mw_can_frame f = frame_of(c.id, static_cast<uint8_t>(dlc));
            f.data[0] = 100;
            mw_message m{};
            EXPECT_EQ(mw_can_decode(&f, &m), MW_ERR_DLC) << "id " << c.id << " dlc " << dlc;
        }
    }
    // The typed decoders agree with the dispatcher.
    mw_can_frame f = frame_of(0x000, 8);
    mw_sync s{};
    EXPECT_EQ(mw_sync_decode(&f, &s), MW_ERR_DLC);
    f = frame_of(0x081, 7);
    mw_raw r{};
    EXPECT_EQ(mw_raw_decode(&f, &r), MW_ERR_DLC);
}

TEST(WireCan, TypedDecodersRejectOtherMessagesIds) {
    mw_can_frame f = frame_of(0x081, 8);  // ACCEL
    mw_sync s{};
    mw_config c{};
    mw_attitude a{};
    mw_status st{};
    EXPECT_EQ(mw_sync_decode(&f, &s), MW_ERR_ID);
    EXPECT_EQ(mw_config_decode(&f, &c), MW_ERR_ID);
    EXPECT_EQ(mw_attitude_decode(&f, &a), MW_ERR_ID);
    EXPECT_EQ(mw_status_decode(&f, &st), MW_ERR_ID);
    f = frame_of(0x181, 8);
    mw_raw r{};
    EXPECT_EQ(mw_raw_decode(&f, &r), MW_ERR_ID);
    f = frame_of(0x080, 8);  // ACCEL from node 0 (the sink never samples)
    EXPECT_EQ(mw_raw_decode(&f, &r), MW_ERR_ID);
}

TEST(WireCan, OutOfRangeFieldsAreRejected) {
    mw_can_frame f{};
    mw_message m{};
    // CONFIG: rate 0, rate 1001, mode 3.
    const mw_config ok = config_of(1, 100, MW_MODE_RAW);
    ASSERT_EQ(mw_config_encode(&ok, &f), MW_OK);
    f.data[0] = 0;
    f.data[1] = 0;
    EXPECT_EQ(mw_can_decode(&f, &m), MW_ERR_RANGE);
    f.data[0] = 0xE9;  // 1001
    f.data[1] = 0x03;
    EXPECT_EQ(mw_can_decode(&f, &m), MW_ERR_RANGE);
    f.data[0] = 0xE8;  // 1000 is the limit
    EXPECT_EQ(mw_can_decode(&f, &m), MW_OK);
    f.data[3] = 3;
    EXPECT_EQ(mw_can_decode(&f, &m), MW_ERR_RANGE);

    // STATUS: state 4..15, mode 3.
    const mw_status st = status_of(4);
    for (unsigned state = MW_NODE_STATE_COUNT; state < 16; ++state) {
        ASSERT_EQ(mw_status_encode(&st, &f), MW_OK);
        f.data[0] = static_cast<uint8_t>((f.data[0] & 0xF0u) | state);
        EXPECT_EQ(mw_can_decode(&f, &m), MW_ERR_RANGE) << state;
    }
    ASSERT_EQ(mw_status_encode(&st, &f), MW_OK);
    f.data[0] = static_cast<uint8_t>(f.data[0] | 0x30u);
    EXPECT_EQ(mw_can_decode(&f, &m), MW_ERR_RANGE);

    // MAG: one axis invalid but not all; a value beyond the AK8963's range.
    mw_raw mag = raw_of(MW_FN_MAG, 2, 10, 20, 30, 0);
    ASSERT_EQ(mw_raw_encode(&mag, &f), MW_OK);
    f.data[0] = 0x00;
    f.data[1] = 0x80;
    EXPECT_EQ(mw_can_decode(&f, &m), MW_ERR_RANGE);
    f.data[0] = 0xF9;  // 32761
    f.data[1] = 0x7F;
    EXPECT_EQ(mw_can_decode(&f, &m), MW_ERR_RANGE);
    mag.xyz[1] = MW_MAG_INVALID;
    EXPECT_EQ(mw_raw_encode(&mag, &f), MW_ERR_RANGE);
    // The same values are legal accelerometer counts.
    const mw_raw acc = raw_of(MW_FN_ACCEL, 2, INT16_MIN, 32761, 0, 0);
    ASSERT_EQ(mw_raw_encode(&acc, &f), MW_OK);
    EXPECT_EQ(mw_can_decode(&f, &m), MW_OK);

    // ATT: a component beyond 1/sqrt(2), and three components holding more than 3/4 of the norm.
    f = frame_of(0x141, 8);
    f.data[0] = 0x83;  // 23171
    f.data[1] = 0x5A;
    EXPECT_EQ(mw_can_decode(&f, &m), MW_ERR_RANGE);
    f.data[0] = 0x82;  // 23170: allowed alone
    EXPECT_EQ(mw_can_decode(&f, &m), MW_OK);
    f.data[2] = 0x82;  // two at 1/sqrt(2): the dropped one would be 0, not the largest
    f.data[3] = 0x5A;
    EXPECT_EQ(mw_can_decode(&f, &m), MW_ERR_RANGE);
}

TEST(WireCan, EncodersRejectBadArguments) {
    mw_can_frame f{};
    const mw_can_frame untouched = frame_of(0x7AB, 3);
    f = untouched;
    const mw_raw node0 = raw_of(MW_FN_ACCEL, 0, 1, 2, 3, 4);
    EXPECT_EQ(mw_raw_encode(&node0, &f), MW_ERR_ARGUMENT);
    const mw_raw node64 = raw_of(MW_FN_GYRO, 64, 1, 2, 3, 4);
    EXPECT_EQ(mw_raw_encode(&node64, &f), MW_ERR_ARGUMENT);
    const mw_raw bad_kind = raw_of(MW_FN_STATUS, 1, 1, 2, 3, 4);
    EXPECT_EQ(mw_raw_encode(&bad_kind, &f), MW_ERR_ARGUMENT);
    EXPECT_EQ(mw_raw_encode(nullptr, &f), MW_ERR_ARGUMENT);
    EXPECT_EQ(mw_raw_encode(&node0, nullptr), MW_ERR_ARGUMENT);
    mw_config c = config_of(64, 100, MW_MODE_RAW);
    EXPECT_EQ(mw_config_encode(&c, &f), MW_ERR_ARGUMENT);
    c = config_of(1, 0, MW_MODE_RAW);
    EXPECT_EQ(mw_config_encode(&c, &f), MW_ERR_RANGE);
    c = config_of(1, 100, static_cast<mw_mode>(7));
    EXPECT_EQ(mw_config_encode(&c, &f), MW_ERR_RANGE);
    mw_status s = status_of(1);
    s.state = static_cast<mw_node_state>(9);
    EXPECT_EQ(mw_status_encode(&s, &f), MW_ERR_RANGE);
    mw_message msg{};
    msg.function = MW_FN_GYRO;
    msg.u.raw = raw_of(MW_FN_ACCEL, 1, 0, 0, 0, 0);  // tag and payload disagree
    EXPECT_EQ(mw_can_encode(&msg, &f), MW_ERR_ARGUMENT);
    msg.function = static_cast<mw_function>(12);
    EXPECT_EQ(mw_can_encode(&msg, &f), MW_ERR_ARGUMENT);
    // Failed encoders leave the output alone.
    EXPECT_EQ(f.id, untouched.id);
    EXPECT_EQ(f.dlc, untouched.dlc);
    mw_message out{};
    EXPECT_EQ(mw_can_decode(nullptr, &out), MW_ERR_ARGUMENT);
    EXPECT_EQ(mw_can_decode(&f, nullptr), MW_ERR_ARGUMENT);
}

TEST(WireCan, EncodersZeroUnusedBytes) {
    mw_can_frame f{};
    std::memset(f.data, 0xAA, sizeof f.data);
    const mw_sync s{7};
    ASSERT_EQ(mw_sync_encode(&s, &f), MW_OK);
    for (unsigned i = MW_DLC_SYNC; i < 8; ++i)
        EXPECT_EQ(f.data[i], 0) << i;
}

TEST(WireCan, CounterExtendFollowsWrapAround) {
    // 16-bit low bits around the 16-bit wrap.
    EXPECT_EQ(mw_counter_extend(0x0001FFFFu, 0x0000u, 16), 0x00020000u);
    EXPECT_EQ(mw_counter_extend(0x00020000u, 0xFFFFu, 16), 0x0001FFFFu);
    EXPECT_EQ(mw_counter_extend(0x00020005u, 0x0005u, 16), 0x00020005u);
    // Around the 32-bit wrap, both directions.
    EXPECT_EQ(mw_counter_extend(0xFFFFFFF0u, 0x0003u, 16), 0x00000003u);
    EXPECT_EQ(mw_counter_extend(0x00000003u, 0xFFF0u, 16), 0xFFFFFFF0u);
    // 14-bit ATT counters.
    EXPECT_EQ(mw_counter_extend(0x00004000u, 0x3FFFu, MW_ATT_COUNTER_BITS), 0x00003FFFu);
    EXPECT_EQ(mw_counter_extend(0xFFFFFFFFu, 0x0000u, MW_ATT_COUNTER_BITS), 0x00000000u);
    // The window is [ref - 2^(bits-1), ref + 2^(bits-1) - 1].
    EXPECT_EQ(mw_counter_extend(0x00010000u, 0x8000u, 16), 0x00008000u);
    EXPECT_EQ(mw_counter_extend(0x00010000u, 0x7FFFu, 16), 0x00017FFFu);
    EXPECT_EQ(mw_counter_extend(5u, 0xABCDu, 32), 0xABCDu);
    EXPECT_EQ(mw_counter_extend(5u, 0xABCDu, 0), 5u);
    // Exhaustive over a sliding window across the 32-bit wrap.
    for (uint32_t ref = 0xFFFFF000u; ref != 0x00001000u; ++ref) {
        for (int32_t delta : {-32768, -1, 0, 1, 32767}) {
            const uint32_t truth = ref + static_cast<uint32_t>(delta);
            ASSERT_EQ(mw_counter_extend(ref, truth & 0xFFFFu, 16), truth) << ref << " " << delta;
        }
    }
}

TEST(WireCan, ErrorNamesAreDistinct) {
    EXPECT_STREQ(mw_error_name(MW_ERR_DLC), "MW_ERR_DLC");
    EXPECT_STREQ(mw_error_name(MW_ERR_CRC), "MW_ERR_CRC");
    EXPECT_STREQ(mw_error_name(-100), "MW_ERR_?");
    for (int a = MW_ERR_RECORD; a <= MW_OK; ++a) {
        for (int b = a + 1; b <= MW_OK; ++b)
            EXPECT_STRNE(mw_error_name(a), mw_error_name(b));
    }
}

}  // namespace
