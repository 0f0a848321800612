// Length-delimited framing: every split of the byte stream yields the same messages;
// oversized and garbage prefixes are reported, not buffered.
#include "serve/framing.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "mocap/v1/mocap.pb.h"

namespace mocap::serve {
namespace {

std::string three_messages() {
    std::string stream;
    v1::ClientMessage a;
    a.mutable_subscribe()->add_subject_ids(7);
    a.mutable_subscribe()->set_decimation(2);
    v1::ClientMessage b;  // empty body: a zero-length message is legal
    v1::ClientMessage c;
    c.mutable_control()->set_token(std::string(300, 'k'));  // > 127 bytes: 2-byte prefix
    c.mutable_control()->mutable_calibrate()->set_subject_id(3);
    EXPECT_TRUE(append_delimited(a, stream));
    EXPECT_TRUE(append_delimited(b, stream));
    EXPECT_TRUE(append_delimited(c, stream));
    return stream;
}

// Feeds `stream` in chunks of the given sizes (cycled) and collects the payloads.
std::vector<std::string> feed(const std::string& stream, std::vector<std::size_t> chunks,
                              std::size_t max_bytes = 1024) {
    DelimitedReader reader(max_bytes);
    std::vector<std::string> out;
    std::size_t at = 0;
    for (std::size_t k = 0; at < stream.size(); ++k) {
        auto area = reader.write_area();
        EXPECT_FALSE(area.empty());
        std::size_t n = std::min({chunks[k % chunks.size()], area.size(), stream.size() - at});
        std::copy_n(stream.data() + at, n, area.data());
        reader.commit(n);
        at += n;
        for (;;) {
            FrameResult r = reader.next();
            if (r.status == FrameStatus::kNeedMore) break;
            EXPECT_EQ(r.status, FrameStatus::kMessage);
            if (r.status != FrameStatus::kMessage) return out;
            out.emplace_back(reinterpret_cast<const char*>(r.payload.data()), r.payload.size());
        }
    }
    EXPECT_EQ(reader.buffered(), 0u);
    return out;
}

TEST(Framing, VarintMatchesProtobufEncoding) {
    std::uint8_t buf[10];
    EXPECT_EQ(write_varint(0, buf), 1u);
    EXPECT_EQ(buf[0], 0);
    EXPECT_EQ(write_varint(300, buf), 2u);
    EXPECT_EQ(buf[0], 0xAC);
    EXPECT_EQ(buf[1], 0x02);
    EXPECT_EQ(write_varint(0xFFFFFFFFu, buf), 5u);
}

TEST(Framing, EverySplitPointYieldsTheSameMessages) {
    const std::string stream = three_messages();
    const auto whole = feed(stream, {stream.size()});
    ASSERT_EQ(whole.size(), 3u);
    v1::ClientMessage c;
    ASSERT_TRUE(c.ParseFromString(whole[2]));
    EXPECT_EQ(c.control().token().size(), 300u);
    EXPECT_EQ(c.control().calibrate().subject_id(), 3u);
    EXPECT_TRUE(whole[1].empty());

    for (std::size_t split = 1; split < stream.size(); ++split) {
        EXPECT_EQ(feed(stream, {split, stream.size()}), whole) << "split at " << split;
    }
    EXPECT_EQ(feed(stream, {1}), whole);  // one byte at a time
    EXPECT_EQ(feed(stream, {3, 7}), whole);
}

TEST(Framing, MessagesLargerThanTheInitialBufferStillArrive) {
    v1::ClientMessage big;
    big.mutable_control()->set_token(std::string(200000, 'x'));
    std::string stream;
    ASSERT_TRUE(append_delimited(big, stream));
    ASSERT_TRUE(append_delimited(big, stream));
    const auto out = feed(stream, {4096, 1, 70000}, 300000);
    ASSERT_EQ(out.size(), 2u);
    EXPECT_EQ(out[0].size(), big.ByteSizeLong());
}

TEST(Framing, OversizedLengthIsReportedBeforeThePayloadArrives) {
    DelimitedReader reader(100);
    std::uint8_t prefix[10];
    const std::size_t n = write_varint(101, prefix);
    auto area = reader.write_area();
    std::copy_n(prefix, n, area.data());
    reader.commit(n);
    EXPECT_EQ(reader.next().status, FrameStatus::kTooLarge);
    EXPECT_EQ(reader.next().status, FrameStatus::kTooLarge);  // sticky
}

TEST(Framing, OverlongPrefixIsGarbage) {
    DelimitedReader reader(1 << 20);
    auto area = reader.write_area();
    for (int i = 0; i < 6; ++i)
        area[static_cast<std::size_t>(i)] = 0xFF;
    reader.commit(6);
    EXPECT_EQ(reader.next().status, FrameStatus::kBadPrefix);
}

TEST(Framing, IncompletePrefixWaits) {
    DelimitedReader reader(1 << 20);
    auto area = reader.write_area();
    area[0] = 0x80;  // continuation bit set, more prefix bytes to come
    reader.commit(1);
    EXPECT_EQ(reader.next().status, FrameStatus::kNeedMore);
}

}  // namespace
}  // namespace mocap::serve
