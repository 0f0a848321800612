/*
 * mw_can.h — the CAN message set of the body network (classic CAN 2.0A, 11-bit IDs, <= 8 bytes).
 *
 * ID layout (docs/protocol.md has every byte):
 *
 *     10 9 8 7 6 | 5 4 3 2 1 0
 *     function   | node id
 *
 *   function  ID range       DLC  sender  content
 *   0 SYNC    0x000          4    sink    uint32 sample counter; all nodes sample on it
 *   1 CONFIG  0x040 + node   5    sink    rate, ranges, mode, status period (node 0 = all nodes)
 *   2 ACCEL   0x080 + node   8    node    int16 x,y,z counts + low 16 bits of the SYNC counter
 *   3 GYRO    0x0C0 + node   8    node    int16 x,y,z counts + low 16 bits of the SYNC counter
 *   4 MAG     0x100 + node   8    node    int16 x,y,z counts + low 16 bits of the SYNC counter
 *   5 ATT     0x140 + node   8    node    quaternion (smallest three, Q15) + low 14 counter bits
 *   6 STATUS  0x180 + node   8    node    state, mode, ranges, error flags, counters (node 0 =
 * sink) 7..31     reserved (a decoder returns MW_ERR_ID)
 *
 * Lower ID wins arbitration, so SYNC (0x000) has the highest priority, then CONFIG, then the
 * samples. Node ids are 1..63 (MW_NODE_ID_MAX); node id 0 is the sink / broadcast address.
 * All multi-byte fields are little-endian, written byte by byte.
 *
 * Every encoder writes a complete frame (id, dlc, data; unused data bytes are zero) into a
 * caller-owned mw_can_frame and returns MW_OK or a negative mw_error; it never writes the
 * output on failure. Every decoder checks the ID, the DLC and every field's range and returns
 * MW_OK or a negative mw_error; on failure the output is unspecified. Encoders and decoders are
 * O(1), reentrant and integer-only, except the ATT pair which uses float (sqrtf).
 */
#ifndef MOCAP_WIRE_MW_CAN_H
#define MOCAP_WIRE_MW_CAN_H

#include <stdbool.h>
#include <stdint.h>

#include "mocap_wire/mw_common.h"
#include "mocap_wire/mw_scale.h"

#ifdef __cplusplus
extern "C" {
#endif

#define MW_CAN_ID_MAX 0x7FFu /**< largest 11-bit identifier */
#define MW_CAN_DLC_MAX 8u    /**< classic CAN */
#define MW_CAN_NODE_BITS 6u  /**< low ID bits holding the node id */
#define MW_CAN_NODE_MASK 0x3Fu
#define MW_NODE_ID_SINK 0u /**< the sink; also the CONFIG broadcast address */
#define MW_NODE_ID_BROADCAST 0u
#define MW_NODE_ID_MIN 1u  /**< smallest sensor-node id */
#define MW_NODE_ID_MAX 63u /**< largest sensor-node id */

#define MW_RATE_HZ_MIN 1u    /**< smallest sample rate a CONFIG may carry */
#define MW_RATE_HZ_MAX 1000u /**< largest sample rate a CONFIG may carry (MPU9250 ODR limit) */

#define MW_RAW_COUNTER_BITS 16u /**< SYNC counter bits carried by ACCEL/GYRO/MAG frames */
#define MW_ATT_COUNTER_BITS 14u /**< SYNC counter bits carried by ATT frames */

/** DLC of each message (a decoder requires exactly this). */
#define MW_DLC_SYNC 4u
#define MW_DLC_CONFIG 5u
#define MW_DLC_RAW 8u
#define MW_DLC_ATTITUDE 8u
#define MW_DLC_STATUS 8u

/** The function code: the top 5 bits of the 11-bit ID. */
typedef enum mw_function {
    MW_FN_SYNC = 0,
    MW_FN_CONFIG = 1,
    MW_FN_ACCEL = 2,
    MW_FN_GYRO = 3,
    MW_FN_MAG = 4,
    MW_FN_ATTITUDE = 5,
    MW_FN_STATUS = 6
} mw_function;

/** 11-bit ID of a function for a node: (function << 6) | node. No range check (a macro). */
#define MW_CAN_ID(function, node) \
    ((uint16_t)((((unsigned)(function)) << MW_CAN_NODE_BITS) | (((unsigned)(node)) & MW_CAN_NODE_MASK)))
#define MW_CAN_ID_SYNC 0x000u

/** What a node sends per sample. */
typedef enum mw_mode {
    MW_MODE_RAW = 0,         /**< ACCEL + GYRO + MAG per sample (3 frames) */
    MW_MODE_ATTITUDE = 1,    /**< ATT per sample (1 frame), on-node filter */
    MW_MODE_RAW_ATTITUDE = 2 /**< both (4 frames) */
} mw_mode;
#define MW_MODE_COUNT 3u

/** Node state reported in STATUS. */
typedef enum mw_node_state {
    MW_NODE_BOOT = 0,    /**< initialising the sensor */
    MW_NODE_WAITING = 1, /**< sensor ready, no SYNC seen recently */
    MW_NODE_RUNNING = 2, /**< sampling on SYNC */
    MW_NODE_FAULT = 3    /**< cannot sample (see error flags) */
} mw_node_state;
#define MW_NODE_STATE_COUNT 4u

/** STATUS error flags (bit set = condition present / happened since the previous STATUS). */
#define MW_ERRF_IMU 0x01u             /**< MPU9250 not responding or WHO_AM_I mismatch */
#define MW_ERRF_MAG 0x02u             /**< AK8963 not responding or overflowed */
#define MW_ERRF_CAN_TX_OVERFLOW 0x04u /**< a frame was dropped: the CAN TX queue was full */
#define MW_ERRF_SYNC_TIMEOUT 0x08u    /**< no SYNC for longer than 3 sample periods */
#define MW_ERRF_CONFIG_REJECTED 0x10u /**< the last CONFIG was invalid and ignored */
#define MW_ERRF_SATURATED 0x20u       /**< an accelerometer or gyroscope axis hit full scale */
#define MW_ERRF_CAN_BUS 0x40u         /**< the CAN controller went error-passive or bus-off */
#define MW_ERRF_RESET 0x80u           /**< first STATUS after a reset (power-on or watchdog) */

/** One classic CAN frame as it travels on the bus and inside the TCP packet. */
typedef struct mw_can_frame {
    uint16_t id;     /**< 11-bit identifier, 0..0x7FF */
    uint8_t dlc;     /**< 0..8 */
    uint8_t data[8]; /**< data[0..dlc-1] valid; encoders zero the rest */
} mw_can_frame;

/** SYNC (sink -> all). The counter increments by one per sample instant and wraps at 2^32. */
typedef struct mw_sync {
    uint32_t counter;
} mw_sync;

/** CONFIG (sink -> one node, or all nodes when node_id is 0). */
typedef struct mw_config {
    uint8_t node_id;  /**< 0 = broadcast, else 1..63 */
    uint16_t rate_hz; /**< SYNC rate the node should expect, MW_RATE_HZ_MIN..MAX */
    mw_accel_range accel_range;
    mw_gyro_range gyro_range;
    mw_mode mode;
    uint8_t status_period_s; /**< seconds between STATUS frames, 0 = only on change */
} mw_config;

/** ACCEL, GYRO or MAG sample: int16 counts in the MPU9250 accel/gyro axes (see mw_scale.h). */
typedef struct mw_raw {
    mw_function kind;     /**< MW_FN_ACCEL, MW_FN_GYRO or MW_FN_MAG */
    uint8_t node_id;      /**< 1..63 */
    int16_t xyz[3];       /**< counts; MAG: all MW_MAG_INVALID = no valid reading */
    uint16_t counter_low; /**< low 16 bits of the SYNC counter this sample belongs to */
} mw_raw;

/**
 * ATT: the node's own orientation estimate q_earth_sensor (w, x, y, z), unit norm, earth frame
 * ENU. Sent as "smallest three": the largest-magnitude component is dropped (its sign made
 * positive) and the other three are int16 Q15; the decoder reconstructs it. Resolution 3e-5.
 */
typedef struct mw_attitude {
    uint8_t node_id;      /**< 1..63 */
    float q[4];           /**< w, x, y, z; encoder normalises it; decoder returns unit norm */
    uint16_t counter_low; /**< low 14 bits of the SYNC counter (the encoder masks it) */
} mw_attitude;

/** STATUS (node -> sink; node_id 0 is the sink's own status, tunnelled to the host). */
typedef struct mw_status {
    uint8_t node_id; /**< 0 = sink, else 1..63 */
    mw_node_state state;
    mw_mode mode;
    bool mag_present;           /**< AK8963 found at start-up */
    mw_accel_range accel_range; /**< range in use */
    mw_gyro_range gyro_range;   /**< range in use */
    uint8_t error_flags;        /**< MW_ERRF_* */
    uint8_t protocol_version;   /**< MW_CAN_PROTOCOL_VERSION of the sender's firmware */
    uint16_t uptime_s;          /**< seconds since reset, wraps at 65536 */
    uint8_t tx_overflows;       /**< frames dropped (CAN TX full; sink: CAN RX full), wraps at 256 */
    uint8_t sync_missed;        /**< SYNCs expected but not received (sink: 0), wraps at 256 */
} mw_status;

/** Any decoded message: `function` selects the member of `u`. */
typedef struct mw_message {
    mw_function function;
    union {
        mw_sync sync;
        mw_config config;
        mw_raw raw; /**< function is ACCEL, GYRO or MAG; raw.kind == function */
        mw_attitude attitude;
        mw_status status;
    } u;
} mw_message;

/** Function code of an ID (top 5 bits). No validation. */
static inline mw_function mw_can_id_function(uint16_t id) {
    return (mw_function)((id >> MW_CAN_NODE_BITS) & 0x1Fu);
}

/** Node field of an ID (low 6 bits). No validation. */
static inline uint8_t mw_can_id_node(uint16_t id) {
    return (uint8_t)(id & MW_CAN_NODE_MASK);
}

int mw_sync_encode(const mw_sync* msg, mw_can_frame* out);
int mw_sync_decode(const mw_can_frame* frame, mw_sync* out);

int mw_config_encode(const mw_config* msg, mw_can_frame* out);
int mw_config_decode(const mw_can_frame* frame, mw_config* out);

int mw_raw_encode(const mw_raw* msg, mw_can_frame* out);
int mw_raw_decode(const mw_can_frame* frame, mw_raw* out);

/** MW_ERR_RANGE if q is not finite or its norm is below 1e-3. */
int mw_attitude_encode(const mw_attitude* msg, mw_can_frame* out);
/** MW_ERR_RANGE if a component is beyond 1/sqrt(2) or the three sum (squared) beyond 1. */
int mw_attitude_decode(const mw_can_frame* frame, mw_attitude* out);

int mw_status_encode(const mw_status* msg, mw_can_frame* out);
int mw_status_decode(const mw_can_frame* frame, mw_status* out);

/** Encodes whichever message `msg->function` selects. */
int mw_can_encode(const mw_message* msg, mw_can_frame* out);

/**
 * Decodes any frame of the message set, dispatching on the ID. Returns MW_OK, MW_ERR_ID for an
 * ID outside the table (reserved function, SYNC with node bits set, samples from node 0),
 * MW_ERR_DLC, or MW_ERR_RANGE.
 */
int mw_can_decode(const mw_can_frame* frame, mw_message* out);

/**
 * Rebuilds a full 32-bit SYNC counter from its low `bits` bits (1..32): returns the counter
 * whose low bits equal `low` and which is nearest to `reference` (for example the last SYNC
 * counter received), so it is correct across wrap-around of both the low bits and the 32-bit
 * counter as long as the true counter lies in [reference - 2^(bits-1), reference + 2^(bits-1) - 1].
 * bits == 32 returns low; bits == 0 returns reference. O(1).
 */
uint32_t mw_counter_extend(uint32_t reference, uint32_t low, unsigned bits);

#ifdef __cplusplus
}
#endif

#endif /* MOCAP_WIRE_MW_CAN_H */
