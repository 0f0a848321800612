/*
 * mw_endian.h — private: little-endian loads and stores, byte by byte, so the wire format does
 * not depend on the host's byte order, alignment or struct layout.
 */
#ifndef MOCAP_WIRE_MW_ENDIAN_H
#define MOCAP_WIRE_MW_ENDIAN_H

#include <stdint.h>

static inline void mw_put_u16(uint8_t* p, uint16_t v) {
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)(v >> 8);
}

static inline void mw_put_u32(uint8_t* p, uint32_t v) {
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)((v >> 8) & 0xFFu);
    p[2] = (uint8_t)((v >> 16) & 0xFFu);
    p[3] = (uint8_t)(v >> 24);
}

static inline void mw_put_u64(uint8_t* p, uint64_t v) {
    mw_put_u32(p, (uint32_t)(v & 0xFFFFFFFFu));
    mw_put_u32(p + 4, (uint32_t)(v >> 32));
}

static inline uint16_t mw_get_u16(const uint8_t* p) {
    return (uint16_t)(p[0] | (p[1] << 8));
}

static inline uint32_t mw_get_u32(const uint8_t* p) {
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static inline uint64_t mw_get_u64(const uint8_t* p) {
    return (uint64_t)mw_get_u32(p) | ((uint64_t)mw_get_u32(p + 4) << 32);
}

/* Two's complement conversions written out so that they are defined behaviour in C99. */
static inline void mw_put_i16(uint8_t* p, int16_t v) {
    mw_put_u16(p, (uint16_t)v);
}

static inline int16_t mw_get_i16(const uint8_t* p) {
    const uint16_t u = mw_get_u16(p);
    return (u & 0x8000u) != 0u ? (int16_t)(-(int32_t)(0xFFFFu - u) - 1) : (int16_t)u;
}

#endif /* MOCAP_WIRE_MW_ENDIAN_H */
