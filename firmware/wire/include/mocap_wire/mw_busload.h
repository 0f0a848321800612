/*
 * mw_busload.h — CAN bus load of the body network, worst case.
 *
 * A classic CAN 2.0A data frame with n data bytes takes, worst case (Davis et al., 2007):
 *   47 + 8n bits (SOF, 11-bit ID, RTR, IDE, r0, DLC, data, CRC + delimiter, ACK slot + delimiter,
 *                 7-bit EOF, 3-bit intermission)
 *   + floor((34 + 8n - 1) / 4) stuff bits (the 34 + 8n bits from SOF to the end of the CRC
 *     are stuffed; the worst case inserts one bit after every 4 bits after the first).
 * So 135 bits for 8 data bytes, 95 bits for SYNC's 4. Integer only, O(1), reentrant.
 */
#ifndef MOCAP_WIRE_MW_BUSLOAD_H
#define MOCAP_WIRE_MW_BUSLOAD_H

#include <stdbool.h>
#include <stdint.h>

#include "mocap_wire/mw_can.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Worst-case bits on the bus for one frame with `dlc` data bytes (dlc > 8 is treated as 8). */
uint32_t mw_can_frame_bits(uint8_t dlc);

/** Frames one node sends per sample in a mode: 3 (raw), 1 (attitude), 4 (both); 0 if invalid. */
uint32_t mw_frames_per_sample(mw_mode mode);

typedef struct mw_busload_params {
    uint32_t nodes;   /**< sensor nodes on the bus, 0..MW_NODE_ID_MAX */
    uint32_t rate_hz; /**< SYNC rate, MW_RATE_HZ_MIN..MW_RATE_HZ_MAX */
    mw_mode mode;
    uint32_t bitrate_bps;     /**< e.g. 500000 or 1000000; > 0 */
    uint32_t status_period_s; /**< STATUS period per node, 0 = no periodic STATUS */
} mw_busload_params;

typedef struct mw_busload {
    uint32_t frames_per_s;  /**< SYNC + samples + STATUS (rounded up) */
    uint32_t bits_per_s;    /**< worst-case stuffing, rounded up */
    uint32_t load_permille; /**< bits_per_s * 1000 / bitrate_bps, rounded up */
    bool fits;              /**< bits_per_s <= bitrate_bps: every sample's frames fit in its period */
} mw_busload;

/** Fills *out. MW_ERR_ARGUMENT for NULL or a parameter outside its range. */
int mw_busload_compute(const mw_busload_params* params, mw_busload* out);

#ifdef __cplusplus
}
#endif

#endif /* MOCAP_WIRE_MW_BUSLOAD_H */
