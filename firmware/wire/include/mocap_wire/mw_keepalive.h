/*
 * mw_keepalive.h — the host -> sink direction of the TCP stream: a small keepalive frame the
 * host sends at a fixed period, so that a sink notices a host that died silently (power
 * loss, cable, a frozen process) instead of writing into a connection nobody reads.
 *
 * Keepalive (16 bytes, little-endian; docs/protocol.md §3.5):
 *
 *   offset size  field
 *   0      4     magic 'M' 'C' 'K' 'A' (0x4D 0x43 0x4B 0x41)
 *   4      1     version = MW_STREAM_VERSION (2): the host speaks stream version 2
 *   5      1     flags: reserved, sent as 0, ignored by receivers
 *   6      2     period_ms: the host's keepalive period, 1..65535 (0 rejected)
 *   8      4     sequence: per connection, 0 for the first keepalive, +1 each, wraps
 *   12     4     CRC-32 (mw_crc32.h) over bytes 0..11
 *
 * Compatibility: the sink -> host packet is unchanged (its version byte stays 1), so a host
 * of either version accepts a sink of either version. A version-1 sink never reads the
 * connection (the host's writes are bounded, so that costs the host nothing); a version-2
 * sink supervises keepalives only once it has received one, so a version-1 host, which
 * sends none, is never taken for dead.
 */
#ifndef MOCAP_WIRE_MW_KEEPALIVE_H
#define MOCAP_WIRE_MW_KEEPALIVE_H

#include <stddef.h>
#include <stdint.h>

#include "mocap_wire/mw_common.h"
#include "mocap_wire/mw_packet.h"

#ifdef __cplusplus
extern "C" {
#endif

#define MW_KEEPALIVE_MAGIC0 0x4Du /* 'M' */
#define MW_KEEPALIVE_MAGIC1 0x43u /* 'C' */
#define MW_KEEPALIVE_MAGIC2 0x4Bu /* 'K' */
#define MW_KEEPALIVE_MAGIC3 0x41u /* 'A' */
#define MW_KEEPALIVE_SIZE 16u

typedef struct mw_keepalive {
    uint16_t period_ms; /* 1..65535 */
    uint32_t sequence;
} mw_keepalive;

/* Writes the 16 bytes into out[0..capacity). Returns MW_KEEPALIVE_SIZE, or MW_ERR_ARGUMENT
 * (NULL), MW_ERR_RANGE (period_ms 0), MW_ERR_SPACE (capacity < 16); out is untouched on error. */
int32_t mw_keepalive_encode(const mw_keepalive* keepalive, uint8_t* out, size_t capacity);

/* Decodes exactly one keepalive from data[0..len). MW_OK, or MW_ERR_ARGUMENT (NULL),
 * MW_ERR_LENGTH (len != 16 or a wrong magic), MW_ERR_VERSION, MW_ERR_CRC, MW_ERR_RANGE
 * (period_ms 0). *out is written only on MW_OK. */
int mw_keepalive_decode(const uint8_t* data, size_t len, mw_keepalive* out);

/* Incremental decoder over the host -> sink byte stream (one per connection). 16 bytes of
 * buffer, no allocation; same contract as mw_stream_decoder (mw_packet.h): bytes before a
 * magic are discarded and counted, a rejected candidate loses its first byte and the rest is
 * rescanned, and counters.bytes_in == 16 * keepalives + bytes_discarded + buffered. In the
 * counters, `packets` counts keepalives. Not thread-safe. */
typedef struct mw_keepalive_decoder {
    mw_stream_counters counters;
    int last_error; /* mw_error of the last MW_STREAM_MALFORMED (MW_OK before) */
    size_t len;     /* private: bytes buffered */
    uint8_t buf[MW_KEEPALIVE_SIZE];
} mw_keepalive_decoder;

void mw_keepalive_decoder_init(mw_keepalive_decoder* decoder);

/* Feeds data[0..len); returns at most one event and sets *consumed, exactly like
 * mw_stream_decoder_feed (call it in a loop until MW_STREAM_NEED_MORE). `out` is written only
 * when MW_STREAM_PACKET is returned. O(consumed + 16) per call. */
mw_stream_result mw_keepalive_decoder_feed(mw_keepalive_decoder* decoder, const uint8_t* data, size_t len,
                                           size_t* consumed, mw_keepalive* out);

#ifdef __cplusplus
}
#endif

#endif /* MOCAP_WIRE_MW_KEEPALIVE_H */
