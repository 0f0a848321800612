// keepalive_test.cpp — the host -> sink keepalive (mw_keepalive.h): exact bytes (also shown in
// docs/protocol.md §3.5), round trip, rejections, and the incremental decoder's chunking,
// resynchronisation and byte accounting.
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "mocap_wire/mocap_wire.h"

namespace {

// period 250 ms, sequence 7: what docs/protocol.md §3.5 shows.
const std::vector<std::uint8_t> kGolden = {0x4D, 0x43, 0x4B, 0x41, 0x02, 0x00, 0xFA, 0x00,
                                           0x07, 0x00, 0x00, 0x00, 0x37, 0xE1, 0xFB, 0x5E};

std::vector<std::uint8_t> encode(std::uint16_t period_ms, std::uint32_t sequence) {
    const mw_keepalive k{period_ms, sequence};
    std::vector<std::uint8_t> out(MW_KEEPALIVE_SIZE);
    EXPECT_EQ(mw_keepalive_encode(&k, out.data(), out.size()), static_cast<std::int32_t>(MW_KEEPALIVE_SIZE));
    return out;
}

// Feeds everything, in chunks of `chunk` bytes; returns the keepalives decoded.
std::vector<mw_keepalive> feed(mw_keepalive_decoder& d, const std::vector<std::uint8_t>& bytes, std::size_t chunk) {
    std::vector<mw_keepalive> got;
    for (std::size_t at = 0; at < bytes.size(); at += chunk) {
        const std::size_t n = std::min(chunk, bytes.size() - at);
        const std::uint8_t* p = bytes.data() + at;
        std::size_t left = n;
        for (;;) {
            std::size_t used = 0;
            mw_keepalive k{};
            const mw_stream_result r = mw_keepalive_decoder_feed(&d, p, left, &used, &k);
            EXPECT_LE(used, left);
            p += used;
            left -= used;
            if (r == MW_STREAM_NEED_MORE) break;
            if (r == MW_STREAM_PACKET) got.push_back(k);
        }
        EXPECT_EQ(left, 0u);
    }
    return got;
}

TEST(WireKeepalive, EncodesTheDocumentedBytes) {
    EXPECT_EQ(encode(250, 7), kGolden);
    std::uint32_t crc = 0;
    for (int i = 0; i < 4; ++i)
        crc |= static_cast<std::uint32_t>(kGolden[12 + i]) << (8 * i);
    EXPECT_EQ(mw_crc32(kGolden.data(), 12), crc);
    std::ifstream in(MOCAP_PROTOCOL_DOC);
    std::stringstream doc;
    doc << in.rdbuf();
    EXPECT_NE(doc.str().find("4D 43 4B 41 02 00 FA 00 07 00 00 00 37 E1 FB 5E"), std::string::npos)
        << "docs/protocol.md must show the keepalive's golden bytes";
}

TEST(WireKeepalive, RoundTripsAndKeepsThePacketVersion) {
    mw_keepalive k{};
    const auto bytes = encode(65535, 0xFFFFFFFFu);
    ASSERT_EQ(mw_keepalive_decode(bytes.data(), bytes.size(), &k), MW_OK);
    EXPECT_EQ(k.period_ms, 65535);
    EXPECT_EQ(k.sequence, 0xFFFFFFFFu);
    EXPECT_EQ(MW_PACKET_VERSION, 1u) << "stream version 2 leaves the sink -> host packet as it was";
    EXPECT_EQ(MW_STREAM_VERSION, 2u);
}

TEST(WireKeepalive, EncoderRefusesBadArguments) {
    std::uint8_t out[MW_KEEPALIVE_SIZE];
    std::memset(out, 0xAA, sizeof out);
    const mw_keepalive zero_period{0, 1};
    const mw_keepalive ok{250, 1};
    EXPECT_EQ(mw_keepalive_encode(&zero_period, out, sizeof out), MW_ERR_RANGE);
    EXPECT_EQ(mw_keepalive_encode(&ok, out, sizeof out - 1), MW_ERR_SPACE);
    EXPECT_EQ(mw_keepalive_encode(nullptr, out, sizeof out), MW_ERR_ARGUMENT);
    EXPECT_EQ(mw_keepalive_encode(&ok, nullptr, sizeof out), MW_ERR_ARGUMENT);
    for (std::uint8_t b : out)
        EXPECT_EQ(b, 0xAA) << "nothing written on error";
}

TEST(WireKeepalive, DecoderRejectsWhatIsNotAKeepalive) {
    mw_keepalive k{};
    auto bad = kGolden;
    EXPECT_EQ(mw_keepalive_decode(bad.data(), bad.size() - 1, &k), MW_ERR_LENGTH);
    bad[0] = 'X';
    EXPECT_EQ(mw_keepalive_decode(bad.data(), bad.size(), &k), MW_ERR_LENGTH);
    bad = kGolden;
    bad[4] = 1;  // a version-1 host sends no keepalive; anything else is not this frame
    EXPECT_EQ(mw_keepalive_decode(bad.data(), bad.size(), &k), MW_ERR_VERSION);
    bad = kGolden;
    bad[9] ^= 0x01;
    EXPECT_EQ(mw_keepalive_decode(bad.data(), bad.size(), &k), MW_ERR_CRC);
    // period 0 with a right CRC: a range error, not a CRC one.
    bad = kGolden;
    bad[6] = bad[7] = 0;
    const std::uint32_t crc = mw_crc32(bad.data(), 12);
    for (int i = 0; i < 4; ++i)
        bad[12 + i] = static_cast<std::uint8_t>(crc >> (8 * i));
    EXPECT_EQ(mw_keepalive_decode(bad.data(), bad.size(), &k), MW_ERR_RANGE);
    // Reserved flags are ignored (room for compatible additions).
    bad = kGolden;
    bad[5] = 0x80;
    const std::uint32_t crc2 = mw_crc32(bad.data(), 12);
    for (int i = 0; i < 4; ++i)
        bad[12 + i] = static_cast<std::uint8_t>(crc2 >> (8 * i));
    ASSERT_EQ(mw_keepalive_decode(bad.data(), bad.size(), &k), MW_OK);
    EXPECT_EQ(k.period_ms, 250);
}

TEST(WireKeepalive, StreamDecoderGivesTheSameKeepalivesForAnyChunking) {
    std::vector<std::uint8_t> stream;
    for (std::uint32_t s = 0; s < 20; ++s) {
        const auto k = encode(200, s);
        stream.insert(stream.end(), k.begin(), k.end());
    }
    for (std::size_t chunk : {1u, 3u, 7u, 16u, 17u, 1000u}) {
        mw_keepalive_decoder d;
        mw_keepalive_decoder_init(&d);
        const auto got = feed(d, stream, chunk);
        ASSERT_EQ(got.size(), 20u) << "chunk " << chunk;
        for (std::uint32_t s = 0; s < 20; ++s)
            EXPECT_EQ(got[s].sequence, s);
        EXPECT_EQ(d.counters.packets, 20u);
        EXPECT_EQ(d.counters.bytes_in, stream.size());
        EXPECT_EQ(d.counters.bytes_discarded, 0u);
        EXPECT_EQ(d.len, 0u);
    }
}

TEST(WireKeepalive, StreamDecoderResynchronisesAfterGarbageAndFalseMagic) {
    std::vector<std::uint8_t> stream = {0x00, 0x4D, 0x43, 0x4B, 0x41, 0x02, 0x11};  // garbage + a false magic
    const auto k1 = encode(250, 1);
    stream.insert(stream.end(), k1.begin(), k1.end());
    auto corrupt = encode(250, 2);
    corrupt[10] ^= 0xFF;  // CRC failure
    stream.insert(stream.end(), corrupt.begin(), corrupt.end());
    const auto k3 = encode(250, 3);
    stream.insert(stream.end(), k3.begin(), k3.end());
    stream.push_back(0x4D);  // a partial magic stays buffered
    for (std::size_t chunk : {1u, 5u, 64u}) {
        mw_keepalive_decoder d;
        mw_keepalive_decoder_init(&d);
        const auto got = feed(d, stream, chunk);
        ASSERT_EQ(got.size(), 2u) << "chunk " << chunk;
        EXPECT_EQ(got[0].sequence, 1u);
        EXPECT_EQ(got[1].sequence, 3u);
        EXPECT_GE(d.counters.malformed_packets, 2u) << "the false magic and the CRC failure";
        EXPECT_GE(d.counters.crc_failures, 1u);
        EXPECT_EQ(d.len, 1u);
        EXPECT_EQ(d.counters.bytes_in, stream.size());
        EXPECT_EQ(d.counters.bytes_in, 2u * MW_KEEPALIVE_SIZE + d.counters.bytes_discarded + d.len);
    }
}

TEST(WireKeepalive, PacketDecoderDiscardsKeepalivesAndKeepsItsPackets) {
    // A host never sends packets, but one stream decoder must not take one frame for the
    // other: the magics differ in their third byte.
    std::vector<std::uint8_t> stream = encode(250, 9);
    const mw_packet_header h{1, 0, 1000};
    std::uint8_t pkt[64];
    const std::int32_t n = mw_packet_encode(&h, nullptr, 0, pkt, sizeof pkt);
    ASSERT_GT(n, 0);
    stream.insert(stream.end(), pkt, pkt + n);
    auto dec = std::make_unique<mw_stream_decoder>();
    mw_stream_decoder_init(dec.get());
    auto out = std::make_unique<mw_packet>();
    std::size_t used = 0;
    int packets = 0;
    const std::uint8_t* p = stream.data();
    std::size_t left = stream.size();
    for (;;) {
        const mw_stream_result r = mw_stream_decoder_feed(dec.get(), p, left, &used, out.get());
        p += used;
        left -= used;
        if (r == MW_STREAM_NEED_MORE) break;
        if (r == MW_STREAM_PACKET) ++packets;
    }
    EXPECT_EQ(packets, 1);
    mw_keepalive_decoder d;
    mw_keepalive_decoder_init(&d);
    EXPECT_EQ(feed(d, stream, 4).size(), 1u);
}

}  // namespace
