/*
 * mw_busload.c — worst-case classic CAN bus load, integer arithmetic (also usable on the sink
 * to warn about a configuration before applying it).
 */
#include "mocap_wire/mw_busload.h"

#include <stddef.h>

/* Bits of an 11-bit-ID data frame outside the data field, stuffing excluded:
 * SOF 1 + ID 11 + RTR 1 + IDE 1 + r0 1 + DLC 4 + CRC 15 + CRC delimiter 1 + ACK 1 +
 * ACK delimiter 1 + EOF 7 + intermission 3. */
#define MW_FRAME_OVERHEAD_BITS 47u
/* Bits exposed to stuffing without data: SOF through the CRC sequence. */
#define MW_STUFFED_OVERHEAD_BITS 34u

uint32_t mw_can_frame_bits(uint8_t dlc) {
    const uint32_t n = dlc > MW_CAN_DLC_MAX ? MW_CAN_DLC_MAX : dlc;
    const uint32_t stuffed = MW_STUFFED_OVERHEAD_BITS + 8u * n;
    return MW_FRAME_OVERHEAD_BITS + 8u * n + (stuffed - 1u) / 4u;
}

uint32_t mw_frames_per_sample(mw_mode mode) {
    switch (mode) {
        case MW_MODE_RAW:
            return 3u;
        case MW_MODE_ATTITUDE:
            return 1u;
        case MW_MODE_RAW_ATTITUDE:
            return 4u;
        default:
            return 0u;
    }
}

static uint64_t div_ceil(uint64_t a, uint64_t b) {
    return (a + b - 1u) / b;
}

int mw_busload_compute(const mw_busload_params* params, mw_busload* out) {
    if (params == NULL || out == NULL) return MW_ERR_ARGUMENT;
    const uint32_t per_sample = mw_frames_per_sample(params->mode);
    if (params->nodes > MW_NODE_ID_MAX || params->rate_hz < MW_RATE_HZ_MIN || params->rate_hz > MW_RATE_HZ_MAX ||
        params->bitrate_bps == 0u || per_sample == 0u) {
        return MW_ERR_ARGUMENT;
    }
    /* Raw and attitude frames both carry 8 data bytes; SYNC carries 4; STATUS 8. */
    const uint64_t sample_frames = (uint64_t)params->nodes * per_sample;
    const uint64_t per_period_bits = mw_can_frame_bits(MW_DLC_SYNC) + sample_frames * mw_can_frame_bits(MW_DLC_RAW);
    uint64_t frames = (1u + sample_frames) * params->rate_hz;
    uint64_t bits = per_period_bits * params->rate_hz;
    if (params->status_period_s > 0u) {
        frames += div_ceil(params->nodes, params->status_period_s);
        bits += div_ceil((uint64_t)params->nodes * mw_can_frame_bits(MW_DLC_STATUS), params->status_period_s);
    }
    out->frames_per_s = (uint32_t)frames;
    out->bits_per_s = (uint32_t)bits;
    out->load_permille = (uint32_t)div_ceil(bits * 1000u, params->bitrate_bps);
    out->fits = bits <= params->bitrate_bps;
    return MW_OK;
}
