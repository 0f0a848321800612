// Fuzz target: the sink -> host stream decoder (firmware/wire mw_stream_decoder_feed), and
// the host -> sink keepalive decoder (mw_keepalive_decoder_feed) on the same chunks.
//
// Input: a sequence of chunks, each one length byte (0..255) followed by that many stream
// bytes, so the fuzzer controls how the TCP stream is split. Each chunk is copied into a
// buffer of exactly its size, so any read past `len` is an AddressSanitizer error.
// After every chunk the decoder's documented invariants must hold:
//   bytes_in == bytes of returned packets + bytes_discarded + buffered,
//   buffered <= MW_PACKET_MAX_SIZE, *consumed <= len, NEED_MORE only with the input used up,
//   every returned packet is well formed (count, ids, dlc) and re-encodes to its own size;
// and for the keepalive decoder: bytes_in == 16 * keepalives + bytes_discarded + buffered,
// buffered <= 16, and every returned keepalive re-encodes to 16 bytes.
#include <cstring>
#include <memory>
#include <vector>

#include "fuzz_target.hpp"
#include "mocap_wire/mw_keepalive.h"
#include "mocap_wire/mw_packet.h"

namespace {

// The keepalive decoder's invariants over one chunk (its contract is the packet decoder's).
void feed_keepalives(mw_keepalive_decoder* d, const std::uint8_t* p, std::size_t left, std::uint64_t* count) {
    const std::size_t max_calls = d->len + left + 2;
    for (std::size_t calls = 0;; ++calls) {
        MOCAP_FUZZ_CHECK(calls < max_calls, "keepalive decoder makes no progress");
        std::size_t used = 0;
        mw_keepalive k{};
        const mw_stream_result r = mw_keepalive_decoder_feed(d, p, left, &used, &k);
        MOCAP_FUZZ_CHECK(used <= left, "keepalive decoder consumed more than given");
        p += used;
        left -= used;
        if (r == MW_STREAM_NEED_MORE) {
            MOCAP_FUZZ_CHECK(left == 0, "keepalive NEED_MORE with input left");
            break;
        }
        if (r == MW_STREAM_PACKET) {
            ++*count;
            std::uint8_t again[MW_KEEPALIVE_SIZE];
            MOCAP_FUZZ_CHECK(mw_keepalive_encode(&k, again, sizeof again) == MW_KEEPALIVE_SIZE,
                             "a decoded keepalive does not re-encode");
        } else {
            MOCAP_FUZZ_CHECK(r == MW_STREAM_MALFORMED && d->last_error < 0, "keepalive MALFORMED without an error");
        }
    }
    const mw_stream_counters& c = d->counters;
    MOCAP_FUZZ_CHECK(d->len <= MW_KEEPALIVE_SIZE, "keepalive buffer bound");
    MOCAP_FUZZ_CHECK(c.bytes_in == *count * MW_KEEPALIVE_SIZE + c.bytes_discarded + d->len,
                     "keepalive bytes_in != keepalives + discarded + buffered");
    MOCAP_FUZZ_CHECK(c.packets == *count, "keepalive counter");
}

}  // namespace

MOCAP_FUZZ_ENTRY(wire_stream) {
    // Large (about 7 KiB each): allocated once, not on the stack.
    static auto* decoder = new mw_stream_decoder;
    static auto* packet = new mw_packet;
    static std::vector<std::uint8_t> reencoded(MW_PACKET_MAX_SIZE);
    static auto* keepalives = new mw_keepalive_decoder;
    mw_stream_decoder_init(decoder);
    mw_keepalive_decoder_init(keepalives);
    std::uint64_t keepalive_count = 0;

    mocap::fuzz::ByteReader in(data, size);
    std::uint64_t packet_bytes = 0;
    std::uint64_t packets = 0;
    while (!in.empty()) {
        std::size_t n = in.u8();
        const std::uint8_t* src = in.take(n);
        const std::unique_ptr<std::uint8_t[]> chunk(n > 0 ? new std::uint8_t[n] : nullptr);
        if (n > 0) std::memcpy(chunk.get(), src, n);

        const std::uint8_t* p = chunk.get();
        std::size_t left = n;
        // Every MALFORMED result drops at least one buffered byte, every PACKET at least a
        // header: the loop ends within buffered + n + 1 calls.
        const std::size_t max_calls = mw_stream_decoder_buffered(decoder) + n + 2;
        for (std::size_t calls = 0;; ++calls) {
            MOCAP_FUZZ_CHECK(calls < max_calls, "decoder makes no progress");
            std::size_t used = 0;
            const mw_stream_result r = mw_stream_decoder_feed(decoder, p, left, &used, packet);
            MOCAP_FUZZ_CHECK(used <= left, "consumed more than given");
            p += used;
            left -= used;
            if (r == MW_STREAM_NEED_MORE) {
                MOCAP_FUZZ_CHECK(left == 0, "NEED_MORE with input left");
                break;
            }
            if (r == MW_STREAM_PACKET) {
                ++packets;
                MOCAP_FUZZ_CHECK(packet->frame_count <= MW_PACKET_MAX_FRAMES, "frame count");
                for (std::size_t i = 0; i < packet->frame_count; ++i) {
                    const mw_can_frame& f = packet->frames[i].frame;
                    MOCAP_FUZZ_CHECK(f.id <= 0x7FF && f.dlc <= 8, "frame id/dlc out of range");
                }
                const std::size_t bytes = mw_packet_size(packet->frames, packet->frame_count);
                packet_bytes += bytes;
                const std::int32_t written = mw_packet_encode(&packet->header, packet->frames, packet->frame_count,
                                                              reencoded.data(), reencoded.size());
                MOCAP_FUZZ_CHECK(written > 0 && static_cast<std::size_t>(written) == bytes,
                                 "a decoded packet does not re-encode to its size");
            } else {
                MOCAP_FUZZ_CHECK(r == MW_STREAM_MALFORMED, "unknown result");
                MOCAP_FUZZ_CHECK(decoder->last_error < 0, "MALFORMED without an error code");
            }
        }
        feed_keepalives(keepalives, chunk.get(), n, &keepalive_count);
        const mw_stream_counters& c = decoder->counters;
        const std::size_t buffered = mw_stream_decoder_buffered(decoder);
        MOCAP_FUZZ_CHECK(buffered <= MW_PACKET_MAX_SIZE, "buffer bound");
        MOCAP_FUZZ_CHECK(c.bytes_in == packet_bytes + c.bytes_discarded + buffered,
                         "bytes_in != packets + discarded + buffered");
        MOCAP_FUZZ_CHECK(c.packets == packets, "packet counter");
        MOCAP_FUZZ_CHECK(c.crc_failures <= c.malformed_packets, "crc failures counted apart");
    }
    return 0;
}
