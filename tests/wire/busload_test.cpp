// busload_test.cpp — worst-case frame length checked against real bit stuffing, and the numbers
// docs/protocol.md promises (15 raw nodes fit at 100 Hz on 1 Mbit/s, not at 200 Hz).
#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "golden_vectors.h"
#include "mocap_wire/mw_busload.h"

namespace {

// Bits of a real CAN 2.0A data frame on the wire: SOF..CRC serialised and stuffed (a
// complement bit after five equal bits, stuff bits counting towards the next run), then CRC
// delimiter, ACK slot, ACK delimiter, EOF and the 3-bit intermission.
uint32_t actual_frame_bits(const mw_can_frame& f) {
    std::vector<int> bits;
    auto push = [&](uint32_t value, int n) {
        for (int i = n - 1; i >= 0; --i)
            bits.push_back(static_cast<int>((value >> i) & 1u));
    };
    push(0, 1);      // SOF
    push(f.id, 11);  // identifier
    push(0, 3);      // RTR, IDE, r0
    push(f.dlc, 4);
    for (unsigned i = 0; i < f.dlc; ++i)
        push(f.data[i], 8);
    uint32_t crc = 0;  // CRC-15/CAN, polynomial 0x4599
    for (int b : bits) {
        const uint32_t top = ((crc >> 14) & 1u) ^ static_cast<uint32_t>(b);
        crc = (crc << 1) & 0x7FFFu;
        if (top != 0u) crc ^= 0x4599u;
    }
    push(crc, 15);
    uint32_t stuffed = 0;
    int run_bit = -1;
    int run = 0;
    for (int b : bits) {
        if (b == run_bit) {
            ++run;
        } else {
            run_bit = b;
            run = 1;
        }
        if (run == 5) {  // insert the complement; it starts a new run of length 1
            ++stuffed;
            run_bit = 1 - b;
            run = 1;
        }
    }
    return static_cast<uint32_t>(bits.size()) + stuffed + 13u;
}

TEST(WireBusload, WorstCaseFrameLengths) {
    EXPECT_EQ(mw_can_frame_bits(0), 55u);
    EXPECT_EQ(mw_can_frame_bits(4), 95u);
    EXPECT_EQ(mw_can_frame_bits(5), 105u);
    EXPECT_EQ(mw_can_frame_bits(8), 135u);
    EXPECT_EQ(mw_can_frame_bits(15), 135u);
    EXPECT_EQ(mw_frames_per_sample(MW_MODE_RAW), 3u);
    EXPECT_EQ(mw_frames_per_sample(MW_MODE_ATTITUDE), 1u);
    EXPECT_EQ(mw_frames_per_sample(MW_MODE_RAW_ATTITUDE), 4u);
    EXPECT_EQ(mw_frames_per_sample(static_cast<mw_mode>(3)), 0u);
}

TEST(WireBusload, RealFramesNeverExceedTheWorstCase) {
    for (size_t i = 0; i < golden_can_count; ++i) {
        const mw_can_frame& f = golden_can_vectors[i].frame;
        EXPECT_LE(actual_frame_bits(f), mw_can_frame_bits(f.dlc)) << golden_can_vectors[i].name;
    }
    std::mt19937 rng(31337);
    std::uniform_int_distribution<int> id(0, MW_CAN_ID_MAX);
    std::uniform_int_distribution<int> dlc(0, 8);
    std::uniform_int_distribution<int> byte(0, 255);
    std::uniform_int_distribution<int> pattern(0, 3);
    uint32_t longest8 = 0;
    for (int n = 0; n < 20000; ++n) {
        mw_can_frame f{};
        f.id = static_cast<uint16_t>(id(rng));
        f.dlc = static_cast<uint8_t>(dlc(rng));
        // Mostly stuffing-heavy payloads (runs of 0x00, 0xFF, 0x0F, 0x78), some random;
        // bytes beyond the DLC are not sent.
        const uint8_t fills[4] = {0x00, 0xFF, 0x0F, 0x78};
        const int p = pattern(rng);
        for (uint8_t& d : f.data)
            d = p == 3 ? static_cast<uint8_t>(byte(rng)) : fills[p];
        const uint32_t bits = actual_frame_bits(f);
        ASSERT_LE(bits, mw_can_frame_bits(f.dlc)) << "id " << f.id << " dlc " << int(f.dlc);
        if (f.dlc == 8 && bits > longest8) longest8 = bits;
    }
    // The bound is not vacuous: stuffing-heavy frames come within 15 % of it.
    EXPECT_GT(longest8 * 100u, mw_can_frame_bits(8) * 85u);
}

mw_busload load(uint32_t nodes, uint32_t rate_hz, mw_mode mode, uint32_t bitrate) {
    const mw_busload_params p{nodes, rate_hz, mode, bitrate, 1};
    mw_busload out{};
    EXPECT_EQ(mw_busload_compute(&p, &out), MW_OK);
    return out;
}

TEST(WireBusload, FifteenRawNodesFitAtOneHundredHertzOnOneMegabitButNotAtTwoHundred) {
    // 100 x (SYNC 95 + 15 x 3 x 135) + 15 STATUS x 135 per second.
    const mw_busload a = load(15, 100, MW_MODE_RAW, 1000000);
    EXPECT_EQ(a.frames_per_s, 100u * 46u + 15u);
    EXPECT_EQ(a.bits_per_s, 100u * (95u + 45u * 135u) + 15u * 135u);
    EXPECT_EQ(a.bits_per_s, 619025u);
    EXPECT_EQ(a.load_permille, 620u);
    EXPECT_TRUE(a.fits);

    const mw_busload b = load(15, 200, MW_MODE_RAW, 1000000);
    EXPECT_EQ(b.bits_per_s, 1236025u);
    EXPECT_FALSE(b.fits);

    const mw_busload c = load(15, 100, MW_MODE_RAW, 500000);
    EXPECT_EQ(c.load_permille, 1239u);
    EXPECT_FALSE(c.fits);

    // On-node attitude sends one frame per sample instead of three: 200 Hz fits again.
    const mw_busload d = load(15, 200, MW_MODE_ATTITUDE, 1000000);
    EXPECT_EQ(d.bits_per_s, 200u * (95u + 15u * 135u) + 15u * 135u);
    EXPECT_TRUE(d.fits);
}

TEST(WireBusload, StatusPeriodAndArguments) {
    mw_busload_params p{10, 100, MW_MODE_RAW, 1000000, 0};
    mw_busload none{};
    ASSERT_EQ(mw_busload_compute(&p, &none), MW_OK);
    p.status_period_s = 3;
    mw_busload slow{};
    ASSERT_EQ(mw_busload_compute(&p, &slow), MW_OK);
    EXPECT_EQ(slow.frames_per_s, none.frames_per_s + 4u);  // ceil(10 / 3)
    EXPECT_EQ(slow.bits_per_s, none.bits_per_s + 450u);    // 10 x 135 / 3
    p.nodes = 64;
    EXPECT_EQ(mw_busload_compute(&p, &slow), MW_ERR_ARGUMENT);
    p.nodes = 1;
    p.rate_hz = 0;
    EXPECT_EQ(mw_busload_compute(&p, &slow), MW_ERR_ARGUMENT);
    p.rate_hz = 100;
    p.bitrate_bps = 0;
    EXPECT_EQ(mw_busload_compute(&p, &slow), MW_ERR_ARGUMENT);
    p.bitrate_bps = 1000000;
    p.mode = static_cast<mw_mode>(5);
    EXPECT_EQ(mw_busload_compute(&p, &slow), MW_ERR_ARGUMENT);
    EXPECT_EQ(mw_busload_compute(nullptr, &slow), MW_ERR_ARGUMENT);
}

}  // namespace
