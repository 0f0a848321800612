/* Sensor-node core. Design notes:
 * - Sampling is driven only by SYNC so that every node samples the same instant; the node
 *   never free-runs, which is why a SYNC timeout is reported rather than covered up.
 * - Frames go through a small FIFO in front of the three CAN mailboxes: one sample is three
 *   frames, so a busy bus must not lose the tail of a sample while a mailbox frees up. When
 *   the FIFO is full the newest frame is dropped (counted), which keeps the order on the bus.
 * - STATUS is queued like any frame; its error flags are the persistent conditions plus the
 *   events since the previous STATUS, which are then cleared (mw_can.h semantics). */
#include "sensor_node/sensor_node.h"

#define US_PER_S 1000000u

static uint64_t now_us(const sensor_node* node) {
    return node->hal.time_us(node->hal.user);
}

static uint8_t persistent_flags(const sensor_node* node) {
    uint8_t flags = 0;
    if (node->state == MW_NODE_FAULT) {
        flags |= MW_ERRF_IMU;
    }
    if (node->state != MW_NODE_FAULT && node->state != MW_NODE_BOOT && !node->imu.mag_present) {
        flags |= MW_ERRF_MAG;
    }
    if (node->state == MW_NODE_WAITING && node->have_sync) {
        flags |= MW_ERRF_SYNC_TIMEOUT;
    }
    return flags;
}

int sensor_node_queue_frame(sensor_node* node, const mw_can_frame* frame) {
    if (node->tx_count >= SENSOR_NODE_TX_QUEUE_LEN) {
        ++node->counters.tx_overflows;
        node->event_flags |= MW_ERRF_CAN_TX_OVERFLOW;
        return MW_ERR_SPACE;
    }
    const unsigned tail = (node->tx_head + node->tx_count) & (SENSOR_NODE_TX_QUEUE_LEN - 1u);
    node->tx_queue[tail] = *frame;
    ++node->tx_count;
    return MW_OK;
}

static void flush_tx(sensor_node* node) {
    while (node->tx_count > 0u) {
        if (node->hal.can_transmit(node->hal.user, &node->tx_queue[node->tx_head]) != 0) {
            return; /* mailboxes full; try again next poll */
        }
        node->tx_head = (uint8_t)((node->tx_head + 1u) & (SENSOR_NODE_TX_QUEUE_LEN - 1u));
        --node->tx_count;
        ++node->counters.frames_sent;
    }
}

void sensor_node_status(const sensor_node* node, mw_status* out) {
    out->node_id = node->config.node_id;
    out->state = node->state;
    out->mode = node->config.mode;
    out->mag_present = node->imu.mag_present != 0u;
    out->accel_range = node->config.accel_range;
    out->gyro_range = node->config.gyro_range;
    out->error_flags = (uint8_t)(node->event_flags | persistent_flags(node));
    out->protocol_version = MW_CAN_PROTOCOL_VERSION;
    out->uptime_s = (uint16_t)((now_us(node) - node->boot_us) / US_PER_S);
    out->tx_overflows = (uint8_t)node->counters.tx_overflows;
    out->sync_missed = (uint8_t)node->counters.sync_missed;
}

static void send_status(sensor_node* node) {
    mw_status status;
    mw_can_frame frame;
    if (node->tx_count >= SENSOR_NODE_TX_QUEUE_LEN) {
        return; /* stays due; a full queue is not a STATUS overflow */
    }
    sensor_node_status(node, &status);
    if (mw_status_encode(&status, &frame) != MW_OK) {
        return; /* cannot happen with our own fields; nothing sensible to send */
    }
    if (sensor_node_queue_frame(node, &frame) == MW_OK) {
        node->event_flags = 0;
        node->last_status_flags = status.error_flags;
        node->last_status_persistent = persistent_flags(node);
        node->last_status_state = status.state;
        node->status_due = 0;
    }
    if (node->config.status_period_s != 0u) {
        node->next_status_us = now_us(node) + (uint64_t)node->config.status_period_s * US_PER_S;
    }
}

static void drop_waiting_syncs(sensor_node* node);

static int init_imu(sensor_node* node) {
    const mpu9250_bus bus = {node->hal.user, node->hal.spi_transfer, node->hal.time_us};
    const int rc = mpu9250_init(&node->imu, &bus, node->config.accel_range, node->config.gyro_range,
                                mpu9250_dlpf_for_rate(node->config.rate_hz));
    if (rc == MPU9250_OK || rc == MPU9250_ERR_I2C || rc == MPU9250_ERR_MAG_ID) {
        node->state = MW_NODE_WAITING; /* the magnetometer alone is not fatal */
        if (rc != MPU9250_OK) {
            ++node->counters.sensor_errors;
        }
        return 1;
    }
    ++node->counters.sensor_errors;
    node->state = MW_NODE_FAULT;
    node->next_imu_retry_us = now_us(node) + SENSOR_NODE_IMU_RETRY_US;
    return 0;
}

int sensor_node_init(sensor_node* node, const sensor_node_hal* hal, uint8_t node_id) {
    if (node == NULL || hal == NULL || hal->spi_transfer == NULL || hal->can_transmit == NULL ||
        hal->can_receive == NULL || hal->time_us == NULL || node_id < MW_NODE_ID_MIN || node_id > MW_NODE_ID_MAX) {
        return MW_ERR_ARGUMENT;
    }
    const sensor_node zero = {0};
    *node = zero;
    node->hal = *hal;
    node->config.node_id = node_id;
    node->config.rate_hz = SENSOR_NODE_DEFAULT_RATE_HZ;
    node->config.accel_range = MW_ACCEL_16G;
    node->config.gyro_range = MW_GYRO_2000DPS;
    node->config.mode = MW_MODE_RAW;
    node->config.status_period_s = SENSOR_NODE_DEFAULT_STATUS_PERIOD_S;
    node->state = MW_NODE_BOOT;
    node->boot_us = now_us(node);
    attitude_reset(&node->attitude);
    (void)init_imu(node);
    node->event_flags = MW_ERRF_RESET;
    node->status_due = 1;
    drop_waiting_syncs(node);
    return MW_OK;
}

static int saturated(const int16_t v[3]) {
    for (int i = 0; i < 3; ++i) {
        if (v[i] == INT16_MAX || v[i] == INT16_MIN) {
            return 1;
        }
    }
    return 0;
}

static void queue_raw(sensor_node* node, mw_function kind, const int16_t xyz[3], uint16_t counter_low) {
    mw_raw raw;
    mw_can_frame frame;
    raw.kind = kind;
    raw.node_id = node->config.node_id;
    raw.xyz[0] = xyz[0];
    raw.xyz[1] = xyz[1];
    raw.xyz[2] = xyz[2];
    raw.counter_low = counter_low;
    if (mw_raw_encode(&raw, &frame) == MW_OK) {
        (void)sensor_node_queue_frame(node, &frame);
    }
}

/* Feeds the filter with the sample (instants = SYNC periods since the previous sample) and
 * queues the ATT frame. */
static void update_attitude(sensor_node* node, const mpu9250_sample* sample, uint32_t instants, uint16_t counter_low) {
    float gyro[3], accel[3], mag[3];
    if (mw_gyro_to_rad_s(sample->gyro, node->config.gyro_range, gyro) != MW_OK ||
        mw_accel_to_m_s2(sample->accel, node->config.accel_range, accel) != MW_OK) {
        return;
    }
    const int mag_ok = mw_mag_to_ut(sample->mag, mag) == MW_OK;
    const float dt_s = (float)instants / (float)node->config.rate_hz;
    attitude_update(&node->attitude, gyro, accel, mag_ok ? mag : NULL, dt_s);
    if (!node->attitude.initialized) {
        return;
    }
    mw_attitude att;
    mw_can_frame frame;
    att.node_id = node->config.node_id;
    for (int i = 0; i < 4; ++i) {
        att.q[i] = node->attitude.q[i];
    }
    att.counter_low = counter_low;
    if (mw_attitude_encode(&att, &frame) == MW_OK) {
        (void)sensor_node_queue_frame(node, &frame);
    }
}

static void on_sync(sensor_node* node, const mw_sync* sync) {
    ++node->counters.syncs;
    uint32_t instants = 1;
    if (node->have_sync && sync->counter - node->last_sync_counter > 1u) {
        node->counters.sync_missed += sync->counter - node->last_sync_counter - 1u;
        instants = sync->counter - node->last_sync_counter;
    }
    node->have_sync = 1;
    node->last_sync_counter = sync->counter;
    node->last_sync_us = now_us(node);
    if (node->state == MW_NODE_FAULT || node->state == MW_NODE_BOOT) {
        return;
    }
    node->state = MW_NODE_RUNNING;
    mpu9250_sample sample;
    if (mpu9250_read(&node->imu, &sample) != MPU9250_OK) {
        /* The sensor stopped answering. It may come back reset (ranges, I2C master, sleep),
         * so nothing it sends is trusted before it was initialised again. */
        ++node->counters.sensor_errors;
        node->event_flags |= MW_ERRF_IMU;
        node->state = MW_NODE_FAULT;
        node->next_imu_retry_us = now_us(node) + SENSOR_NODE_IMU_RETRY_US;
        return;
    }
    ++node->counters.samples;
    if (saturated(sample.accel) || saturated(sample.gyro)) {
        node->event_flags |= MW_ERRF_SATURATED;
    }
    if (sample.mag_overflow) {
        node->event_flags |= MW_ERRF_MAG;
    }
    const uint16_t low = (uint16_t)sync->counter;
    if (node->config.mode != MW_MODE_ATTITUDE) {
        queue_raw(node, MW_FN_ACCEL, sample.accel, low);
        queue_raw(node, MW_FN_GYRO, sample.gyro, low);
        queue_raw(node, MW_FN_MAG, sample.mag, low);
    }
    if (node->config.mode != MW_MODE_RAW) {
        update_attitude(node, &sample, instants, low);
    }
}

static void on_config(sensor_node* node, const mw_config* config) {
    if (config->node_id != MW_NODE_ID_BROADCAST && config->node_id != node->config.node_id) {
        return;
    }
    if (node->state != MW_NODE_FAULT) {
        if (mpu9250_set_ranges(&node->imu, config->accel_range, config->gyro_range) != MPU9250_OK ||
            mpu9250_set_dlpf(&node->imu, mpu9250_dlpf_for_rate(config->rate_hz)) != MPU9250_OK) {
            ++node->counters.sensor_errors;
            node->event_flags |= MW_ERRF_IMU;
        }
    }
    if (node->config.mode == MW_MODE_RAW && config->mode != MW_MODE_RAW) {
        attitude_reset(&node->attitude); /* stale while it did not run: start from a measurement */
    }
    const uint8_t own_id = node->config.node_id;
    node->config = *config;
    node->config.node_id = own_id;
    ++node->counters.configs_applied;
    node->status_due = 1; /* acknowledges the new ranges */
}

static void handle_frame(sensor_node* node, const mw_can_frame* frame) {
    const mw_function fn = mw_can_id_function(frame->id);
    mw_sync sync;
    mw_config config;
    /* The per-message decoders rather than mw_can_decode(): the node never receives an
     * attitude frame, and this keeps its float decoder out of the Cortex-M3 image. */
    if (fn == MW_FN_SYNC) {
        if (mw_sync_decode(frame, &sync) != MW_OK) {
            ++node->counters.malformed_frames;
            return;
        }
        on_sync(node, &sync);
    } else if (fn == MW_FN_CONFIG) {
        const uint8_t to = mw_can_id_node(frame->id);
        if (to != MW_NODE_ID_BROADCAST && to != node->config.node_id) {
            return; /* another node's CONFIG */
        }
        if (mw_config_decode(frame, &config) != MW_OK) {
            ++node->counters.malformed_frames;
            ++node->counters.configs_rejected;
            node->event_flags |= MW_ERRF_CONFIG_REJECTED;
            node->status_due = 1;
            return;
        }
        on_config(node, &config);
    }
    /* Everything else is other nodes' traffic. */
}

/* Frames that arrived while the node was bringing its sensor up (about 144 ms at power-on)
 * waited in the CAN controller's receive FIFO. A SYNC among them is not the present instant:
 * a sample read now and tagged with its counter would be a wrong sample that looks right
 * (found by the firmware-in-the-loop test of a node reset mid-stream). Such SYNCs are
 * dropped and counted; a CONFIG among them still applies. */
static void drop_waiting_syncs(sensor_node* node) {
    mw_can_frame frame;
    while (node->hal.can_receive(node->hal.user, &frame) == 1) {
        if (mw_can_id_function(frame.id) == MW_FN_SYNC) {
            ++node->counters.syncs_stale;
        } else {
            handle_frame(node, &frame);
        }
    }
}

void sensor_node_poll(sensor_node* node) {
    mw_can_frame frame;
    while (node->hal.can_receive(node->hal.user, &frame) == 1) {
        handle_frame(node, &frame);
    }
    if (node->hal.can_bus_error != NULL && node->hal.can_bus_error(node->hal.user)) {
        node->event_flags |= MW_ERRF_CAN_BUS;
    }
    const uint64_t now = now_us(node);
    if (node->state == MW_NODE_FAULT && now >= node->next_imu_retry_us) {
        if (init_imu(node)) {
            node->status_due = 1;
        }
        drop_waiting_syncs(node);
    }
    if (node->state == MW_NODE_RUNNING && node->config.rate_hz > 0u &&
        now - node->last_sync_us > (uint64_t)SENSOR_NODE_SYNC_TIMEOUT_PERIODS * US_PER_S / node->config.rate_hz) {
        node->state = MW_NODE_WAITING;
    }
    /* A STATUS goes out early for a new state, a changed condition or a new kind of event;
     * an event merely ending is reported by the next periodic STATUS. */
    const uint8_t persistent = persistent_flags(node);
    if (node->state != node->last_status_state || persistent != node->last_status_persistent ||
        (node->event_flags & (uint8_t)~node->last_status_flags) != 0u) {
        node->status_due = 1;
    }
    if (node->status_due || (node->config.status_period_s != 0u && now >= node->next_status_us)) {
        send_status(node);
    }
    flush_tx(node);
}
