/*
 * mw_keepalive.c — host -> sink keepalive frames and their incremental decoder.
 *
 * The frame has a fixed size, so the decoder needs no header stage: it keeps at most one
 * candidate (16 bytes) and judges it whole. The scan is the packet decoder's
 * (mw_stream_scan.c), so a sink's host -> sink parsing behaves like the host's sink -> host
 * parsing.
 */
#include "mocap_wire/mw_keepalive.h"

#include <string.h>

#include "mocap_wire/mw_crc32.h"
#include "mw_endian.h"
#include "mw_stream_scan.h"

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

/* mw_scan_need_fn: a keepalive has a fixed size, so there is no header stage. */
static int keepalive_need(const uint8_t* buf, size_t len, size_t* need) {
    (void)buf;
    (void)len;
    *need = MW_KEEPALIVE_SIZE;
    return MW_OK;
}

/* mw_scan_judge_fn */
static int keepalive_judge(const uint8_t* buf, size_t need, void* out) {
    return mw_keepalive_decode(buf, need, (mw_keepalive*)out);
}

mw_stream_result mw_keepalive_decoder_feed(mw_keepalive_decoder* d, const uint8_t* data, size_t len, size_t* consumed,
                                           mw_keepalive* out) {
    if (d == NULL || consumed == NULL || out == NULL || (data == NULL && len > 0u)) {
        if (consumed != NULL) *consumed = 0;
        return MW_STREAM_NEED_MORE;
    }
    const mw_stream_scan scan = {ka_magic,       d->buf,         &d->len,        &d->counters,
                                 &d->last_error, keepalive_need, keepalive_judge};
    return mw_stream_scan_feed(&scan, data, len, consumed, out);
}
