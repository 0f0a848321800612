// golden_test.cpp — exact bytes: every golden vector encodes to its bytes, decodes back to its
// message, and appears verbatim in docs/protocol.md (so the document cannot drift from the code).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>

#include "golden_vectors.h"
#include "wire_expect.hpp"

namespace {

std::string read_doc() {
    std::ifstream in(MOCAP_PROTOCOL_DOC);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

bool same_frame(const mw_can_frame& a, const mw_can_frame& b) {
    return a.id == b.id && a.dlc == b.dlc && std::memcmp(a.data, b.data, sizeof a.data) == 0;
}

TEST(WireGolden, CanVectorsEncodeExactly) {
    for (size_t i = 0; i < golden_can_count; ++i) {
        const golden_can& g = golden_can_vectors[i];
        mw_can_frame f{};
        ASSERT_EQ(mw_can_encode(&g.message, &f), MW_OK) << g.name;
        EXPECT_TRUE(same_frame(f, g.frame)) << g.name;
    }
}

TEST(WireGolden, CanVectorsDecodeToTheirMessage) {
    for (size_t i = 0; i < golden_can_count; ++i) {
        const golden_can& g = golden_can_vectors[i];
        mw_message m{};
        ASSERT_EQ(mw_can_decode(&g.frame, &m), MW_OK) << g.name;
        ASSERT_EQ(m.function, g.message.function) << g.name;
        switch (m.function) {
            case MW_FN_SYNC:
                EXPECT_EQ(m.u.sync.counter, g.message.u.sync.counter);
                break;
            case MW_FN_CONFIG:
                expect_same_config(m.u.config, g.message.u.config);
                break;
            case MW_FN_ACCEL:
            case MW_FN_GYRO:
            case MW_FN_MAG:
                expect_same_raw(m.u.raw, g.message.u.raw);
                break;
            case MW_FN_ATTITUDE: {
                const mw_attitude& a = m.u.attitude;
                const mw_attitude& b = g.message.u.attitude;
                EXPECT_EQ(a.node_id, b.node_id);
                EXPECT_EQ(a.counter_low, b.counter_low & 0x3FFFu);
                for (int k = 0; k < 4; ++k)
                    EXPECT_NEAR(a.q[k], b.q[k], 3e-5f) << g.name << " " << k;
                mw_can_frame again{};
                ASSERT_EQ(mw_attitude_encode(&a, &again), MW_OK);
                EXPECT_TRUE(same_frame(again, g.frame)) << g.name;
                break;
            }
            case MW_FN_STATUS:
                expect_same_status(m.u.status, g.message.u.status);
                break;
            default:
                FAIL() << g.name;
        }
    }
}

TEST(WireGolden, PacketsEncodeAndDecodeExactly) {
    auto dec = std::make_unique<mw_stream_decoder>();
    auto pkt = std::make_unique<mw_packet>();
    for (size_t i = 0; i < golden_packet_count; ++i) {
        const golden_packet& g = golden_packets[i];
        uint8_t out[256];
        const int32_t n = mw_packet_encode(&g.header, g.frames, g.frame_count, out, sizeof out);
        ASSERT_EQ(n, static_cast<int32_t>(g.size)) << g.name;
        EXPECT_EQ(std::memcmp(out, g.bytes, g.size), 0) << g.name;
        // The last four bytes are the CRC-32 of everything before them.
        uint32_t crc = 0;
        for (int k = 0; k < 4; ++k)
            crc |= static_cast<uint32_t>(g.bytes[g.size - 4 + k]) << (8 * k);
        EXPECT_EQ(mw_crc32(g.bytes, g.size - 4), crc) << g.name;

        mw_stream_decoder_init(dec.get());
        size_t used = 0;
        ASSERT_EQ(mw_stream_decoder_feed(dec.get(), g.bytes, g.size, &used, pkt.get()), MW_STREAM_PACKET);
        EXPECT_EQ(used, g.size);
        EXPECT_EQ(pkt->header.sink_id, g.header.sink_id);
        EXPECT_EQ(pkt->header.sequence, g.header.sequence);
        EXPECT_EQ(pkt->header.timestamp_us, g.header.timestamp_us);
        ASSERT_EQ(pkt->frame_count, g.frame_count);
        for (size_t k = 0; k < g.frame_count; ++k) {
            EXPECT_EQ(pkt->frames[k].offset_us, g.frames[k].offset_us);
            EXPECT_TRUE(same_frame(pkt->frames[k].frame, g.frames[k].frame));
        }
    }
}

TEST(WireGolden, ProtocolDocumentShowsTheSameBytes) {
    const std::string doc = read_doc();
    ASSERT_FALSE(doc.empty()) << MOCAP_PROTOCOL_DOC;
    char line[256];
    for (size_t i = 0; i < golden_can_count; ++i) {
        const golden_can& g = golden_can_vectors[i];
        ASSERT_GT(golden_format_can(g.name, &g.frame, line, sizeof line), 0u);
        EXPECT_NE(doc.find(line), std::string::npos) << "docs/protocol.md lacks: " << line;
    }
    for (size_t i = 0; i < golden_packet_count; ++i) {
        const golden_packet& g = golden_packets[i];
        char hex[1024];
        golden_format_hex(g.bytes, g.size, hex, sizeof hex);
        EXPECT_NE(doc.find(g.name), std::string::npos) << "docs/protocol.md lacks: " << g.name;
        EXPECT_NE(doc.find(hex), std::string::npos) << "docs/protocol.md lacks: " << hex;
    }
    EXPECT_NE(doc.find("0xCBF43926"), std::string::npos);
}

}  // namespace
