/*
 * mw_can.c — encoders and decoders of the CAN message set (byte layouts in docs/protocol.md).
 *
 * Decoders check, in this order: NULL arguments, the ID (function and node field), the DLC,
 * then field ranges; so a frame with both a bad ID and a bad DLC reports MW_ERR_ID.
 * Reserved bits are written as zero and ignored on reception (room for compatible additions).
 */
#include "mocap_wire/mw_can.h"

#include <math.h>
#include <string.h>

#include "mw_endian.h"

/* Q15 scale of the three smallest quaternion components; |component| <= 1/sqrt(2) -> |v| <= 23170.
 */
#define MW_ATT_Q15_SCALE 32768.0f
#define MW_ATT_COMPONENT_MAX 23170
/* Sum of the three squared components in Q30: the dropped (largest) component is >= 1/2, so
 * the three others hold at most 3/4 of the unit norm; plus rounding slack of one half LSB each. */
#define MW_ATT_SUMSQ_MAX (805306368u + 65536u)

static void frame_begin(mw_can_frame* out, uint16_t id, uint8_t dlc) {
    out->id = id;
    out->dlc = dlc;
    memset(out->data, 0, sizeof out->data);
}

static bool node_is_sensor(uint8_t node_id) {
    return node_id >= MW_NODE_ID_MIN && node_id <= MW_NODE_ID_MAX;
}

static bool is_raw_kind(mw_function f) {
    return f == MW_FN_ACCEL || f == MW_FN_GYRO || f == MW_FN_MAG;
}

/* Common ID/DLC check of a frame that must carry `function` from a node in [node_min, 63]. */
static int check_frame(const mw_can_frame* frame, mw_function function, uint8_t node_min, uint8_t dlc) {
    if (frame->id > MW_CAN_ID_MAX || mw_can_id_function(frame->id) != function ||
        mw_can_id_node(frame->id) < node_min) {
        return MW_ERR_ID;
    }
    return frame->dlc == dlc ? MW_OK : MW_ERR_DLC;
}

/* ---------------------------------------------------------------- SYNC */

int mw_sync_encode(const mw_sync* msg, mw_can_frame* out) {
    if (msg == NULL || out == NULL) return MW_ERR_ARGUMENT;
    frame_begin(out, MW_CAN_ID_SYNC, MW_DLC_SYNC);
    mw_put_u32(out->data, msg->counter);
    return MW_OK;
}

int mw_sync_decode(const mw_can_frame* frame, mw_sync* out) {
    if (frame == NULL || out == NULL) return MW_ERR_ARGUMENT;
    if (frame->id != MW_CAN_ID_SYNC) return MW_ERR_ID;
    if (frame->dlc != MW_DLC_SYNC) return MW_ERR_DLC;
    out->counter = mw_get_u32(frame->data);
    return MW_OK;
}

/* ---------------------------------------------------------------- CONFIG */

static bool config_fields_valid(uint32_t rate_hz, uint32_t accel, uint32_t gyro, uint32_t mode) {
    return rate_hz >= MW_RATE_HZ_MIN && rate_hz <= MW_RATE_HZ_MAX && accel <= (uint32_t)MW_ACCEL_16G &&
           gyro <= (uint32_t)MW_GYRO_2000DPS && mode < MW_MODE_COUNT;
}

int mw_config_encode(const mw_config* msg, mw_can_frame* out) {
    if (msg == NULL || out == NULL || msg->node_id > MW_NODE_ID_MAX) return MW_ERR_ARGUMENT;
    if (!config_fields_valid(msg->rate_hz, (uint32_t)msg->accel_range, (uint32_t)msg->gyro_range,
                             (uint32_t)msg->mode)) {
        return MW_ERR_RANGE;
    }
    frame_begin(out, MW_CAN_ID(MW_FN_CONFIG, msg->node_id), MW_DLC_CONFIG);
    mw_put_u16(out->data, msg->rate_hz);
    out->data[2] = (uint8_t)((unsigned)msg->accel_range | ((unsigned)msg->gyro_range << 2));
    out->data[3] = (uint8_t)msg->mode;
    out->data[4] = msg->status_period_s;
    return MW_OK;
}

int mw_config_decode(const mw_can_frame* frame, mw_config* out) {
    if (frame == NULL || out == NULL) return MW_ERR_ARGUMENT;
    const int rc = check_frame(frame, MW_FN_CONFIG, MW_NODE_ID_BROADCAST, MW_DLC_CONFIG);
    if (rc != MW_OK) return rc;
    const uint16_t rate_hz = mw_get_u16(frame->data);
    const uint32_t accel = frame->data[2] & 0x3u;
    const uint32_t gyro = (frame->data[2] >> 2) & 0x3u;
    const uint32_t mode = frame->data[3];
    if (!config_fields_valid(rate_hz, accel, gyro, mode)) return MW_ERR_RANGE;
    out->node_id = mw_can_id_node(frame->id);
    out->rate_hz = rate_hz;
    out->accel_range = (mw_accel_range)accel;
    out->gyro_range = (mw_gyro_range)gyro;
    out->mode = (mw_mode)mode;
    out->status_period_s = frame->data[4];
    return MW_OK;
}

/* ---------------------------------------------------------------- ACCEL / GYRO / MAG */

/* A MAG reading is either three valid AK8963 values or the all-invalid marker. */
static bool mag_valid(const int16_t xyz[3]) {
    int invalid = 0;
    for (int i = 0; i < 3; ++i) {
        if (xyz[i] == MW_MAG_INVALID) {
            ++invalid;
        } else if (xyz[i] > MW_MAG_COUNTS_MAX || xyz[i] < -MW_MAG_COUNTS_MAX) {
            return false;
        }
    }
    return invalid == 0 || invalid == 3;
}

int mw_raw_encode(const mw_raw* msg, mw_can_frame* out) {
    if (msg == NULL || out == NULL || !is_raw_kind(msg->kind) || !node_is_sensor(msg->node_id)) {
        return MW_ERR_ARGUMENT;
    }
    if (msg->kind == MW_FN_MAG && !mag_valid(msg->xyz)) return MW_ERR_RANGE;
    frame_begin(out, MW_CAN_ID(msg->kind, msg->node_id), MW_DLC_RAW);
    for (size_t i = 0; i < 3u; ++i)
        mw_put_i16(out->data + 2u * i, msg->xyz[i]);
    mw_put_u16(out->data + 6, msg->counter_low);
    return MW_OK;
}

int mw_raw_decode(const mw_can_frame* frame, mw_raw* out) {
    if (frame == NULL || out == NULL) return MW_ERR_ARGUMENT;
    const mw_function kind = mw_can_id_function(frame->id);
    if (!is_raw_kind(kind)) return MW_ERR_ID;
    const int rc = check_frame(frame, kind, MW_NODE_ID_MIN, MW_DLC_RAW);
    if (rc != MW_OK) return rc;
    int16_t xyz[3];
    for (size_t i = 0; i < 3u; ++i)
        xyz[i] = mw_get_i16(frame->data + 2u * i);
    if (kind == MW_FN_MAG && !mag_valid(xyz)) return MW_ERR_RANGE;
    out->kind = kind;
    out->node_id = mw_can_id_node(frame->id);
    memcpy(out->xyz, xyz, sizeof xyz);
    out->counter_low = mw_get_u16(frame->data + 6);
    return MW_OK;
}

/* ---------------------------------------------------------------- ATT */

int mw_attitude_encode(const mw_attitude* msg, mw_can_frame* out) {
    if (msg == NULL || out == NULL || !node_is_sensor(msg->node_id)) return MW_ERR_ARGUMENT;
    float norm2 = 0.0f;
    for (int i = 0; i < 4; ++i) {
        if (!isfinite(msg->q[i])) return MW_ERR_RANGE;
        norm2 += msg->q[i] * msg->q[i];
    }
    if (!(norm2 >= 1e-6f) || !isfinite(norm2)) return MW_ERR_RANGE;
    const float inv_norm = 1.0f / sqrtf(norm2);

    /* Drop the largest-magnitude component: it is >= 1/2, so rebuilding it from the others is
     * well conditioned (dropping w instead loses about a degree near a 180 deg rotation). */
    unsigned largest = 0;
    for (unsigned i = 1; i < 4; ++i) {
        if (fabsf(msg->q[i]) > fabsf(msg->q[largest])) largest = i;
    }
    /* q and -q are the same rotation: choose the sign that makes the dropped component positive. */
    const float sign = msg->q[largest] < 0.0f ? -inv_norm : inv_norm;

    frame_begin(out, MW_CAN_ID(MW_FN_ATTITUDE, msg->node_id), MW_DLC_ATTITUDE);
    uint8_t* p = out->data;
    for (unsigned i = 0; i < 4; ++i) {
        if (i == largest) continue;
        float v = msg->q[i] * sign * MW_ATT_Q15_SCALE;
        v = v < 0.0f ? v - 0.5f : v + 0.5f; /* round half away from zero */
        int32_t c = (int32_t)v;
        if (c > MW_ATT_COMPONENT_MAX) c = MW_ATT_COMPONENT_MAX;
        if (c < -MW_ATT_COMPONENT_MAX) c = -MW_ATT_COMPONENT_MAX;
        mw_put_i16(p, (int16_t)c);
        p += 2;
    }
    const uint16_t counter = (uint16_t)(msg->counter_low & ((1u << MW_ATT_COUNTER_BITS) - 1u));
    mw_put_u16(out->data + 6, (uint16_t)(counter | (largest << MW_ATT_COUNTER_BITS)));
    return MW_OK;
}

int mw_attitude_decode(const mw_can_frame* frame, mw_attitude* out) {
    if (frame == NULL || out == NULL) return MW_ERR_ARGUMENT;
    const int rc = check_frame(frame, MW_FN_ATTITUDE, MW_NODE_ID_MIN, MW_DLC_ATTITUDE);
    if (rc != MW_OK) return rc;
    int16_t c[3];
    uint32_t sumsq = 0;
    for (size_t i = 0; i < 3u; ++i) {
        c[i] = mw_get_i16(frame->data + 2u * i);
        if (c[i] > MW_ATT_COMPONENT_MAX || c[i] < -MW_ATT_COMPONENT_MAX) return MW_ERR_RANGE;
        sumsq += (uint32_t)((int32_t)c[i] * (int32_t)c[i]);
    }
    if (sumsq > MW_ATT_SUMSQ_MAX) return MW_ERR_RANGE;
    const uint16_t tail = mw_get_u16(frame->data + 6);
    const unsigned largest = (unsigned)(tail >> MW_ATT_COUNTER_BITS); /* two bits: 0..3 */

    float q[4];
    float small2 = 0.0f;
    /* The three sent components fill the other slots in order (k indexes what was sent). */
    for (unsigned k = 0; k < 3u; ++k) {
        const unsigned i = k < largest ? k : k + 1u;
        q[i] = (float)c[k] / MW_ATT_Q15_SCALE;
        small2 += q[i] * q[i];
    }
    q[largest] = sqrtf(1.0f - small2); /* small2 <= 0.75 + slack, so the root is >= 0.49 */
    const float inv_norm = 1.0f / sqrtf(small2 + q[largest] * q[largest]);
    out->node_id = mw_can_id_node(frame->id);
    for (unsigned i = 0; i < 4; ++i)
        out->q[i] = q[i] * inv_norm;
    out->counter_low = (uint16_t)(tail & ((1u << MW_ATT_COUNTER_BITS) - 1u));
    return MW_OK;
}

/* ---------------------------------------------------------------- STATUS */

int mw_status_encode(const mw_status* msg, mw_can_frame* out) {
    if (msg == NULL || out == NULL || msg->node_id > MW_NODE_ID_MAX) return MW_ERR_ARGUMENT;
    if ((unsigned)msg->state >= MW_NODE_STATE_COUNT || (unsigned)msg->mode >= MW_MODE_COUNT ||
        (unsigned)msg->accel_range > (unsigned)MW_ACCEL_16G || (unsigned)msg->gyro_range > (unsigned)MW_GYRO_2000DPS) {
        return MW_ERR_RANGE;
    }
    frame_begin(out, MW_CAN_ID(MW_FN_STATUS, msg->node_id), MW_DLC_STATUS);
    out->data[0] = (uint8_t)((unsigned)msg->state | ((unsigned)msg->mode << 4) | (msg->mag_present ? 0x40u : 0u));
    out->data[1] = (uint8_t)((unsigned)msg->accel_range | ((unsigned)msg->gyro_range << 2));
    out->data[2] = msg->error_flags;
    out->data[3] = msg->protocol_version;
    mw_put_u16(out->data + 4, msg->uptime_s);
    out->data[6] = msg->tx_overflows;
    out->data[7] = msg->sync_missed;
    return MW_OK;
}

int mw_status_decode(const mw_can_frame* frame, mw_status* out) {
    if (frame == NULL || out == NULL) return MW_ERR_ARGUMENT;
    const int rc = check_frame(frame, MW_FN_STATUS, MW_NODE_ID_SINK, MW_DLC_STATUS);
    if (rc != MW_OK) return rc;
    const unsigned state = frame->data[0] & 0x0Fu;
    const unsigned mode = (frame->data[0] >> 4) & 0x03u;
    if (state >= MW_NODE_STATE_COUNT || mode >= MW_MODE_COUNT) return MW_ERR_RANGE;
    out->node_id = mw_can_id_node(frame->id);
    out->state = (mw_node_state)state;
    out->mode = (mw_mode)mode;
    out->mag_present = (frame->data[0] & 0x40u) != 0u;
    out->accel_range = (mw_accel_range)(frame->data[1] & 0x3u);
    out->gyro_range = (mw_gyro_range)((frame->data[1] >> 2) & 0x3u);
    out->error_flags = frame->data[2];
    out->protocol_version = frame->data[3];
    out->uptime_s = mw_get_u16(frame->data + 4);
    out->tx_overflows = frame->data[6];
    out->sync_missed = frame->data[7];
    return MW_OK;
}

/* ---------------------------------------------------------------- dispatch */

int mw_can_encode(const mw_message* msg, mw_can_frame* out) {
    if (msg == NULL) return MW_ERR_ARGUMENT;
    switch (msg->function) {
        case MW_FN_SYNC:
            return mw_sync_encode(&msg->u.sync, out);
        case MW_FN_CONFIG:
            return mw_config_encode(&msg->u.config, out);
        case MW_FN_ACCEL:
        case MW_FN_GYRO:
        case MW_FN_MAG:
            if (msg->u.raw.kind != msg->function) return MW_ERR_ARGUMENT;
            return mw_raw_encode(&msg->u.raw, out);
        case MW_FN_ATTITUDE:
            return mw_attitude_encode(&msg->u.attitude, out);
        case MW_FN_STATUS:
            return mw_status_encode(&msg->u.status, out);
        default:
            return MW_ERR_ARGUMENT;
    }
}

int mw_can_decode(const mw_can_frame* frame, mw_message* out) {
    if (frame == NULL || out == NULL) return MW_ERR_ARGUMENT;
    if (frame->id > MW_CAN_ID_MAX) return MW_ERR_ID;
    const mw_function function = mw_can_id_function(frame->id);
    int rc;
    switch (function) {
        case MW_FN_SYNC:
            rc = mw_sync_decode(frame, &out->u.sync);
            break;
        case MW_FN_CONFIG:
            rc = mw_config_decode(frame, &out->u.config);
            break;
        case MW_FN_ACCEL:
        case MW_FN_GYRO:
        case MW_FN_MAG:
            rc = mw_raw_decode(frame, &out->u.raw);
            break;
        case MW_FN_ATTITUDE:
            rc = mw_attitude_decode(frame, &out->u.attitude);
            break;
        case MW_FN_STATUS:
            rc = mw_status_decode(frame, &out->u.status);
            break;
        default:
            return MW_ERR_ID;
    }
    if (rc == MW_OK) out->function = function;
    return rc;
}

/* ---------------------------------------------------------------- counters */

uint32_t mw_counter_extend(uint32_t reference, uint32_t low, unsigned bits) {
    if (bits == 0u || bits >= 32u) return bits == 0u ? reference : low;
    const uint32_t span = 1u << bits;
    const uint32_t mask = span - 1u;
    /* Forward distance from the reference to the next counter with these low bits. */
    const uint32_t ahead = (low - reference) & mask;
    return ahead < (span >> 1) ? reference + ahead : reference - (span - ahead);
}
