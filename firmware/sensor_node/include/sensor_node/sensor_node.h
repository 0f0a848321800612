/* Sensor-node core: the portable part of the IMU node firmware (C99, no heap, no OS).
 *
 * What it does: on every SYNC frame from the sink it reads one MPU9250 sample and queues the
 * ACCEL, GYRO and MAG frames (tagged with the low 16 bits of the SYNC counter) for CAN
 * transmission, or in attitude mode the ATT frame of its own filter (attitude.h), or both; it applies CONFIG frames
 * addressed to it or broadcast (rate -> low-pass filter, accelerometer/gyroscope ranges, status period); it sends
 * STATUS frames periodically and early when its state or a persistent condition changes or a new kind of event occurs.
 * Message formats: mocap_wire/mw_can.h.
 *
 * HAL (libcanard style): a struct of function pointers plus a user pointer, filled by the
 * caller and copied into the node at init. The core calls the HAL only from
 * sensor_node_init() and sensor_node_poll(), never from an interrupt.
 *
 * Ownership: the caller allocates `sensor_node` (about 300 bytes) and keeps it alive.
 * Threading: single context; call sensor_node_poll() from the main loop as often as possible
 * (each call drains the CAN receive path, so SYNC-to-sample latency is one loop iteration).
 * Cost: one poll with a SYNC = one 23-byte SPI burst + three frame encodes (+ one filter
 * update and one ATT encode in attitude modes); otherwise O(1).
 */
#ifndef MOCAP_SENSOR_NODE_SENSOR_NODE_H
#define MOCAP_SENSOR_NODE_SENSOR_NODE_H

#include <stddef.h>
#include <stdint.h>

#include "mocap_wire/mw_can.h"
#include "sensor_node/attitude.h"
#include "sensor_node/mpu9250.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Frames the core can hold while the CAN controller's mailboxes are busy. A power of two. */
#define SENSOR_NODE_TX_QUEUE_LEN 16u
/* Sensor re-initialisation interval while the MPU9250 does not answer. */
#define SENSOR_NODE_IMU_RETRY_US 1000000u
/* A SYNC is "missing" when none arrived for this many sample periods (MW_ERRF_SYNC_TIMEOUT). */
#define SENSOR_NODE_SYNC_TIMEOUT_PERIODS 3u

typedef struct sensor_node_hal {
    void* user; /* passed to every call */
    /* One chip-select-framed full-duplex SPI transfer of len bytes to the MPU9250; 0 = ok. */
    int (*spi_transfer)(void* user, const uint8_t* tx, uint8_t* rx, size_t len);
    /* Offers one frame to the CAN controller: 0 = accepted (a TX mailbox was free), nonzero =
     * all mailboxes busy; the core keeps the frame queued and offers it again later. */
    int (*can_transmit)(void* user, const mw_can_frame* frame);
    /* Takes one received frame: 1 = *frame filled, 0 = nothing pending. */
    int (*can_receive)(void* user, mw_can_frame* frame);
    /* Monotonic microseconds since an arbitrary origin. */
    uint64_t (*time_us)(void* user);
    /* Optional (may be NULL): nonzero while the CAN controller is error-passive, bus-off or
     * not on the bus; reported as MW_ERRF_CAN_BUS. */
    int (*can_bus_error)(void* user);
} sensor_node_hal;

/* Counters only go up (they wrap at 2^32). */
typedef struct sensor_node_counters {
    uint32_t syncs;            /* SYNC frames received */
    uint32_t samples;          /* samples read and queued */
    uint32_t frames_sent;      /* frames accepted by the CAN controller */
    uint32_t tx_overflows;     /* frames dropped because the TX queue was full */
    uint32_t sync_missed;      /* SYNC counter gaps (counter jumped by more than one) */
    uint32_t syncs_stale;      /* SYNCs that waited while the sensor was brought up: dropped */
    uint32_t configs_applied;  /* CONFIG frames accepted */
    uint32_t configs_rejected; /* CONFIG frames for this node that were invalid or unsupported */
    uint32_t malformed_frames; /* received frames the wire decoder rejected */
    uint32_t sensor_errors;    /* failed sample reads or sensor initialisations */
} sensor_node_counters;

typedef struct sensor_node {
    sensor_node_hal hal;
    mpu9250 imu;
    attitude_filter attitude; /* runs only in MW_MODE_ATTITUDE / MW_MODE_RAW_ATTITUDE */
    mw_config config;         /* node_id is this node's id; rate/ranges/mode/status period in use */
    mw_node_state state;
    uint8_t event_flags;            /* MW_ERRF_* events since the last STATUS */
    uint8_t last_status_flags;      /* flags of the last STATUS sent */
    uint8_t last_status_persistent; /* of which persistent conditions (not events) */
    mw_node_state last_status_state;
    uint8_t status_due; /* a STATUS must go out at the next poll */
    uint8_t have_sync;
    uint32_t last_sync_counter;
    uint64_t boot_us;
    uint64_t last_sync_us;
    uint64_t next_status_us;
    uint64_t next_imu_retry_us;
    mw_can_frame tx_queue[SENSOR_NODE_TX_QUEUE_LEN];
    uint8_t tx_head; /* index of the oldest queued frame */
    uint8_t tx_count;
    sensor_node_counters counters;
} sensor_node;

/* Defaults before any CONFIG arrives: 100 Hz, +-16 g, +-2000 dps, raw mode, STATUS every 1 s. */
#define SENSOR_NODE_DEFAULT_RATE_HZ 100u
#define SENSOR_NODE_DEFAULT_STATUS_PERIOD_S 1u

/* Copies the HAL, initialises the MPU9250 (~150 ms, blocking) and queues the first STATUS
 * (with MW_ERRF_RESET). node_id must be MW_NODE_ID_MIN..MW_NODE_ID_MAX.
 * Returns MW_OK (also when the sensor failed: the node then reports MW_NODE_FAULT and retries
 * every SENSOR_NODE_IMU_RETRY_US) or MW_ERR_ARGUMENT. */
int sensor_node_init(sensor_node* node, const sensor_node_hal* hal, uint8_t node_id);

/* Handles every received frame, the STATUS timer, the sensor retry, and offers queued frames
 * to the CAN controller until it is full. */
void sensor_node_poll(sensor_node* node);

/* Queues a frame for transmission; returns MW_OK or MW_ERR_SPACE (counted as an overflow). */
int sensor_node_queue_frame(sensor_node* node, const mw_can_frame* frame);

/* Current STATUS content (what the next STATUS frame would carry, minus clearing events). */
void sensor_node_status(const sensor_node* node, mw_status* out);

#ifdef __cplusplus
}
#endif

#endif
