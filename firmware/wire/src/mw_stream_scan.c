/*
 * mw_stream_scan.c — the resynchronising scan shared by the stream decoders (see the header).
 */
#include "mw_stream_scan.h"

#include <string.h>

enum { MAGIC_SIZE = 4 };

/* First index where a magic, or a prefix of one cut by the end of the data, starts; n if none. */
static size_t find_magic(const uint8_t* magic, const uint8_t* p, size_t n) {
    for (size_t i = 0; i < n; ++i) {
        if (p[i] != magic[0]) continue;
        const size_t m = n - i < MAGIC_SIZE ? n - i : MAGIC_SIZE;
        if (memcmp(p + i, magic, m) == 0) return i;
    }
    return n;
}

static void drop_front(const mw_stream_scan* s, size_t n) {
    memmove(s->buf, s->buf + n, *s->len - n);
    *s->len -= n;
}

static void discard_front(const mw_stream_scan* s, size_t n) {
    drop_front(s, n);
    s->counters->bytes_discarded += n;
}

/* Rejects the candidate at the front: drop its first byte so the rescan finds the next magic. */
static mw_stream_result reject(const mw_stream_scan* s, int error) {
    discard_front(s, 1u);
    s->counters->malformed_packets++;
    if (error == MW_ERR_CRC) s->counters->crc_failures++;
    *s->last_error = error;
    return MW_STREAM_MALFORMED;
}

mw_stream_result mw_stream_scan_feed(const mw_stream_scan* s, const uint8_t* data, size_t len, size_t* consumed,
                                     void* out) {
    size_t used = 0;
    mw_stream_result result = MW_STREAM_NEED_MORE;
    for (;;) {
        /* The buffer always starts at a (possibly partial) magic, or is empty. */
        const size_t skip = find_magic(s->magic, s->buf, *s->len);
        if (skip > 0u) discard_front(s, skip);

        size_t need = 0;
        const int header = s->need(s->buf, *s->len, &need);
        if (header != MW_OK) {
            result = reject(s, header);
            break;
        }
        if (*s->len < need) {
            if (used == len) break; /* NEED_MORE */
            if (*s->len == 0u) {
                /* Fast path over garbage: skip input bytes that cannot start a magic. */
                const size_t garbage = find_magic(s->magic, data + used, len - used);
                used += garbage;
                s->counters->bytes_discarded += garbage;
                if (used == len) break;
            }
            size_t n = need - *s->len;
            if (n > len - used) n = len - used;
            memcpy(s->buf + *s->len, data + used, n);
            *s->len += n;
            used += n;
            continue;
        }
        /* A whole candidate is buffered at the front (maybe followed by more bytes). */
        const int rc = s->judge(s->buf, need, out);
        if (rc != MW_OK) {
            result = reject(s, rc);
            break;
        }
        drop_front(s, need);
        s->counters->packets++;
        result = MW_STREAM_PACKET;
        break;
    }
    s->counters->bytes_in += used;
    *consumed = used;
    return result;
}
