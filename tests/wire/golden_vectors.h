/*
 * golden_vectors.h — the exact bytes of docs/protocol.md, shared by the GoogleTest suite and by
 * the plain-C self-test (which also runs as a 32-bit build). The data lives in
 * golden_vectors.c so that it is compiled as C99 in both.
 */
#ifndef MOCAP_TESTS_WIRE_GOLDEN_VECTORS_H
#define MOCAP_TESTS_WIRE_GOLDEN_VECTORS_H

#include <stddef.h>
#include <stdint.h>

#include "mocap_wire/mocap_wire.h"

#ifdef __cplusplus
extern "C" {
#endif

/** One CAN message and the frame it must encode to. */
typedef struct golden_can {
    const char* name; /**< as written in docs/protocol.md */
    mw_message message;
    mw_can_frame frame;
} golden_can;

/** One packet: the frames it carries and its exact bytes. */
typedef struct golden_packet {
    const char* name;
    mw_packet_header header;
    const mw_stamped_frame* frames;
    size_t frame_count;
    const uint8_t* bytes;
    size_t size;
} golden_packet;

extern const golden_can golden_can_vectors[];
extern const size_t golden_can_count;
extern const golden_packet golden_packets[];
extern const size_t golden_packet_count;

/**
 * Formats a frame as docs/protocol.md writes it: "<name>: id=0x083 dlc=8 data=64 00 ..".
 * Returns the length written (buffer of at least 128 bytes).
 */
size_t golden_format_can(const char* name, const mw_can_frame* frame, char* out, size_t capacity);

/** Formats bytes as upper-case hex pairs separated by spaces (3 * n bytes of buffer). */
size_t golden_format_hex(const uint8_t* bytes, size_t n, char* out, size_t capacity);

#ifdef __cplusplus
}
#endif

#endif /* MOCAP_TESTS_WIRE_GOLDEN_VECTORS_H */
