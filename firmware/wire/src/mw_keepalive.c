/*
 * mw_keepalive.c — host -> sink keepalive frames and their incremental decoder.
 *
 * The frame has a fixed size, so the decoder needs no header stage: it keeps at most one
 * candidate (16 bytes) and judges it whole. The resynchronisation rule is the packet
 * decoder's, so a sink's host -> sink parsing behaves like the host's sink -> host parsing.
 */
#include "mocap_wire/mw_keepalive.h"

#include <string.h>

#include "mocap_wire/mw_crc32.h"
#include "mw_endian.h"

static const uint8_t ka_magic[4] = {MW_KEEPALIVE_MAGIC0, MW_KEEPALIVE_MAGIC1, MW_KEEPALIVE_MAGIC2, MW_KEEPALIVE_MAGIC3};

enum { OFF_VERSION = 4, OFF_FLAGS = 5, OFF_PERIOD = 6, OFF_SEQUENCE = 8, OFF_CRC = 12 };

int32_t mw_keepalive_encode(const mw_keepalive* keepalive, uint8_t* out, size_t capacity) {
    if (keepalive == NULL || out == NULL) return MW_ERR_ARGUMENT;
    if (keepalive->period_ms == 0u) return MW_ERR_RANGE;
    if (capacity < MW_KEEPALIVE_SIZE) return MW_ERR_SPACE;
    memcpy(out, ka_magic, sizeof ka_magic);
    out[OFF_VERSION] = (uint8_t)MW_STREAM_VERSION;
    out[OFF_FLAGS] = 0u;
    mw_put_u16(out + OFF_PERIOD, keepalive->period_ms);
    mw_put_u32(out + OFF_SEQUENCE, keepalive->sequence);
    mw_put_u32(out + OFF_CRC, mw_crc32(out, OFF_CRC));
    return (int32_t)MW_KEEPALIVE_SIZE;
}

int mw_keepalive_decode(const uint8_t* data, size_t len, mw_keepalive* out) {
    if (data == NULL || out == NULL) return MW_ERR_ARGUMENT;
    if (len != MW_KEEPALIVE_SIZE || memcmp(data, ka_magic, sizeof ka_magic) != 0) return MW_ERR_LENGTH;
    if (data[OFF_VERSION] != MW_STREAM_VERSION) return MW_ERR_VERSION;
    if (mw_crc32(data, OFF_CRC) != mw_get_u32(data + OFF_CRC)) return MW_ERR_CRC;
    const uint16_t period = mw_get_u16(data + OFF_PERIOD);
    if (period == 0u) return MW_ERR_RANGE;
    /* data[OFF_FLAGS] is reserved: ignored, so a later version can use it compatibly. */
    out->period_ms = period;
    out->sequence = mw_get_u32(data + OFF_SEQUENCE);
    return MW_OK;
}

void mw_keepalive_decoder_init(mw_keepalive_decoder* decoder) {
    if (decoder == NULL) return;
    memset(&decoder->counters, 0, sizeof decoder->counters);
    decoder->last_error = MW_OK;
    decoder->len = 0u;
}

/* First index where a magic, or a prefix of one cut by the end of the data, starts; n if none. */
static size_t find_magic(const uint8_t* p, size_t n) {
    for (size_t i = 0; i < n; ++i) {
        if (p[i] != ka_magic[0]) continue;
        const size_t m = n - i < sizeof ka_magic ? n - i : sizeof ka_magic;
        if (memcmp(p + i, ka_magic, m) == 0) return i;
    }
    return n;
}

static void drop_front(mw_keepalive_decoder* d, size_t n) {
    memmove(d->buf, d->buf + n, d->len - n);
    d->len -= n;
}

mw_stream_result mw_keepalive_decoder_feed(mw_keepalive_decoder* d, const uint8_t* data, size_t len, size_t* consumed,
                                           mw_keepalive* out) {
    size_t used = 0;
    mw_stream_result result = MW_STREAM_NEED_MORE;
    if (d == NULL || consumed == NULL || out == NULL || (data == NULL && len > 0u)) {
        if (consumed != NULL) *consumed = 0;
        return MW_STREAM_NEED_MORE;
    }
    for (;;) {
        /* The buffer always starts at a (possibly partial) magic, or is empty. */
        const size_t skip = find_magic(d->buf, d->len);
        if (skip > 0u) {
            drop_front(d, skip);
            d->counters.bytes_discarded += skip;
        }
        if (d->len < MW_KEEPALIVE_SIZE) {
            if (used == len) break; /* NEED_MORE */
            if (d->len == 0u) {
                const size_t garbage = find_magic(data + used, len - used);
                used += garbage;
                d->counters.bytes_discarded += garbage;
                if (used == len) break;
            }
            size_t n = MW_KEEPALIVE_SIZE - d->len;
            if (n > len - used) n = len - used;
            memcpy(d->buf + d->len, data + used, n);
            d->len += n;
            used += n;
            continue;
        }
        const int rc = mw_keepalive_decode(d->buf, MW_KEEPALIVE_SIZE, out);
        if (rc != MW_OK) {
            /* Drop the candidate's first byte: a keepalive behind a false magic is still found. */
            drop_front(d, 1u);
            d->counters.bytes_discarded += 1u;
            d->counters.malformed_packets++;
            if (rc == MW_ERR_CRC) d->counters.crc_failures++;
            d->last_error = rc;
            result = MW_STREAM_MALFORMED;
            break;
        }
        drop_front(d, MW_KEEPALIVE_SIZE);
        d->counters.packets++;
        result = MW_STREAM_PACKET;
        break;
    }
    d->counters.bytes_in += used;
    *consumed = used;
    return result;
}
