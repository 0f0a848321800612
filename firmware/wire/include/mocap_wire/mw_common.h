/*
 * mw_common.h — error codes and versions shared by every part of the mocap wire library.
 *
 * The wire library is C99 with no heap and no OS: every object is allocated by the caller,
 * no function keeps a pointer to caller memory after it returns (unless its contract says so),
 * and every function is reentrant (no global mutable state). It is linked by the sensor-node
 * and sink-node firmware (Cortex-M), by the host simulator and by the daemon's ingest.
 *
 * Error convention (as in libcanard): functions that can fail return an `int`; zero or a
 * positive value means success, a negative value is one of the MW_ERR_* codes below.
 * Malformed input from the wire is always reported by a return code, never by an assert.
 */
#ifndef MOCAP_WIRE_MW_COMMON_H
#define MOCAP_WIRE_MW_COMMON_H

#ifdef __cplusplus
extern "C" {
#endif

/** Version of the CAN message set described in docs/protocol.md; nodes report it in STATUS. */
#define MW_CAN_PROTOCOL_VERSION 1u

/** Version of the sink -> host TCP packet; byte 4 of every packet. Unchanged by stream version 2. */
#define MW_PACKET_VERSION 1u

/** Version of the TCP stream as a whole (docs/protocol.md §3.6): 1 = sink -> host packets only,
 * 2 = the host also sends keepalives (mw_keepalive.h), whose byte 4 carries this number. */
#define MW_STREAM_VERSION 2u

/** Error codes. All negative so that "ret < 0" means failure. */
typedef enum mw_error {
    MW_OK = 0,
    MW_ERR_ARGUMENT = -1, /**< caller error: NULL pointer or argument outside its documented domain */
    MW_ERR_DLC = -2,      /**< CAN frame has the wrong data length for its ID (or DLC > 8) */
    MW_ERR_ID = -3,       /**< CAN ID is not one of the IDs in docs/protocol.md (or > 0x7FF) */
    MW_ERR_RANGE = -4,    /**< a field holds a value outside its documented range */
    MW_ERR_SPACE = -5,    /**< the caller's output buffer (or the packet) is full */
    MW_ERR_VERSION = -6,  /**< TCP packet version is not MW_PACKET_VERSION */
    MW_ERR_LENGTH = -7,   /**< TCP packet header claims a frame count / payload length that cannot be */
    MW_ERR_CRC = -8,      /**< TCP packet CRC-32 does not match */
    MW_ERR_RECORD = -9    /**< TCP packet payload holds a bad frame record (ID bits, DLC, length) */
} mw_error;

/** Static, human-readable name of an error code ("MW_ERR_DLC"); "MW_ERR_?" for unknown codes. */
const char* mw_error_name(int error);

#ifdef __cplusplus
}
#endif

#endif /* MOCAP_WIRE_MW_COMMON_H */
