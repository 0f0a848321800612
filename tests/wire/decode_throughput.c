/*
 * decode_throughput.c — how fast the host side decodes the sink stream: builds 1 MiB of
 * packets shaped like a 17-node raw body (SYNC + 17 x 3 frames per packet), then feeds it
 * 100 times in 1460-byte chunks (one TCP segment) through mw_stream_decoder and mw_can_decode.
 * Prints one line; not a ctest (timings vary), run it by hand:
 *   build/tests/wire/wire_decode_throughput
 */
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <time.h>

#include "mocap_wire/mocap_wire.h"

static mw_stream_decoder decoder;
static mw_packet packet;
static uint8_t stream[1u << 20];

static double now_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

static size_t build_stream(unsigned* packets) {
    size_t len = 0;
    *packets = 0;
    while (len + MW_PACKET_MAX_SIZE < sizeof stream) {
        const mw_packet_header h = {1u, *packets, (uint64_t)*packets * 10000u};
        mw_packet_builder b;
        mw_stamped_frame f = {0u, {0u, 0u, {0u}}};
        const mw_sync sync = {*packets};
        if (mw_packet_builder_begin(&b, stream + len, sizeof stream - len, &h) != MW_OK ||
            mw_sync_encode(&sync, &f.frame) != MW_OK || mw_packet_builder_add(&b, &f) != MW_OK) {
            return 0;
        }
        for (uint8_t node = 1; node <= 17; ++node) {
            for (unsigned k = 0; k < 3; ++k) {
                const mw_raw r = {(mw_function)(MW_FN_ACCEL + k), node, {1, -2, 2048}, (uint16_t)*packets};
                f.offset_us = (uint16_t)(node * 50u);
                if (mw_raw_encode(&r, &f.frame) != MW_OK || mw_packet_builder_add(&b, &f) != MW_OK) return 0;
            }
        }
        const int32_t n = mw_packet_builder_finish(&b);
        if (n <= 0) return 0;
        len += (size_t)n;
        ++*packets;
    }
    return len;
}

int main(void) {
    unsigned packets = 0;
    const size_t len = build_stream(&packets);
    if (len == 0) return 1;
    mw_stream_decoder_init(&decoder);
    const unsigned reps = 100;
    unsigned long frames = 0;
    const double t0 = now_s();
    for (unsigned r = 0; r < reps; ++r) {
        for (size_t pos = 0; pos < len;) {
            size_t left = len - pos < 1460u ? len - pos : 1460u;
            const uint8_t* p = stream + pos;
            pos += left;
            for (;;) {
                size_t used = 0;
                const mw_stream_result res = mw_stream_decoder_feed(&decoder, p, left, &used, &packet);
                p += used;
                left -= used;
                if (res == MW_STREAM_NEED_MORE) break;
                for (unsigned i = 0; res == MW_STREAM_PACKET && i < packet.frame_count; ++i) {
                    mw_message m;
                    if (mw_can_decode(&packet.frames[i].frame, &m) == MW_OK) ++frames;
                }
            }
        }
    }
    const double dt = now_s() - t0;
    const double bytes = (double)len * reps;
    printf("{\"bytes\": %.0f, \"packets\": %u, \"frames\": %lu, \"seconds\": %.3f, ", bytes, packets * reps, frames,
           dt);
    printf("\"mb_per_s\": %.1f, \"mframes_per_s\": %.2f, \"malformed\": %llu}\n", bytes / dt / 1e6,
           (double)frames / dt / 1e6, (unsigned long long)decoder.counters.malformed_packets);
    const unsigned long expected = (unsigned long)packets * 52ul * reps;
    return decoder.counters.malformed_packets == 0 && frames == expected ? 0 : 1;
}
