/*
 * mw_crc32.h — CRC-32/IEEE 802.3 (the zlib / Ethernet CRC) used by the sink -> host packet.
 *
 * Parameters: polynomial 0x04C11DB7 (processed reflected as 0xEDB88320), initial value
 * 0xFFFFFFFF, input and output reflected, final XOR 0xFFFFFFFF. Check value:
 * CRC of the ASCII bytes "123456789" = 0xCBF43926.
 * Implementation: slicing-by-8, eight 256-entry const tables (8 KiB of flash), 8 bytes per
 * step with 8 independent lookups; ~5x the byte-at-a-time speed on x86 (docs/performance.md).
 * Built with MW_CRC32_SLICE_BY=1 the library keeps only the byte-at-a-time table (1 KiB) and
 * mw_crc32_update() uses it; the results are identical either way. Any length, any alignment.
 * Reentrant, no state.
 */
#ifndef MOCAP_WIRE_MW_CRC32_H
#define MOCAP_WIRE_MW_CRC32_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/** Initial value to pass to mw_crc32_update() for the first chunk. */
#define MW_CRC32_INIT 0u

/** CRC-32 of `len` bytes at `data` (data may be NULL when len is 0). */
uint32_t mw_crc32(const void* data, size_t len);

/**
 * Incremental form: crc = mw_crc32_update(MW_CRC32_INIT, a, na); crc = mw_crc32_update(crc, b, nb)
 * gives mw_crc32 of a followed by b. The value passed and returned is the finished CRC.
 */
uint32_t mw_crc32_update(uint32_t crc, const void* data, size_t len);

/**
 * Same result as mw_crc32_update(), one table lookup per byte (the 1 KiB table only): the
 * reference the tests and benchmarks compare the sliced form with.
 */
uint32_t mw_crc32_update_bytewise(uint32_t crc, const void* data, size_t len);

#ifdef __cplusplus
}
#endif

#endif /* MOCAP_WIRE_MW_CRC32_H */
