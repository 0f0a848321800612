// packet_test.cpp — sink -> host packets: builder, encoder, and the incremental stream decoder
// under every kind of damage (garbage, false magics, truncation, bad CRC, bad headers/records).
#include <gtest/gtest.h>

#include <cstring>
#include <memory>
#include <random>
#include <vector>

#include "mocap_wire/mw_crc32.h"
#include "mocap_wire/mw_packet.h"

namespace {

using Bytes = std::vector<uint8_t>;

mw_stamped_frame stamped(uint16_t id, uint8_t dlc, uint16_t offset_us, uint8_t fill) {
    mw_stamped_frame f{};
    f.offset_us = offset_us;
    f.frame.id = id;
    f.frame.dlc = dlc;
    for (uint8_t i = 0; i < dlc; ++i)
        f.frame.data[i] = static_cast<uint8_t>(fill + i);
    return f;
}

std::vector<mw_stamped_frame> random_frames(std::mt19937& rng, size_t count) {
    std::uniform_int_distribution<int> id(0, MW_CAN_ID_MAX);
    std::uniform_int_distribution<int> dlc(0, MW_CAN_DLC_MAX);
    std::uniform_int_distribution<int> byte(0, 255);
    std::uniform_int_distribution<int> offset(0, 65535);
    std::vector<mw_stamped_frame> frames(count);
    for (auto& f : frames) {
        f = mw_stamped_frame{};
        f.offset_us = static_cast<uint16_t>(offset(rng));
        f.frame.id = static_cast<uint16_t>(id(rng));
        f.frame.dlc = static_cast<uint8_t>(dlc(rng));
        for (uint8_t i = 0; i < f.frame.dlc; ++i)
            f.frame.data[i] = static_cast<uint8_t>(byte(rng));
    }
    return frames;
}

Bytes encode(const mw_packet_header& h, const std::vector<mw_stamped_frame>& frames) {
    Bytes out(mw_packet_size(frames.data(), frames.size()));
    const int32_t n = mw_packet_encode(&h, frames.data(), frames.size(), out.data(), out.size());
    EXPECT_EQ(n, static_cast<int32_t>(out.size()));
    return out;
}

// Re-seals a hand-edited packet so that only the edited field is wrong.
void reseal(Bytes& pkt) {
    const uint32_t crc = mw_crc32(pkt.data(), pkt.size() - 4);
    for (int i = 0; i < 4; ++i)
        pkt[pkt.size() - 4 + i] = static_cast<uint8_t>(crc >> (8 * i));
}

struct Event {
    mw_stream_result result;
    int error;  // last_error for MALFORMED
    uint32_t sequence;
    std::vector<mw_stamped_frame> frames;
};

// Feeds `data` in chunks of the given sizes (cycled) and records every event.
class Feeder {
public:
    Feeder() : dec_(std::make_unique<mw_stream_decoder>()), pkt_(std::make_unique<mw_packet>()) {
        mw_stream_decoder_init(dec_.get());
    }

    std::vector<Event> feed(const Bytes& data, const std::vector<size_t>& chunks = {SIZE_MAX}) {
        std::vector<Event> events;
        size_t pos = 0;
        size_t k = 0;
        while (pos < data.size()) {
            const size_t n = std::min(chunks[k++ % chunks.size()], data.size() - pos);
            // Copy each chunk into an exactly sized heap block so reads past it are caught by ASan.
            std::unique_ptr<uint8_t[]> chunk(new uint8_t[n]);
            std::memcpy(chunk.get(), data.data() + pos, n);
            const uint8_t* p = chunk.get();
            size_t left = n;
            for (;;) {
                size_t used = 0;
                const mw_stream_result r = mw_stream_decoder_feed(dec_.get(), p, left, &used, pkt_.get());
                EXPECT_LE(used, left);
                p += used;
                left -= used;
                if (r == MW_STREAM_NEED_MORE) {
                    EXPECT_EQ(left, 0u);
                    break;
                }
                Event e{r, dec_->last_error, 0, {}};
                if (r == MW_STREAM_PACKET) {
                    e.sequence = pkt_->header.sequence;
                    e.frames.assign(pkt_->frames, pkt_->frames + pkt_->frame_count);
                }
                events.push_back(std::move(e));
            }
            pos += n;
        }
        return events;
    }

    const mw_stream_decoder& decoder() const { return *dec_; }

private:
    std::unique_ptr<mw_stream_decoder> dec_;
    std::unique_ptr<mw_packet> pkt_;
};

bool same_frames(const std::vector<mw_stamped_frame>& a, const std::vector<mw_stamped_frame>& b) {
    if (a.size() != b.size()) return false;
    for (size_t i = 0; i < a.size(); ++i) {
        if (a[i].offset_us != b[i].offset_us || a[i].frame.id != b[i].frame.id || a[i].frame.dlc != b[i].frame.dlc ||
            std::memcmp(a[i].frame.data, b[i].frame.data, a[i].frame.dlc) != 0) {
            return false;
        }
    }
    return true;
}

std::vector<uint32_t> packet_sequences(const std::vector<Event>& events) {
    std::vector<uint32_t> s;
    for (const auto& e : events) {
        if (e.result == MW_STREAM_PACKET) s.push_back(e.sequence);
    }
    return s;
}

size_t malformed(const std::vector<Event>& events) {
    size_t n = 0;
    for (const auto& e : events)
        n += e.result == MW_STREAM_MALFORMED ? 1u : 0u;
    return n;
}

void expect_accounting(const Feeder& f, uint64_t good_packet_bytes) {
    const mw_stream_counters& c = f.decoder().counters;
    EXPECT_EQ(c.bytes_in, good_packet_bytes + c.bytes_discarded + mw_stream_decoder_buffered(&f.decoder()));
}

// Edits one byte of a packet, re-seals its CRC and expects the decoder to reject it with `error`.
void expect_rejected(const Bytes& base, size_t offset, uint8_t value, int error) {
    Bytes p = base;
    p[offset] = value;
    reseal(p);
    Feeder f;
    const auto ev = f.feed(p);
    ASSERT_FALSE(ev.empty());
    EXPECT_EQ(ev[0].result, MW_STREAM_MALFORMED);
    EXPECT_EQ(ev[0].error, error) << "offset " << offset << " value " << int(value);
    EXPECT_TRUE(packet_sequences(ev).empty());
    EXPECT_EQ(f.decoder().counters.crc_failures, 0u);
}

TEST(WirePacket, RoundTripOfRandomPacketsWholeAndByteByByte) {
    std::mt19937 rng(2024);
    std::vector<std::vector<mw_stamped_frame>> sent;
    Bytes stream;
    for (uint32_t seq = 0; seq < 200; ++seq) {
        sent.push_back(random_frames(rng, seq % 40));
        const mw_packet_header h{static_cast<uint8_t>(seq), seq, 1000000ull * seq};
        const Bytes p = encode(h, sent.back());
        stream.insert(stream.end(), p.begin(), p.end());
    }
    Feeder whole;
    Feeder bytewise;
    Feeder odd;
    const auto a = whole.feed(stream);
    const auto b = bytewise.feed(stream, {1});
    const auto c = odd.feed(stream, {7, 1, 300, 2, 4096, 13});
    ASSERT_EQ(a.size(), sent.size());
    ASSERT_EQ(b.size(), sent.size());
    ASSERT_EQ(c.size(), sent.size());
    for (size_t i = 0; i < sent.size(); ++i) {
        ASSERT_EQ(a[i].result, MW_STREAM_PACKET);
        EXPECT_EQ(a[i].sequence, i);
        EXPECT_TRUE(same_frames(a[i].frames, sent[i])) << i;
        EXPECT_TRUE(same_frames(b[i].frames, sent[i])) << i;
        EXPECT_TRUE(same_frames(c[i].frames, sent[i])) << i;
    }
    EXPECT_EQ(whole.decoder().counters.packets, 200u);
    EXPECT_EQ(whole.decoder().counters.bytes_discarded, 0u);
    EXPECT_EQ(bytewise.decoder().counters.bytes_in, stream.size());
    expect_accounting(whole, stream.size());
}

TEST(WirePacket, HeaderFieldsRoundTripIncludingWrap) {
    const mw_packet_header h{255, 0xFFFFFFFFu, 0xFEDCBA9876543210ull};
    const Bytes p = encode(h, {stamped(0x7FF, 8, 65535, 1)});
    Feeder f;
    const auto ev = f.feed(p);
    ASSERT_EQ(ev.size(), 1u);
    ASSERT_EQ(ev[0].result, MW_STREAM_PACKET);
    EXPECT_EQ(ev[0].sequence, 0xFFFFFFFFu);
    auto dec = std::make_unique<mw_stream_decoder>();
    auto pkt = std::make_unique<mw_packet>();
    mw_stream_decoder_init(dec.get());
    size_t used = 0;
    ASSERT_EQ(mw_stream_decoder_feed(dec.get(), p.data(), p.size(), &used, pkt.get()), MW_STREAM_PACKET);
    EXPECT_EQ(pkt->header.sink_id, 255u);
    EXPECT_EQ(pkt->header.timestamp_us, 0xFEDCBA9876543210ull);
    EXPECT_EQ(pkt->frames[0].offset_us, 65535u);
    EXPECT_EQ(pkt->frames[0].frame.id, 0x7FFu);
}

TEST(WirePacket, GarbagePrefixIsDiscardedAndCounted) {
    const Bytes p = encode({1, 9, 5}, {stamped(0x081, 8, 10, 0)});
    // Garbage that holds partial magics ("M", "MC", "MCA") but never a whole one.
    Bytes s = {0x00, 'M', 0x11, 'M', 'C', 0x22, 'M', 'C', 'A', 0x33, 0xFF, 'M', 'M', 'C'};
    const size_t garbage = s.size();
    s.insert(s.end(), p.begin(), p.end());
    for (const std::vector<size_t>& chunks : {std::vector<size_t>{SIZE_MAX}, {1}, {3}}) {
        Feeder f;
        const auto ev = f.feed(s, chunks);
        ASSERT_EQ(ev.size(), 1u);
        EXPECT_EQ(ev[0].result, MW_STREAM_PACKET);
        EXPECT_EQ(f.decoder().counters.bytes_discarded, garbage);
        EXPECT_EQ(f.decoder().counters.malformed_packets, 0u);
        expect_accounting(f, p.size());
    }
}

TEST(WirePacket, BadMagicNeverYieldsAPacket) {
    Bytes p = encode({1, 1, 1}, {stamped(0x000, 4, 0, 0)});
    p[3] = 'Q';  // "MCAQ"
    Feeder f;
    const auto ev = f.feed(p);
    EXPECT_TRUE(ev.empty());
    EXPECT_EQ(f.decoder().counters.bytes_discarded, p.size());
    EXPECT_EQ(mw_stream_decoder_buffered(&f.decoder()), 0u);
}

TEST(WirePacket, EveryCorruptedByteIsRejectedAndTheNextPacketSurvives) {
    const Bytes good = encode({3, 100, 777}, {stamped(0x000, 4, 0, 9), stamped(0x0C5, 8, 120, 1)});
    const Bytes next = encode({3, 101, 778}, {stamped(0x105, 8, 5, 2)});
    for (size_t i = 0; i < good.size(); ++i) {
        for (uint8_t flip : {0x01, 0x80, 0xFF}) {
            Bytes s = good;
            s[i] ^= flip;
            s.insert(s.end(), next.begin(), next.end());
            Feeder f;
            const auto ev = f.feed(s);
            const auto seqs = packet_sequences(ev);
            ASSERT_EQ(seqs.size(), 1u) << "byte " << i << " flip " << int(flip);
            EXPECT_EQ(seqs[0], 101u) << "byte " << i;
            if (i >= 4) {
                // Past the magic the damage is seen, as a header error, a record error or the CRC.
                ASSERT_GE(malformed(ev), 1u) << "byte " << i;
                if (i >= MW_PACKET_HEADER_SIZE) {
                    EXPECT_EQ(ev[0].error, MW_ERR_CRC) << "byte " << i;
                    EXPECT_EQ(f.decoder().counters.crc_failures, 1u);
                }
            }
            expect_accounting(f, next.size());
        }
    }
}

TEST(WirePacket, TruncatedPacketThenAGoodOne) {
    const Bytes a = encode({1, 1, 1}, {stamped(0x081, 8, 0, 1), stamped(0x0C1, 8, 0, 2)});
    const Bytes b = encode({1, 2, 2}, {stamped(0x101, 8, 0, 3)});
    Bytes s(a.begin(), a.end() - 5);  // the connection lost the end of a
    {
        Feeder f;
        EXPECT_TRUE(f.feed(s).empty());  // need more
        EXPECT_EQ(mw_stream_decoder_buffered(&f.decoder()), s.size());
    }
    s.insert(s.end(), b.begin(), b.end());
    for (const std::vector<size_t>& chunks : {std::vector<size_t>{SIZE_MAX}, {1}}) {
        Feeder f;
        const auto ev = f.feed(s, chunks);
        ASSERT_EQ(ev.size(), 2u);
        EXPECT_EQ(ev[0].result, MW_STREAM_MALFORMED);
        EXPECT_EQ(ev[0].error, MW_ERR_CRC);  // a's claimed length swallowed b's first bytes
        EXPECT_EQ(ev[1].result, MW_STREAM_PACKET);
        EXPECT_EQ(ev[1].sequence, 2u);
        EXPECT_EQ(f.decoder().counters.bytes_discarded, a.size() - 5);
        expect_accounting(f, b.size());
    }
}

TEST(WirePacket, HugeCountIsRejectedAsSoonAsTheHeaderIsIn) {
    Bytes h = encode({1, 1, 1}, {});
    h.resize(MW_PACKET_HEADER_SIZE);
    const uint16_t count = MW_PACKET_MAX_FRAMES + 1;
    const uint16_t len = count * 5;
    h[6] = static_cast<uint8_t>(count);
    h[7] = static_cast<uint8_t>(count >> 8);
    h[8] = static_cast<uint8_t>(len);
    h[9] = static_cast<uint8_t>(len >> 8);
    Feeder f;
    const auto ev = f.feed(h);  // just the header: no waiting for 2565 bytes that never come
    ASSERT_EQ(ev.size(), 1u);
    EXPECT_EQ(ev[0].result, MW_STREAM_MALFORMED);
    EXPECT_EQ(ev[0].error, MW_ERR_LENGTH);
    EXPECT_EQ(mw_stream_decoder_buffered(&f.decoder()), 0u);
    EXPECT_EQ(f.decoder().counters.bytes_discarded, h.size());
}

TEST(WirePacket, ImpossiblePayloadLengthsAndVersionsAreRejected) {
    const Bytes base = encode({1, 1, 1}, {stamped(0x081, 8, 0, 1)});
    struct Case {
        size_t offset;
        uint8_t value;
        int error;
    };
    const Case cases[] = {
        {4, 2, MW_ERR_VERSION},  // version 2
        {4, 0, MW_ERR_VERSION},  // version 0
        {8, 4, MW_ERR_LENGTH},   // payload 4 < 1 record of at least 5
        {8, 14, MW_ERR_LENGTH},  // payload 14 > 1 record of at most 13
        {6, 0, MW_ERR_LENGTH},   // 0 frames but 13 payload bytes
    };
    for (const Case& c : cases)
        expect_rejected(base, c.offset, c.value, c.error);
}

TEST(WirePacket, BadRecordsWithAValidCrcAreRejected) {
    const Bytes base = encode({1, 1, 1}, {stamped(0x081, 4, 0, 1), stamped(0x082, 4, 0, 2)});
    const size_t r0 = MW_PACKET_HEADER_SIZE;
    struct Case {
        size_t offset;
        uint8_t value;
    };
    const Case cases[] = {
        {r0 + 1, 0x08},  // id 0x881: bit 11 set
        {r0 + 1, 0x80},  // id bit 15 set
        {r0 + 2, 9},     // dlc 9
        {r0 + 2, 5},     // dlc 5: records overrun the declared payload
        {r0 + 2, 3},     // dlc 3: records end before the declared payload
    };
    for (const Case& c : cases)
        expect_rejected(base, c.offset, c.value, MW_ERR_RECORD);
}

TEST(WirePacket, FalseMagicInGarbageDoesNotHideTheRealPacket) {
    const Bytes real = encode({2, 55, 9}, {stamped(0x083, 8, 1, 7)});
    // A plausible header claiming 40 records of 13 bytes, immediately followed by the real packet.
    Bytes fake = encode({2, 54, 8}, {});
    fake.resize(MW_PACKET_HEADER_SIZE);
    fake[6] = 40;
    fake[8] = static_cast<uint8_t>(40 * 13);
    fake[9] = static_cast<uint8_t>((40 * 13) >> 8);
    Bytes s = fake;
    s.insert(s.end(), real.begin(), real.end());
    Bytes tail(600, 0x00);  // enough to complete the fake candidate
    s.insert(s.end(), tail.begin(), tail.end());
    const Bytes after = encode({2, 56, 10}, {});
    s.insert(s.end(), after.begin(), after.end());
    for (const std::vector<size_t>& chunks : {std::vector<size_t>{SIZE_MAX}, {1}, {50}}) {
        Feeder f;
        const auto ev = f.feed(s, chunks);
        EXPECT_EQ(packet_sequences(ev), (std::vector<uint32_t>{55u, 56u}));
        EXPECT_EQ(f.decoder().counters.crc_failures, 1u);
        expect_accounting(f, real.size() + after.size());
    }
}

TEST(WirePacket, RandomGarbageWithPacketsIsRobust) {
    std::mt19937 rng(424242);
    std::uniform_int_distribution<int> byte(0, 255);
    std::uniform_int_distribution<int> glen(0, 3000);
    Bytes s;
    uint64_t good_bytes = 0;
    std::vector<uint32_t> expected;
    for (uint32_t seq = 0; seq < 300; ++seq) {
        const size_t n = static_cast<size_t>(glen(rng));
        for (size_t i = 0; i < n; ++i)
            s.push_back(static_cast<uint8_t>(byte(rng)));
        if (seq % 7 == 0) {  // a false magic with a plausible small header inside the garbage
            const Bytes fake = {'M', 'C', 'A', 'P', 1, 0, 1, 0, 13, 0};
            s.insert(s.end(), fake.begin(), fake.end());
        }
        const Bytes p = encode({0, seq, seq}, random_frames(rng, seq % 20));
        s.insert(s.end(), p.begin(), p.end());
        good_bytes += p.size();
        expected.push_back(seq);
    }
    Feeder whole;
    Feeder chunked;
    EXPECT_EQ(packet_sequences(whole.feed(s)), expected);
    EXPECT_EQ(packet_sequences(chunked.feed(s, {1, 2, 3, 5, 8, 13, 21, 34, 55, 89, 144})), expected);
    expect_accounting(whole, good_bytes);
    EXPECT_EQ(whole.decoder().counters.bytes_discarded, s.size() - good_bytes);
    EXPECT_EQ(whole.decoder().counters.malformed_packets, chunked.decoder().counters.malformed_packets);

    // Pure noise: never a packet, never stuck, everything accounted for.
    Bytes noise(1 << 20);
    for (auto& b : noise)
        b = static_cast<uint8_t>(byte(rng));
    Feeder f;
    EXPECT_TRUE(packet_sequences(f.feed(noise, {4096})).empty());
    expect_accounting(f, 0);
    EXPECT_LT(mw_stream_decoder_buffered(&f.decoder()), MW_PACKET_MAX_SIZE + 1);
}

TEST(WirePacket, BuilderEnforcesCapacityFrameLimitAndRecords) {
    const mw_packet_header h{1, 2, 3};
    mw_packet_builder b{};
    uint8_t small[MW_PACKET_HEADER_SIZE + MW_PACKET_CRC_SIZE + 12];
    EXPECT_EQ(mw_packet_builder_begin(&b, small, MW_PACKET_HEADER_SIZE + 3, &h), MW_ERR_SPACE);
    ASSERT_EQ(mw_packet_builder_begin(&b, small, sizeof small, &h), MW_OK);
    const mw_stamped_frame eight = stamped(0x081, 8, 0, 0);
    const mw_stamped_frame four = stamped(0x000, 4, 0, 0);
    EXPECT_EQ(mw_packet_builder_add(&b, &eight), MW_ERR_SPACE);  // 13 > 12 bytes left
    EXPECT_EQ(mw_packet_builder_add(&b, &four), MW_OK);          // 9 bytes
    mw_stamped_frame bad = four;
    bad.frame.id = 0x800;
    EXPECT_EQ(mw_packet_builder_add(&b, &bad), MW_ERR_RECORD);
    bad = four;
    bad.frame.dlc = 9;
    EXPECT_EQ(mw_packet_builder_add(&b, &bad), MW_ERR_RECORD);
    const int32_t n = mw_packet_builder_finish(&b);
    ASSERT_EQ(n, static_cast<int32_t>(MW_PACKET_HEADER_SIZE + 9 + MW_PACKET_CRC_SIZE));
    EXPECT_EQ(mw_packet_builder_add(&b, &four), MW_ERR_ARGUMENT);  // finished
    Feeder f;
    const auto ev = f.feed(Bytes(small, small + n));
    ASSERT_EQ(ev.size(), 1u);
    EXPECT_EQ(ev[0].frames.size(), 1u);

    // MW_PACKET_MAX_FRAMES, then no more; the full packet decodes.
    std::vector<uint8_t> big(MW_PACKET_MAX_SIZE);
    ASSERT_EQ(mw_packet_builder_begin(&b, big.data(), big.size(), &h), MW_OK);
    for (unsigned i = 0; i < MW_PACKET_MAX_FRAMES; ++i)
        ASSERT_EQ(mw_packet_builder_add(&b, &eight), MW_OK);
    EXPECT_EQ(mw_packet_builder_add(&b, &four), MW_ERR_SPACE);
    ASSERT_EQ(mw_packet_builder_finish(&b), static_cast<int32_t>(MW_PACKET_MAX_SIZE));
    Feeder g;
    const auto ev2 = g.feed(big);
    ASSERT_EQ(ev2.size(), 1u);
    EXPECT_EQ(ev2[0].frames.size(), MW_PACKET_MAX_FRAMES);
}

TEST(WirePacket, EncoderRejectsBadInput) {
    const mw_packet_header h{1, 2, 3};
    std::vector<mw_stamped_frame> frames(MW_PACKET_MAX_FRAMES + 1, stamped(0x081, 0, 0, 0));
    std::vector<uint8_t> out(MW_PACKET_MAX_SIZE * 2);
    EXPECT_EQ(mw_packet_encode(&h, frames.data(), frames.size(), out.data(), out.size()), MW_ERR_LENGTH);
    frames.resize(2);
    frames[1].frame.dlc = 12;
    EXPECT_EQ(mw_packet_encode(&h, frames.data(), 2, out.data(), out.size()), MW_ERR_RECORD);
    frames[1].frame.dlc = 8;
    const size_t need = mw_packet_size(frames.data(), 2);
    EXPECT_EQ(need, MW_PACKET_HEADER_SIZE + 5 + 13 + MW_PACKET_CRC_SIZE);
    EXPECT_EQ(mw_packet_encode(&h, frames.data(), 2, out.data(), need - 1), MW_ERR_SPACE);
    EXPECT_EQ(mw_packet_encode(&h, frames.data(), 2, out.data(), need), static_cast<int32_t>(need));
    EXPECT_EQ(mw_packet_encode(nullptr, frames.data(), 2, out.data(), need), MW_ERR_ARGUMENT);
    EXPECT_EQ(mw_packet_encode(&h, nullptr, 2, out.data(), need), MW_ERR_ARGUMENT);
}

TEST(WirePacket, FeedWithNoBytesOrBadArgumentsDoesNothing) {
    auto dec = std::make_unique<mw_stream_decoder>();
    auto pkt = std::make_unique<mw_packet>();
    mw_stream_decoder_init(dec.get());
    size_t used = 99;
    EXPECT_EQ(mw_stream_decoder_feed(dec.get(), nullptr, 0, &used, pkt.get()), MW_STREAM_NEED_MORE);
    EXPECT_EQ(used, 0u);
    const uint8_t b[2] = {'M', 'C'};
    used = 99;
    EXPECT_EQ(mw_stream_decoder_feed(dec.get(), b, 2, &used, nullptr), MW_STREAM_NEED_MORE);
    EXPECT_EQ(used, 0u);
    EXPECT_EQ(dec->counters.bytes_in, 0u);
}

}  // namespace
