// crc32_test.cpp — the CRC-32/IEEE check value, the incremental form, and the sliced form
// against the byte-at-a-time one. Built twice: against mocap_wire (slicing-by-8) and as
// wire_crc32_slice1_tests with mw_crc32.c compiled for MW_CRC32_SLICE_BY=1.
#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <vector>

#include "mocap_wire/mw_crc32.h"

namespace {

// Bit-at-a-time reference written from the parameters in mw_crc32.h, independent of the table.
uint32_t crc32_bitwise(const uint8_t* p, size_t n) {
    uint32_t c = 0xFFFFFFFFu;
    for (size_t i = 0; i < n; ++i) {
        c ^= p[i];
        for (int k = 0; k < 8; ++k)
            c = (c & 1u) != 0u ? (c >> 1) ^ 0xEDB88320u : c >> 1;
    }
    return c ^ 0xFFFFFFFFu;
}

TEST(WireCrc32, CheckValue) {
    const char* s = "123456789";
    EXPECT_EQ(mw_crc32(s, std::strlen(s)), 0xCBF43926u);
    EXPECT_EQ(mw_crc32(nullptr, 0), 0x00000000u);
    const uint8_t zero = 0;
    EXPECT_EQ(mw_crc32(&zero, 1), 0xD202EF8Du);
    const char* fox = "The quick brown fox jumps over the lazy dog";
    EXPECT_EQ(mw_crc32(fox, std::strlen(fox)), 0x414FA339u);
}

TEST(WireCrc32, TableMatchesBitwiseAndIncrementalMatchesOneShot) {
    std::mt19937 rng(99);
    std::uniform_int_distribution<int> byte(0, 255);
    for (size_t n = 0; n < 600; n += 7) {
        std::vector<uint8_t> d(n);
        for (auto& b : d)
            b = static_cast<uint8_t>(byte(rng));
        const uint32_t whole = mw_crc32(d.data(), n);
        EXPECT_EQ(whole, crc32_bitwise(d.data(), n)) << n;
        for (size_t cut = 0; cut <= n; cut += 13) {
            uint32_t c = mw_crc32_update(MW_CRC32_INIT, d.data(), cut);
            c = mw_crc32_update(c, d.data() + cut, n - cut);
            EXPECT_EQ(c, whole) << n << " " << cut;
        }
    }
}

// Every length 0..80 (tail lengths 0..7 after 0..10 full 8-byte steps) and random longer
// ones, at all 8 start offsets of an 8-aligned buffer, split at a random point: the sliced
// form, the byte-at-a-time form and the bit-at-a-time reference agree.
TEST(WireCrc32, SlicedMatchesBytewiseAtAnyLengthAndAlignment) {
    std::mt19937 rng(2024);
    std::uniform_int_distribution<int> byte(0, 255);
    std::uniform_int_distribution<size_t> long_len(81, 4096);
    alignas(8) static uint8_t buf[4096 + 8];
    for (auto& b : buf)
        b = static_cast<uint8_t>(byte(rng));
    std::vector<size_t> lengths;
    for (size_t n = 0; n <= 80; ++n)
        lengths.push_back(n);
    for (int i = 0; i < 60; ++i)
        lengths.push_back(long_len(rng));
    for (const size_t n : lengths) {
        for (size_t offset = 0; offset < 8; ++offset) {
            const uint8_t* p = buf + offset;
            const uint32_t bytewise = mw_crc32_update_bytewise(MW_CRC32_INIT, p, n);
            ASSERT_EQ(mw_crc32(p, n), bytewise) << "len " << n << " offset " << offset;
            if (n % 17 == 0) {
                ASSERT_EQ(bytewise, crc32_bitwise(p, n)) << n;
            }
            const size_t cut = std::uniform_int_distribution<size_t>(0, n)(rng);
            const uint32_t head = mw_crc32_update(MW_CRC32_INIT, p, cut);
            ASSERT_EQ(mw_crc32_update(head, p + cut, n - cut), bytewise)
                << "len " << n << " offset " << offset << " cut " << cut;
            ASSERT_EQ(mw_crc32_update_bytewise(head, p + cut, n - cut), bytewise);
        }
    }
}

// The byte order of the 8-byte steps matters: a buffer whose words are byte-reversed must
// give a different CRC (guards against a word load that ignores the wire's byte order).
TEST(WireCrc32, SlicedIsByteOrderSensitive) {
    const uint8_t a[16] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16};
    const uint8_t b[16] = {4, 3, 2, 1, 8, 7, 6, 5, 12, 11, 10, 9, 16, 15, 14, 13};
    EXPECT_EQ(mw_crc32(a, 16), crc32_bitwise(a, 16));
    EXPECT_EQ(mw_crc32(b, 16), crc32_bitwise(b, 16));
    EXPECT_NE(mw_crc32(a, 16), mw_crc32(b, 16));
}

}  // namespace
