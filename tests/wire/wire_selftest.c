/*
 * wire_selftest.c — a plain-C99 check of the wire library that needs nothing but libc, so the
 * same checks run where GoogleTest cannot: as a 32-bit (-m32) build on the host, where size_t
 * and long are 32 bits wide. It replays the golden vectors, a byte-by-byte stream decode with a
 * garbage prefix, the CRC check value and the bus-load figures. Exit status 0 = all passed.
 */
#include <stdio.h>
#include <string.h>

#include "golden_vectors.h"

static int failures = 0;

#define CHECK(cond)                                                                  \
    do {                                                                             \
        if (!(cond)) {                                                               \
            fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #cond); \
            ++failures;                                                              \
        }                                                                            \
    } while (0)

static int same_frame(const mw_can_frame* a, const mw_can_frame* b) {
    return a->id == b->id && a->dlc == b->dlc && memcmp(a->data, b->data, sizeof a->data) == 0;
}

static void check_can_vectors(void) {
    for (size_t i = 0; i < golden_can_count; ++i) {
        const golden_can* g = &golden_can_vectors[i];
        mw_can_frame f;
        mw_message m;
        mw_can_frame again;
        memset(&f, 0, sizeof f);
        CHECK(mw_can_encode(&g->message, &f) == MW_OK);
        CHECK(same_frame(&f, &g->frame));
        CHECK(mw_can_decode(&g->frame, &m) == MW_OK);
        CHECK(m.function == g->message.function);
        CHECK(mw_can_encode(&m, &again) == MW_OK);
        CHECK(same_frame(&again, &g->frame));
    }
}

static mw_stream_decoder decoder;
static mw_packet packet;

static void check_packets(void) {
    uint8_t stream[512];
    size_t len = 0;
    const uint8_t garbage[5] = {0x00, 'M', 'C', 'A', 0x7F};
    memcpy(stream, garbage, sizeof garbage);
    len += sizeof garbage;
    for (size_t i = 0; i < golden_packet_count; ++i) {
        const golden_packet* g = &golden_packets[i];
        uint8_t out[256];
        const int32_t n = mw_packet_encode(&g->header, g->frames, g->frame_count, out, sizeof out);
        CHECK(n == (int32_t)g->size);
        CHECK(memcmp(out, g->bytes, g->size) == 0);
        memcpy(stream + len, g->bytes, g->size);
        len += g->size;
    }
    mw_stream_decoder_init(&decoder);
    size_t packets = 0;
    for (size_t pos = 0; pos < len; ++pos) { /* one byte at a time */
        const uint8_t* p = &stream[pos];
        size_t left = 1;
        for (;;) {
            size_t used = 0;
            const mw_stream_result r = mw_stream_decoder_feed(&decoder, p, left, &used, &packet);
            p += used;
            left -= used;
            if (r == MW_STREAM_NEED_MORE) break;
            CHECK(r == MW_STREAM_PACKET);
            if (r == MW_STREAM_PACKET && packets < golden_packet_count) {
                const golden_packet* g = &golden_packets[packets];
                CHECK(packet.header.sequence == g->header.sequence);
                CHECK(packet.header.timestamp_us == g->header.timestamp_us);
                CHECK(packet.frame_count == g->frame_count);
            }
            ++packets;
        }
    }
    CHECK(packets == golden_packet_count);
    CHECK(decoder.counters.bytes_discarded == sizeof garbage);
    CHECK(decoder.counters.bytes_in == len);
}

static void check_crc_and_busload(void) {
    CHECK(mw_crc32("123456789", 9) == 0xCBF43926u);
    const mw_busload_params p100 = {15, 100, MW_MODE_RAW, 1000000, 1};
    const mw_busload_params p200 = {15, 200, MW_MODE_RAW, 1000000, 1};
    mw_busload a;
    mw_busload b;
    CHECK(mw_busload_compute(&p100, &a) == MW_OK && a.fits && a.bits_per_s == 619025u);
    CHECK(mw_busload_compute(&p200, &b) == MW_OK && !b.fits && b.bits_per_s == 1236025u);
    CHECK(mw_counter_extend(0xFFFFFFF0u, 0x0003u, 16) == 0x00000003u);
}

int main(void) {
    check_can_vectors();
    check_packets();
    check_crc_and_busload();
    printf("wire self-test (%u-bit pointers): %s\n", (unsigned)(8u * sizeof(void*)),
           failures == 0 ? "passed" : "FAILED");
    return failures == 0 ? 0 : 1;
}
