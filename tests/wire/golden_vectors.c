/*
 * golden_vectors.c — every byte here was derived by hand from docs/protocol.md (and the packet
 * CRCs cross-checked with an independent CRC-32 implementation, zlib's crc32); the tests check
 * the library against them and check that docs/protocol.md shows the same bytes.
 */
#include "golden_vectors.h"

#include <stdio.h>

#define CAN(id_, dlc_, ...) \
    {                       \
        (id_), (dlc_), {    \
            __VA_ARGS__     \
        }                   \
    }

const golden_can golden_can_vectors[] = {
    {"sync counter=0x12345678",
     {.function = MW_FN_SYNC, .u = {.sync = {0x12345678u}}},
     CAN(0x000, 4, 0x78, 0x56, 0x34, 0x12)},
    {"sync counter=0xFFFFFFFF",
     {.function = MW_FN_SYNC, .u = {.sync = {0xFFFFFFFFu}}},
     CAN(0x000, 4, 0xFF, 0xFF, 0xFF, 0xFF)},
    {"config all nodes 100 Hz 16 g 2000 dps raw status 1 s",
     {.function = MW_FN_CONFIG, .u = {.config = {0, 100, MW_ACCEL_16G, MW_GYRO_2000DPS, MW_MODE_RAW, 1}}},
     CAN(0x040, 5, 0x64, 0x00, 0x0F, 0x00, 0x01)},
    {"config node 5 200 Hz 8 g 1000 dps attitude status off",
     {.function = MW_FN_CONFIG, .u = {.config = {5, 200, MW_ACCEL_8G, MW_GYRO_1000DPS, MW_MODE_ATTITUDE, 0}}},
     CAN(0x045, 5, 0xC8, 0x00, 0x0A, 0x01, 0x00)},
    {"accel node 3 xyz=100,-200,2048 counter=0xBEEF",
     {.function = MW_FN_ACCEL, .u = {.raw = {MW_FN_ACCEL, 3, {100, -200, 2048}, 0xBEEFu}}},
     CAN(0x083, 8, 0x64, 0x00, 0x38, 0xFF, 0x00, 0x08, 0xEF, 0xBE)},
    {"gyro node 15 xyz=-1,0,32767 counter=0x0001",
     {.function = MW_FN_GYRO, .u = {.raw = {MW_FN_GYRO, 15, {-1, 0, 32767}, 0x0001u}}},
     CAN(0x0CF, 8, 0xFF, 0xFF, 0x00, 0x00, 0xFF, 0x7F, 0x01, 0x00)},
    {"mag node 1 xyz=300,-32760,32760 counter=0x1234",
     {.function = MW_FN_MAG, .u = {.raw = {MW_FN_MAG, 1, {300, -32760, 32760}, 0x1234u}}},
     CAN(0x101, 8, 0x2C, 0x01, 0x08, 0x80, 0xF8, 0x7F, 0x34, 0x12)},
    {"mag node 63 invalid counter=0xFFFF",
     {.function = MW_FN_MAG, .u = {.raw = {MW_FN_MAG, 63, {MW_MAG_INVALID, MW_MAG_INVALID, MW_MAG_INVALID}, 0xFFFFu}}},
     CAN(0x13F, 8, 0x00, 0x80, 0x00, 0x80, 0x00, 0x80, 0xFF, 0xFF)},
    {"attitude node 2 q=1,0,0,0 counter=0x3FFF",
     {.function = MW_FN_ATTITUDE, .u = {.attitude = {2, {1.0f, 0.0f, 0.0f, 0.0f}, 0x3FFFu}}},
     CAN(0x142, 8, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xFF, 0x3F)},
    {"attitude node 7 q=0,0,0,1 counter=0x2345",
     {.function = MW_FN_ATTITUDE, .u = {.attitude = {7, {0.0f, 0.0f, 0.0f, 1.0f}, 0x2345u}}},
     CAN(0x147, 8, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x45, 0xE3)},
    {"attitude node 4 q=0.2,-0.4,0.8,0.4 counter=5",
     {.function = MW_FN_ATTITUDE, .u = {.attitude = {4, {0.2f, -0.4f, 0.8f, 0.4f}, 5u}}},
     CAN(0x144, 8, 0x9A, 0x19, 0xCD, 0xCC, 0x33, 0x33, 0x05, 0x80)},
    {"attitude node 4 q=0.5,-0.5,0.5,-0.5 counter=100",
     {.function = MW_FN_ATTITUDE, .u = {.attitude = {4, {0.5f, -0.5f, 0.5f, -0.5f}, 100u}}},
     CAN(0x144, 8, 0x00, 0xC0, 0x00, 0x40, 0x00, 0xC0, 0x64, 0x00)},
    {"status node 9 running raw mag 16 g 2000 dps flags=0x84 uptime=258 tx_overflows=7 "
     "sync_missed=255",
     {.function = MW_FN_STATUS,
      .u = {.status = {9, MW_NODE_RUNNING, MW_MODE_RAW, true, MW_ACCEL_16G, MW_GYRO_2000DPS, 0x84u, 1u, 258u, 7u,
                       255u}}},
     CAN(0x189, 8, 0x42, 0x0F, 0x84, 0x01, 0x02, 0x01, 0x07, 0xFF)},
    {"status sink running uptime=65535 rx_overflows=3",
     {.function = MW_FN_STATUS,
      .u = {.status = {0, MW_NODE_RUNNING, MW_MODE_RAW, false, MW_ACCEL_2G, MW_GYRO_250DPS, 0u, 1u, 65535u, 3u, 0u}}},
     CAN(0x180, 8, 0x02, 0x00, 0x00, 0x01, 0xFF, 0xFF, 0x03, 0x00)},
};
const size_t golden_can_count = sizeof golden_can_vectors / sizeof golden_can_vectors[0];

static const mw_stamped_frame packet1_frames[] = {
    {0u, CAN(0x000, 4, 0x2A, 0x00, 0x00, 0x00)},
    {150u, CAN(0x081, 8, 0x00, 0x00, 0x00, 0x00, 0x00, 0x08, 0x2A, 0x00)},
};
/* clang-format off */
static const uint8_t packet1_bytes[] = {
    0x4D, 0x43, 0x41, 0x50,                         /* magic "MCAP" */
    0x01,                                           /* version */
    0x01,                                           /* sink_id */
    0x02, 0x00,                                     /* frame_count 2 */
    0x16, 0x00,                                     /* payload_length 22 */
    0x07, 0x00, 0x00, 0x00,                         /* sequence 7 */
    0x40, 0x42, 0x0F, 0x00, 0x00, 0x00, 0x00, 0x00, /* timestamp_us 1000000 */
    0x00, 0x00, 0x04, 0x00, 0x00,                   /* SYNC id 0x000, dlc 4, offset 0 */
    0x2A, 0x00, 0x00, 0x00,                         /*   counter 42 */
    0x81, 0x00, 0x08, 0x96, 0x00,                   /* ACCEL node 1, dlc 8, offset 150 us */
    0x00, 0x00, 0x00, 0x00, 0x00, 0x08, 0x2A, 0x00, /*   x 0, y 0, z 2048 (1 g at 16 g), counter 42 */
    0xE7, 0x1A, 0xB0, 0x65,                         /* CRC-32 0x65B01AE7 */
};
/* clang-format on */
static const uint8_t packet_empty_bytes[] = {
    0x4D, 0x43, 0x41, 0x50, 0x01, 0xC8, 0x00, 0x00, 0x00, 0x00, 0xFF, 0xFF, 0xFF,
    0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x01, 0xAE, 0x43, 0x3F,
};

const golden_packet golden_packets[] = {
    {"packet sink 1 sequence 7 timestamp 1000000 us: SYNC 42 + ACCEL node 1",
     {1u, 7u, 1000000u},
     packet1_frames,
     2u,
     packet1_bytes,
     sizeof packet1_bytes},
    {"packet sink 200 sequence 0xFFFFFFFF timestamp 2^64-1 us, no frames",
     {200u, 0xFFFFFFFFu, UINT64_MAX},
     NULL,
     0u,
     packet_empty_bytes,
     sizeof packet_empty_bytes},
};
const size_t golden_packet_count = sizeof golden_packets / sizeof golden_packets[0];

size_t golden_format_hex(const uint8_t* bytes, size_t n, char* out, size_t capacity) {
    size_t len = 0;
    if (capacity == 0u) return 0u;
    out[0] = '\0';
    for (size_t i = 0; i < n && len + 4u <= capacity; ++i) {
        len += (size_t)snprintf(out + len, capacity - len, i == 0u ? "%02X" : " %02X", bytes[i]);
    }
    return len;
}

size_t golden_format_can(const char* name, const mw_can_frame* frame, char* out, size_t capacity) {
    int len = snprintf(out, capacity, "%s: id=0x%03X dlc=%u data=", name, (unsigned)frame->id, (unsigned)frame->dlc);
    if (len < 0 || (size_t)len >= capacity) return 0u;
    return (size_t)len + golden_format_hex(frame->data, frame->dlc, out + len, capacity - (size_t)len);
}
