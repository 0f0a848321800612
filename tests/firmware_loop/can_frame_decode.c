/* Decodes CAN frames with the repository's wire library (mocap_wire), for the firmware-in-the-
 * loop tests: what the emulated node put on the bus is read exactly as the sink and mocapd
 * read it. One frame per input line, "<id hex> <data hex>"; one output line per frame:
 *   ACCEL|GYRO|MAG <node> <counter_low> <x> <y> <z> <sx> <sy> <sz>   counts, then SI units
 *                                        (m/s^2, rad/s, uT; ranges from the node's last STATUS)
 *   STATUS <node> <state> <error_flags> <accel_range> <gyro_range> <mag_present>
 *   ATT <node> <counter_low> <w> <x> <y> <z>
 *   SYNC <counter> | CONFIG <node> | ERROR <mw_error> */
#include <stdio.h>
#include <string.h>

#include "mocap_wire/mw_can.h"

static int parse(const char* line, mw_can_frame* frame) {
    unsigned id = 0;
    char hex[32] = {0};
    const int n = sscanf(line, "%x %31s", &id, hex);
    if (n < 1 || id > MW_CAN_ID_MAX) {
        return -1;
    }
    const size_t len = n == 2 ? strlen(hex) : 0u;
    if (len % 2u != 0u || len > 16u) {
        return -1;
    }
    frame->id = (uint16_t)id;
    frame->dlc = (uint8_t)(len / 2u);
    memset(frame->data, 0, sizeof frame->data);
    for (size_t i = 0; i < frame->dlc; ++i) {
        unsigned byte = 0;
        if (sscanf(hex + 2u * i, "%2x", &byte) != 1) {
            return -1;
        }
        frame->data[i] = (uint8_t)byte;
    }
    return 0;
}

int main(void) {
    mw_accel_range accel_range[MW_NODE_ID_MAX + 1];
    mw_gyro_range gyro_range[MW_NODE_ID_MAX + 1];
    for (unsigned i = 0; i <= MW_NODE_ID_MAX; ++i) { /* the node defaults until a STATUS says otherwise */
        accel_range[i] = MW_ACCEL_16G;
        gyro_range[i] = MW_GYRO_2000DPS;
    }
    char line[128];
    while (fgets(line, sizeof line, stdin) != NULL) {
        mw_can_frame frame;
        mw_message msg;
        if (parse(line, &frame) != 0) {
            printf("ERROR parse\n");
            continue;
        }
        const int rc = mw_can_decode(&frame, &msg);
        if (rc != MW_OK) {
            printf("ERROR %d\n", rc);
            continue;
        }
        float si[3] = {0.0f, 0.0f, 0.0f};
        switch (msg.function) {
            case MW_FN_ACCEL:
            case MW_FN_GYRO:
            case MW_FN_MAG: {
                const mw_raw* r = &msg.u.raw;
                const char* name = "MAG";
                if (r->kind == MW_FN_ACCEL) {
                    name = "ACCEL";
                    (void)mw_accel_to_m_s2(r->xyz, accel_range[r->node_id], si);
                } else if (r->kind == MW_FN_GYRO) {
                    name = "GYRO";
                    (void)mw_gyro_to_rad_s(r->xyz, gyro_range[r->node_id], si);
                } else {
                    (void)mw_mag_to_ut(r->xyz, si);
                }
                printf("%s %u %u %d %d %d %.6f %.6f %.6f\n", name, r->node_id, r->counter_low, r->xyz[0], r->xyz[1],
                       r->xyz[2], (double)si[0], (double)si[1], (double)si[2]);
                break;
            }
            case MW_FN_STATUS: {
                const mw_status* s = &msg.u.status;
                if (s->node_id <= MW_NODE_ID_MAX) {
                    accel_range[s->node_id] = s->accel_range;
                    gyro_range[s->node_id] = s->gyro_range;
                }
                printf("STATUS %u %d %u %d %d %d\n", s->node_id, (int)s->state, s->error_flags, (int)s->accel_range,
                       (int)s->gyro_range, s->mag_present ? 1 : 0);
                break;
            }
            case MW_FN_ATTITUDE: {
                const mw_attitude* a = &msg.u.attitude;
                printf("ATT %u %u %.6f %.6f %.6f %.6f\n", a->node_id, a->counter_low, (double)a->q[0], (double)a->q[1],
                       (double)a->q[2], (double)a->q[3]);
                break;
            }
            case MW_FN_SYNC:
                printf("SYNC %u\n", (unsigned)msg.u.sync.counter);
                break;
            case MW_FN_CONFIG:
                printf("CONFIG %u\n", msg.u.config.node_id);
                break;
        }
    }
    return 0;
}
