/*
 * mw_packet.h — the sink -> host TCP stream: framed, versioned packets of CAN frames.
 *
 * Packet (all fields little-endian, written byte by byte; docs/protocol.md has examples):
 *
 *   offset size  field
 *   0      4     magic 'M' 'C' 'A' 'P' (0x4D 0x43 0x41 0x50)
 *   4      1     version = MW_PACKET_VERSION (1)
 *   5      1     sink_id
 *   6      2     frame_count, 0..MW_PACKET_MAX_FRAMES
 *   8      2     payload_length: bytes of frame records that follow the header
 *   10     4     sequence: per-connection packet counter, +1 per packet, wraps at 2^32
 *   14     8     timestamp_us: sink clock (microseconds) at which the batch started
 *   22     ...   frame_count records, each 5 + dlc bytes:
 *                  uint16 id (bits 0..10; bits 11..15 zero), uint8 dlc (0..8),
 *                  uint16 offset_us (reception time - timestamp_us), dlc data bytes
 *   22+L   4     CRC-32 (mw_crc32.h) over bytes 0 .. 22+L-1 (magic included)
 *
 * Encoding: mw_packet_encode() for a ready array of frames, or the mw_packet_builder for a sink
 * that appends frames as they arrive and finishes when the batch closes.
 * Decoding: mw_stream_decoder, incremental over a byte stream (see below).
 */
#ifndef MOCAP_WIRE_MW_PACKET_H
#define MOCAP_WIRE_MW_PACKET_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "mocap_wire/mw_can.h"
#include "mocap_wire/mw_common.h"

#ifdef __cplusplus
extern "C" {
#endif

#define MW_PACKET_MAGIC0 0x4Du /* 'M' */
#define MW_PACKET_MAGIC1 0x43u /* 'C' */
#define MW_PACKET_MAGIC2 0x41u /* 'A' */
#define MW_PACKET_MAGIC3 0x50u /* 'P' */
#define MW_PACKET_HEADER_SIZE 22u
#define MW_PACKET_CRC_SIZE 4u
#define MW_PACKET_RECORD_MIN 5u  /**< record with dlc 0 */
#define MW_PACKET_RECORD_MAX 13u /**< record with dlc 8 */
/** Most frames one packet may carry (63 nodes x 4 frames + SYNC + STATUS fit with room). */
#define MW_PACKET_MAX_FRAMES 512u
/** Largest packet on the wire: 22 + 512 * 13 + 4 = 6682 bytes. */
#define MW_PACKET_MAX_SIZE (MW_PACKET_HEADER_SIZE + MW_PACKET_MAX_FRAMES * MW_PACKET_RECORD_MAX + MW_PACKET_CRC_SIZE)

/** Header fields a sink chooses (magic, version, count and length are implied). */
typedef struct mw_packet_header {
    uint8_t sink_id;
    uint32_t sequence;
    uint64_t timestamp_us;
} mw_packet_header;

/** A CAN frame with its reception time relative to the packet's timestamp_us. */
typedef struct mw_stamped_frame {
    uint16_t offset_us;
    mw_can_frame frame;
} mw_stamped_frame;

/** A decoded packet. Large (about 7 KiB): allocate it once, not on a small stack. */
typedef struct mw_packet {
    mw_packet_header header;
    uint16_t frame_count;
    mw_stamped_frame frames[MW_PACKET_MAX_FRAMES];
} mw_packet;

/** Bytes a packet holding these frames takes on the wire (no validation of the frames). */
size_t mw_packet_size(const mw_stamped_frame* frames, size_t count);

/**
 * Writes one whole packet into out[0..capacity). Returns the number of bytes written (> 0), or
 * MW_ERR_ARGUMENT (NULL), MW_ERR_LENGTH (count > MW_PACKET_MAX_FRAMES), MW_ERR_RECORD (a frame
 * with id > 0x7FF or dlc > 8), MW_ERR_SPACE (capacity too small). O(bytes).
 */
int32_t mw_packet_encode(const mw_packet_header* header, const mw_stamped_frame* frames, size_t count, uint8_t* out,
                         size_t capacity);

/**
 * Incremental packet writer for the sink. The builder borrows `buf` from begin() until finish()
 * (the caller must keep it alive and must not write to it meanwhile). Not thread-safe.
 */
typedef struct mw_packet_builder {
    uint8_t* buf;         /* private */
    size_t capacity;      /* private */
    size_t len;           /* bytes written so far (header + records) */
    uint16_t frame_count; /* records added so far */
} mw_packet_builder;

/** Starts a packet in buf. MW_ERR_SPACE if capacity < MW_PACKET_HEADER_SIZE + MW_PACKET_CRC_SIZE.
 */
int mw_packet_builder_begin(mw_packet_builder* builder, uint8_t* buf, size_t capacity, const mw_packet_header* header);

/**
 * Appends one frame record. MW_ERR_RECORD for a bad frame (id > 0x7FF, dlc > 8), MW_ERR_SPACE if
 * the record plus the CRC would not fit or the packet already has MW_PACKET_MAX_FRAMES frames;
 * on error the packet is unchanged and can still be finished. O(dlc).
 */
int mw_packet_builder_add(mw_packet_builder* builder, const mw_stamped_frame* frame);

/** Writes count, length and CRC; returns the packet length in bytes (> 0) or MW_ERR_ARGUMENT.
 * O(bytes). */
int32_t mw_packet_builder_finish(mw_packet_builder* builder);

/** Result of one mw_stream_decoder_feed() call. */
typedef enum mw_stream_result {
    MW_STREAM_NEED_MORE = 0, /**< all input consumed, no complete packet buffered */
    MW_STREAM_PACKET = 1,    /**< *out holds a valid packet */
    MW_STREAM_MALFORMED = -1 /**< a candidate packet was rejected (see last_error); keep feeding */
} mw_stream_result;

/** Counters only go up (they wrap at 2^64). */
typedef struct mw_stream_counters {
    uint64_t bytes_in;          /**< every byte consumed by feed */
    uint64_t bytes_discarded;   /**< bytes that were not part of a valid packet */
    uint64_t packets;           /**< valid packets returned */
    uint64_t malformed_packets; /**< MW_STREAM_MALFORMED results (CRC failures included) */
    uint64_t crc_failures;      /**< of which the CRC did not match */
} mw_stream_counters;

/**
 * Incremental decoder over a byte stream (one per TCP connection). Caller-allocated
 * (about 6.7 KiB); holds at most MW_PACKET_MAX_SIZE bytes of the stream. Not thread-safe.
 * Invariant: counters.bytes_in == bytes of returned packets + counters.bytes_discarded + buffered.
 */
typedef struct mw_stream_decoder {
    mw_stream_counters counters;
    int last_error;                  /**< mw_error of the last MW_STREAM_MALFORMED (MW_OK before) */
    size_t len;                      /* private: bytes buffered */
    uint8_t buf[MW_PACKET_MAX_SIZE]; /* private */
} mw_stream_decoder;

void mw_stream_decoder_init(mw_stream_decoder* decoder);

/** Bytes currently buffered (a partial packet, or a partial magic). */
size_t mw_stream_decoder_buffered(const mw_stream_decoder* decoder);

/**
 * Feeds bytes data[0..len) and returns at most one event; *consumed is set to the number of
 * input bytes taken (never more than len; data is never read beyond len). Call it in a loop
 * until it returns MW_STREAM_NEED_MORE, advancing data by *consumed each time:
 *
 *     for (;;) {
 *         size_t used = 0;
 *         mw_stream_result r = mw_stream_decoder_feed(&dec, p, n, &used, &pkt);
 *         p += used; n -= used;
 *         if (r == MW_STREAM_NEED_MORE) break;      // n is now 0
 *         if (r == MW_STREAM_PACKET) handle(&pkt);
 *         else count_and_log(dec.last_error);       // decoder already resynchronised
 *     }
 *
 * Bytes before a magic are discarded (counted). A header with a wrong version, a frame count
 * above MW_PACKET_MAX_FRAMES or an impossible payload length is rejected as soon as the 22
 * header bytes are in; a CRC mismatch or a bad record when the whole packet is in. After a
 * rejection the decoder drops the first byte of the candidate and rescans the buffered bytes
 * for the next magic, so a packet hidden behind a false magic is still found.
 * MW_STREAM_MALFORMED may come with *consumed == 0 (the bytes were buffered by an earlier call).
 * `data` may be NULL when len is 0. `out` is written only when MW_STREAM_PACKET is returned.
 * Cost: O(consumed + buffered) per call; no allocation.
 */
mw_stream_result mw_stream_decoder_feed(mw_stream_decoder* decoder, const uint8_t* data, size_t len, size_t* consumed,
                                        mw_packet* out);

#ifdef __cplusplus
}
#endif

#endif /* MOCAP_WIRE_MW_PACKET_H */
