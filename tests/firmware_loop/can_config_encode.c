/* Encodes one CONFIG frame with the repository's wire library (mocap_wire), for the firmware-
 * in-the-loop tests to put on the virtual bus as the sink would:
 *   can_config_encode <node> <rate_hz> <accel_range> <gyro_range> <mode> <status_period_s>
 * prints "<id hex> <data hex>"; exit status 1 if the wire library rejects the fields. */
#include <stdio.h>
#include <stdlib.h>

#include "mocap_wire/mw_can.h"

int main(int argc, char** argv) {
    if (argc != 7) {
        fprintf(stderr, "usage: %s node rate_hz accel_range gyro_range mode status_period_s\n", argv[0]);
        return 2;
    }
    mw_config config;
    config.node_id = (uint8_t)strtoul(argv[1], NULL, 0);
    config.rate_hz = (uint16_t)strtoul(argv[2], NULL, 0);
    config.accel_range = (mw_accel_range)strtoul(argv[3], NULL, 0);
    config.gyro_range = (mw_gyro_range)strtoul(argv[4], NULL, 0);
    config.mode = (mw_mode)strtoul(argv[5], NULL, 0);
    config.status_period_s = (uint8_t)strtoul(argv[6], NULL, 0);
    mw_can_frame frame;
    if (mw_config_encode(&config, &frame) != MW_OK) {
        fprintf(stderr, "the wire library rejects this CONFIG\n");
        return 1;
    }
    printf("%03X ", frame.id);
    for (unsigned i = 0; i < frame.dlc; ++i) {
        printf("%02x", frame.data[i]);
    }
    printf("\n");
    return 0;
}
