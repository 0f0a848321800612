// crc32_test.cpp — the CRC-32/IEEE check value and the incremental form.
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

}  // namespace
