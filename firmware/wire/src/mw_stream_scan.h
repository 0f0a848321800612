/*
 * mw_stream_scan.h — private: the resynchronising scan shared by the stream decoders
 * (sink -> host packets in mw_packet.c, host -> sink keepalives in mw_keepalive.c).
 *
 * A decoder owns a bounded buffer that always starts at a (possibly partial) magic, or is
 * empty. The scan skips bytes that cannot start a magic (counted as discarded), fills the
 * buffer up to the candidate's length, asks the decoder to judge the whole candidate, and on
 * a rejection drops only the candidate's first byte, so a frame behind a false magic is still
 * found. Both decoders therefore keep the same contract:
 *   counters.bytes_in == bytes of returned frames + counters.bytes_discarded + buffered.
 */
#ifndef MOCAP_WIRE_MW_STREAM_SCAN_H
#define MOCAP_WIRE_MW_STREAM_SCAN_H

#include <stddef.h>
#include <stdint.h>

#include "mocap_wire/mw_packet.h"

/* Length of the candidate at the front of buf[0..len): MW_OK and *need (the bytes the scan
 * must buffer before judging again; may grow once a header is in), or a negative mw_error
 * that rejects the candidate. */
typedef int (*mw_scan_need_fn)(const uint8_t* buf, size_t len, size_t* need);

/* Judges a whole candidate buf[0..need): MW_OK (and fills out), or a negative mw_error. */
typedef int (*mw_scan_judge_fn)(const uint8_t* buf, size_t need, void* out);

/* The decoder's state, borrowed for one feed. */
typedef struct mw_stream_scan {
    const uint8_t* magic; /* 4 bytes */
    uint8_t* buf;
    size_t* len;
    mw_stream_counters* counters;
    int* last_error;
    mw_scan_need_fn need;
    mw_scan_judge_fn judge;
} mw_stream_scan;

/* One feed of data[0..len): returns at most one event and sets *consumed, as documented for
 * mw_stream_decoder_feed (mw_packet.h). */
mw_stream_result mw_stream_scan_feed(const mw_stream_scan* scan, const uint8_t* data, size_t len, size_t* consumed,
                                     void* out);

#endif
