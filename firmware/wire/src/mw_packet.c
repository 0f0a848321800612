/*
 * mw_packet.c — sink -> host packets: builder, one-shot encoder, incremental stream decoder.
 *
 * The decoder keeps the candidate packet in its own bounded buffer rather than parsing in
 * place, so the caller may hand it any chunking of the stream and reuse its read buffer at
 * once. It buffers at most one maximum-size packet; a header is judged as soon as its 22 bytes
 * are in, so a false magic in garbage costs at most one packet's worth of buffering.
 */
#include "mocap_wire/mw_packet.h"

#include <string.h>

#include "mocap_wire/mw_crc32.h"
#include "mw_endian.h"
#include "mw_stream_scan.h"

static const uint8_t mw_magic[4] = {MW_PACKET_MAGIC0, MW_PACKET_MAGIC1, MW_PACKET_MAGIC2, MW_PACKET_MAGIC3};

/* Header field offsets. */
enum { OFF_VERSION = 4, OFF_SINK_ID = 5, OFF_COUNT = 6, OFF_PAYLOAD_LEN = 8, OFF_SEQUENCE = 10, OFF_TIMESTAMP = 14 };

static bool frame_recordable(const mw_can_frame* f) {
    return f->id <= MW_CAN_ID_MAX && f->dlc <= MW_CAN_DLC_MAX;
}

size_t mw_packet_size(const mw_stamped_frame* frames, size_t count) {
    size_t size = MW_PACKET_HEADER_SIZE + MW_PACKET_CRC_SIZE;
    for (size_t i = 0; frames != NULL && i < count; ++i) {
        const uint8_t dlc = frames[i].frame.dlc;
        size += MW_PACKET_RECORD_MIN + (dlc > MW_CAN_DLC_MAX ? MW_CAN_DLC_MAX : dlc);
    }
    return size;
}

/* ---------------------------------------------------------------- builder */

int mw_packet_builder_begin(mw_packet_builder* builder, uint8_t* buf, size_t capacity, const mw_packet_header* header) {
    if (builder == NULL || buf == NULL || header == NULL) return MW_ERR_ARGUMENT;
    if (capacity < MW_PACKET_HEADER_SIZE + MW_PACKET_CRC_SIZE) return MW_ERR_SPACE;
    memcpy(buf, mw_magic, sizeof mw_magic);
    buf[OFF_VERSION] = (uint8_t)MW_PACKET_VERSION;
    buf[OFF_SINK_ID] = header->sink_id;
    mw_put_u16(buf + OFF_COUNT, 0u);
    mw_put_u16(buf + OFF_PAYLOAD_LEN, 0u);
    mw_put_u32(buf + OFF_SEQUENCE, header->sequence);
    mw_put_u64(buf + OFF_TIMESTAMP, header->timestamp_us);
    builder->buf = buf;
    builder->capacity = capacity;
    builder->len = MW_PACKET_HEADER_SIZE;
    builder->frame_count = 0u;
    return MW_OK;
}

int mw_packet_builder_add(mw_packet_builder* builder, const mw_stamped_frame* frame) {
    if (builder == NULL || builder->buf == NULL || frame == NULL) return MW_ERR_ARGUMENT;
    if (!frame_recordable(&frame->frame)) return MW_ERR_RECORD;
    const size_t record = MW_PACKET_RECORD_MIN + frame->frame.dlc;
    if (builder->frame_count >= MW_PACKET_MAX_FRAMES ||
        builder->len + record + MW_PACKET_CRC_SIZE > builder->capacity) {
        return MW_ERR_SPACE;
    }
    uint8_t* p = builder->buf + builder->len;
    mw_put_u16(p, frame->frame.id);
    p[2] = frame->frame.dlc;
    mw_put_u16(p + 3, frame->offset_us);
    memcpy(p + MW_PACKET_RECORD_MIN, frame->frame.data, frame->frame.dlc);
    builder->len += record;
    builder->frame_count++;
    return MW_OK;
}

int32_t mw_packet_builder_finish(mw_packet_builder* builder) {
    if (builder == NULL || builder->buf == NULL) return MW_ERR_ARGUMENT;
    uint8_t* buf = builder->buf;
    mw_put_u16(buf + OFF_COUNT, builder->frame_count);
    mw_put_u16(buf + OFF_PAYLOAD_LEN, (uint16_t)(builder->len - MW_PACKET_HEADER_SIZE));
    mw_put_u32(buf + builder->len, mw_crc32(buf, builder->len));
    const size_t total = builder->len + MW_PACKET_CRC_SIZE;
    builder->buf = NULL; /* a finished builder refuses further frames */
    return (int32_t)total;
}

int32_t mw_packet_encode(const mw_packet_header* header, const mw_stamped_frame* frames, size_t count, uint8_t* out,
                         size_t capacity) {
    if (header == NULL || out == NULL || (frames == NULL && count > 0u)) return MW_ERR_ARGUMENT;
    if (count > MW_PACKET_MAX_FRAMES) return MW_ERR_LENGTH;
    for (size_t i = 0; i < count; ++i) {
        if (!frame_recordable(&frames[i].frame)) return MW_ERR_RECORD;
    }
    if (mw_packet_size(frames, count) > capacity) return MW_ERR_SPACE;
    mw_packet_builder b;
    int rc = mw_packet_builder_begin(&b, out, capacity, header);
    for (size_t i = 0; rc == MW_OK && i < count; ++i)
        rc = mw_packet_builder_add(&b, &frames[i]);
    return rc == MW_OK ? mw_packet_builder_finish(&b) : rc;
}

/* ---------------------------------------------------------------- stream decoder */

void mw_stream_decoder_init(mw_stream_decoder* decoder) {
    if (decoder == NULL) return;
    memset(&decoder->counters, 0, sizeof decoder->counters);
    decoder->last_error = MW_OK;
    decoder->len = 0u;
}

size_t mw_stream_decoder_buffered(const mw_stream_decoder* decoder) {
    return decoder == NULL ? 0u : decoder->len;
}

/* Checks the 22 header bytes at the front; on success stores the whole packet length. */
static int check_header(const uint8_t* h, size_t* packet_len) {
    if (h[OFF_VERSION] != MW_PACKET_VERSION) return MW_ERR_VERSION;
    const uint32_t count = mw_get_u16(h + OFF_COUNT);
    const uint32_t payload = mw_get_u16(h + OFF_PAYLOAD_LEN);
    if (count > MW_PACKET_MAX_FRAMES || payload < count * MW_PACKET_RECORD_MIN ||
        payload > count * MW_PACKET_RECORD_MAX) {
        return MW_ERR_LENGTH;
    }
    *packet_len = MW_PACKET_HEADER_SIZE + payload + MW_PACKET_CRC_SIZE;
    return MW_OK;
}

/* Walks the records of a CRC-checked packet; fills `out` only if `out` is not NULL. */
static int parse_records(const uint8_t* pkt, size_t packet_len, mw_packet* out) {
    const uint16_t count = mw_get_u16(pkt + OFF_COUNT);
    const size_t end = packet_len - MW_PACKET_CRC_SIZE;
    size_t pos = MW_PACKET_HEADER_SIZE;
    for (uint16_t i = 0; i < count; ++i) {
        if (pos + MW_PACKET_RECORD_MIN > end) return MW_ERR_RECORD;
        const uint16_t id = mw_get_u16(pkt + pos);
        const uint8_t dlc = pkt[pos + 2];
        if (id > MW_CAN_ID_MAX || dlc > MW_CAN_DLC_MAX || pos + MW_PACKET_RECORD_MIN + dlc > end) {
            return MW_ERR_RECORD;
        }
        if (out != NULL) {
            mw_stamped_frame* f = &out->frames[i];
            f->offset_us = mw_get_u16(pkt + pos + 3);
            f->frame.id = id;
            f->frame.dlc = dlc;
            memset(f->frame.data, 0, sizeof f->frame.data);
            memcpy(f->frame.data, pkt + pos + MW_PACKET_RECORD_MIN, dlc);
        }
        pos += MW_PACKET_RECORD_MIN + dlc;
    }
    if (pos != end) return MW_ERR_RECORD;
    if (out != NULL) {
        out->header.sink_id = pkt[OFF_SINK_ID];
        out->header.sequence = mw_get_u32(pkt + OFF_SEQUENCE);
        out->header.timestamp_us = mw_get_u64(pkt + OFF_TIMESTAMP);
        out->frame_count = count;
    }
    return MW_OK;
}

/* mw_scan_need_fn: a header is judged as soon as its bytes are in. */
static int packet_need(const uint8_t* buf, size_t len, size_t* need) {
    *need = MW_PACKET_HEADER_SIZE;
    return len < MW_PACKET_HEADER_SIZE ? MW_OK : check_header(buf, need);
}

/* mw_scan_judge_fn: CRC, then every record, before `out` is touched. */
static int packet_judge(const uint8_t* buf, size_t need, void* out) {
    const uint32_t crc = mw_get_u32(buf + need - MW_PACKET_CRC_SIZE);
    if (mw_crc32(buf, need - MW_PACKET_CRC_SIZE) != crc) return MW_ERR_CRC;
    const int rc = parse_records(buf, need, NULL);
    if (rc != MW_OK) return rc;
    return parse_records(buf, need, (mw_packet*)out);
}

mw_stream_result mw_stream_decoder_feed(mw_stream_decoder* d, const uint8_t* data, size_t len, size_t* consumed,
                                        mw_packet* out) {
    if (d == NULL || consumed == NULL || out == NULL || (data == NULL && len > 0u)) {
        if (consumed != NULL) *consumed = 0;
        return MW_STREAM_NEED_MORE;
    }
    const mw_stream_scan scan = {mw_magic, d->buf, &d->len, &d->counters, &d->last_error, packet_need, packet_judge};
    return mw_stream_scan_feed(&scan, data, len, consumed, out);
}
