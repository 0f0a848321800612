/* Sink-node core. Design notes:
 * - The SYNC schedule is computed from the SYNC index, not by adding a rounded period, so
 *   rates that do not divide one second (e.g. 120 Hz) do not drift against the host clock.
 * - A batch is closed by the next SYNC rather than by a timer: the nodes answer each SYNC
 *   within a fraction of a period, so "everything until the next SYNC" is one instant, and
 *   a missing node can never hold a packet back.
 * - Early close (header): the previous instant's sample-frame count predicts this one's, so
 *   a complete instant leaves at once instead of one period later; a short instant (node
 *   loss) still ends at the next SYNC, so a missing node never holds a packet back longer
 *   than before.
 * - Packets are built in place with the wire library's builder as frames arrive, so closing
 *   a batch costs only the CRC; the uplink takes the finished bytes or refuses them whole. */
#include "sink_node/sink_node.h"

#define US_PER_S 1000000u

static uint64_t now_us(const sink_node* sink) {
    return sink->hal.time_us(sink->hal.user);
}

void sink_node_default_config(sink_node_config* config) {
    const sink_node_config zero = {0};
    *config = zero;
    config->sink_id = 1;
    config->rate_hz = 100;
    config->first_counter = 0;
    config->max_batch_frames = 128;
    config->backoff_min_us = 100000u;
    config->backoff_max_us = 5000000u;
    config->connect_timeout_us = 10000000u;
    config->status_period_s = 1;
    config->config_period_s = 1;
    config->node_config.node_id = MW_NODE_ID_BROADCAST;
    config->node_config.rate_hz = 100;
    config->node_config.accel_range = MW_ACCEL_16G;
    config->node_config.gyro_range = MW_GYRO_2000DPS;
    config->node_config.mode = MW_MODE_RAW;
    config->node_config.status_period_s = 1;
    config->early_close = 1;
    config->host_count = 1;
    config->host_retry_us = 1000000u;
    config->keepalive_timeout_us = 750000u;
}

/* ---- CAN transmit queue ------------------------------------------------------------------ */

static void queue_can(sink_node* sink, const mw_can_frame* frame) {
    if (sink->can_tx_count >= SINK_NODE_CAN_TX_QUEUE_LEN) {
        ++sink->counters.can_tx_overflows;
        sink->can_tx_overflow_event = 1;
        return;
    }
    const unsigned tail = (sink->can_tx_head + sink->can_tx_count) % SINK_NODE_CAN_TX_QUEUE_LEN;
    sink->can_tx[tail] = *frame;
    ++sink->can_tx_count;
}

static void flush_can(sink_node* sink) {
    while (sink->can_tx_count > 0u) {
        if (sink->hal.can_transmit(sink->hal.user, &sink->can_tx[sink->can_tx_head]) != 0) {
            return;
        }
        sink->can_tx_head = (uint8_t)((sink->can_tx_head + 1u) % SINK_NODE_CAN_TX_QUEUE_LEN);
        --sink->can_tx_count;
    }
}

/* ---- uplink --------------------------------------------------------------------------------- */

/* After a failure: the next host of the list, after the back-off (and, with several hosts,
 * not sooner than host_retry_us after the last attempt to that host). The back-off doubles
 * once every host has failed in turn, so one dead host does not slow the move to the next. */
static void schedule_retry(sink_node* sink, uint64_t now) {
    const uint8_t count = sink->config.host_count;
    uint64_t at = now + sink->backoff_us;
    if (count > 1u) {
        sink->host = (uint8_t)((sink->host + 1u) % count);
        ++sink->counters.host_switches;
        if (sink->host_tried[sink->host]) {
            const uint64_t spaced = sink->host_attempt_us[sink->host] + sink->config.host_retry_us;
            if (spaced > at) {
                at = spaced;
            }
        }
    }
    sink->next_connect_us = at;
    if (++sink->round_failures >= count) {
        sink->round_failures = 0;
        const uint64_t doubled = 2u * (uint64_t)sink->backoff_us;
        sink->backoff_us = doubled > sink->config.backoff_max_us ? sink->config.backoff_max_us : (uint32_t)doubled;
    }
}

static void link_lost(sink_node* sink, uint64_t now) {
    ++sink->counters.disconnects;
    sink->link = SINK_UPLINK_DOWN;
    sink->backoff_us = sink->config.backoff_min_us;
    sink->round_failures = 0;
    schedule_retry(sink, now);
}

static void attempt_failed(sink_node* sink, uint64_t now) {
    ++sink->counters.connect_failures;
    sink->link = SINK_UPLINK_DOWN;
    schedule_retry(sink, now);
}

enum { SINK_KEEPALIVE_PERIOD_MAX_MS = 60000 };

/* How long a connection may go without a keepalive: the configured time-out, stretched to
 * three periods of a host that announces a slower keepalive than the time-out expects. */
static uint64_t keepalive_timeout_us(const sink_node* sink) {
    const uint64_t announced = 3u * (uint64_t)sink->keepalive_period_us;
    return announced > sink->config.keepalive_timeout_us ? announced : sink->config.keepalive_timeout_us;
}

/* Reads what the host sent (bounded per poll) and judges its keepalives. Returns 0 when the
 * connection was closed here. */
static int supervise_host(sink_node* sink, uint64_t now) {
    if (sink->hal.uplink_read == NULL) {
        return 1;
    }
    uint8_t buf[64];
    for (unsigned reads = 0; reads < 8u; ++reads) {
        const int n = sink->hal.uplink_read(sink->hal.user, buf, sizeof buf);
        if (n < 0) {
            sink->hal.uplink_close(sink->hal.user);
            link_lost(sink, now);
            return 0;
        }
        if (n == 0) {
            break;
        }
        const uint8_t* p = buf;
        size_t left = (size_t)n;
        for (;;) {
            size_t used = 0;
            mw_keepalive keepalive;
            const mw_stream_result r = mw_keepalive_decoder_feed(&sink->keepalives, p, left, &used, &keepalive);
            p += used;
            left -= used;
            if (r == MW_STREAM_NEED_MORE) {
                break;
            }
            if (r == MW_STREAM_PACKET) {
                ++sink->counters.keepalives_in;
                sink->keepalive_seen = 1;
                sink->last_keepalive_us = now;
                /* A host may not stretch the time-out without bound: 60 s at most, as mocapd's
                 * [ingest] keepalive_period_s. */
                sink->keepalive_period_us =
                    (uint32_t)(keepalive.period_ms < SINK_KEEPALIVE_PERIOD_MAX_MS ? keepalive.period_ms
                                                                                  : SINK_KEEPALIVE_PERIOD_MAX_MS) *
                    1000u;
            }
        }
    }
    if (sink->keepalive_seen && sink->config.keepalive_timeout_us != 0u &&
        now - sink->last_keepalive_us > keepalive_timeout_us(sink)) {
        ++sink->counters.keepalive_timeouts;
        sink->hal.uplink_close(sink->hal.user);
        link_lost(sink, now);
        return 0;
    }
    return 1;
}

static void manage_uplink(sink_node* sink, uint64_t now) {
    const sink_uplink_state state = sink->hal.uplink_state(sink->hal.user);
    if (state == SINK_UPLINK_UP && sink->link != SINK_UPLINK_UP) {
        if (sink->counters.connects > 0u) {
            ++sink->counters.reconnects;
        }
        ++sink->counters.connects;
        sink->link = SINK_UPLINK_UP;
        sink->sequence = 0;
        sink->backoff_us = sink->config.backoff_min_us;
        sink->round_failures = 0;
        sink->last_keepalive_us = now;
        sink->keepalive_period_us = 0; /* this host's own announcement counts, not the last one's */
        mw_keepalive_decoder_init(&sink->keepalives);
        return;
    }
    if (state == SINK_UPLINK_UP) {
        (void)supervise_host(sink, now);
        return;
    }
    if (state == SINK_UPLINK_DOWN) {
        if (sink->link == SINK_UPLINK_UP) {
            link_lost(sink, now);
        } else if (sink->link == SINK_UPLINK_CONNECTING) {
            attempt_failed(sink, now);
        }
        if (now >= sink->next_connect_us) {
            ++sink->counters.connect_attempts;
            sink->connect_started_us = now;
            sink->host_tried[sink->host] = 1;
            sink->host_attempt_us[sink->host] = now;
            if (sink->hal.uplink_connect(sink->hal.user, sink->host) < 0) {
                attempt_failed(sink, now);
                return;
            }
            sink->link = SINK_UPLINK_CONNECTING;
            manage_uplink(sink, now); /* a connect that completed at once is UP now */
        }
        return;
    }
    if (state == SINK_UPLINK_CONNECTING) {
        sink->link = SINK_UPLINK_CONNECTING;
        if (now - sink->connect_started_us > sink->config.connect_timeout_us) {
            sink->hal.uplink_close(sink->hal.user);
            attempt_failed(sink, now);
        }
    }
}

/* ---- batches -------------------------------------------------------------------------------- */

static void open_batch(sink_node* sink, uint64_t timestamp_us) {
    mw_packet_header header;
    header.sink_id = sink->config.sink_id;
    header.sequence = sink->sequence;
    header.timestamp_us = timestamp_us;
    (void)mw_packet_builder_begin(&sink->builder, sink->packet, sizeof sink->packet, &header);
    sink->batch_open = 1;
    sink->batch_timestamp_us = timestamp_us;
    sink->batch_node_frames = 0;
}

static void close_batch(sink_node* sink, uint64_t now) {
    if (!sink->batch_open) {
        return;
    }
    sink->batch_open = 0;
    /* The connection may have changed since the batch was opened: the header must carry the
     * sequence of the connection it goes out on (bytes 10..13, little-endian, mw_packet.h). */
    for (unsigned i = 0; i < 4u; ++i) {
        sink->packet[10u + i] = (uint8_t)(sink->sequence >> (8u * i));
    }
    const int32_t len = mw_packet_builder_finish(&sink->builder);
    if (len <= 0) {
        return;
    }
    if (sink->link != SINK_UPLINK_UP) {
        ++sink->counters.packets_dropped;
        sink->counters.frames_dropped += sink->batch_node_frames;
        return;
    }
    ++sink->sequence; /* used even if refused: the host sees the gap */
    const int rc = sink->hal.uplink_write(sink->hal.user, sink->packet, (size_t)len);
    if (rc == 0) {
        ++sink->counters.packets_out;
        sink->counters.bytes_out += (uint32_t)len;
        return;
    }
    ++sink->counters.packets_dropped;
    sink->counters.frames_dropped += sink->batch_node_frames;
    if (rc > 0) {
        ++sink->counters.packets_busy;
    } else {
        sink->hal.uplink_close(sink->hal.user);
        link_lost(sink, now);
    }
}

/* Appends a record; a full batch is closed and continued with the same timestamp. */
static void add_to_batch(sink_node* sink, const mw_can_frame* frame, uint64_t at_us, int node_frame) {
    if (!sink->batch_open) {
        /* After an early close, later frames of the instant continue it (same timestamp). */
        open_batch(sink, sink->instant_started ? sink->batch_timestamp_us : at_us);
    }
    if (sink->builder.frame_count >= sink->config.max_batch_frames) {
        const uint64_t timestamp = sink->batch_timestamp_us;
        ++sink->counters.batch_splits;
        close_batch(sink, at_us);
        open_batch(sink, timestamp);
    }
    if (at_us - sink->batch_timestamp_us > 0xFFFFu) {
        /* offset_us is 16 bits: at low rates a batch outlives it; continue in a packet
         * stamped with this frame's time (docs/protocol.md §3.4). */
        ++sink->counters.batch_splits;
        close_batch(sink, at_us);
        open_batch(sink, at_us);
    }
    mw_stamped_frame stamped;
    stamped.offset_us = (uint16_t)(at_us - sink->batch_timestamp_us);
    stamped.frame = *frame;
    if (mw_packet_builder_add(&sink->builder, &stamped) == MW_OK && node_frame) {
        ++sink->batch_node_frames;
    }
}

/* ---- periodic frames ------------------------------------------------------------------------ */

static uint64_t sync_due_us(const sink_node* sink, uint64_t index) {
    return sink->start_us + index * US_PER_S / sink->config.rate_hz;
}

static int is_sample_frame(const mw_can_frame* frame) {
    const mw_function fn = mw_can_id_function(frame->id);
    return fn == MW_FN_ACCEL || fn == MW_FN_GYRO || fn == MW_FN_MAG || fn == MW_FN_ATTITUDE;
}

/* A received node frame: batch it, and close the packet when the instant is complete. */
static void receive_frame(sink_node* sink, const mw_can_frame* frame, uint64_t at_us) {
    add_to_batch(sink, frame, at_us, 1);
    if (!sink->instant_started || !is_sample_frame(frame)) {
        return;
    }
    ++sink->instant_sample_frames;
    if (sink->config.early_close && !sink->instant_closed_early && sink->expected_sample_frames > 0u &&
        sink->instant_sample_frames == sink->expected_sample_frames) {
        sink->instant_closed_early = 1;
        ++sink->counters.early_closes;
        close_batch(sink, at_us);
    }
}

static void send_sync(sink_node* sink, uint64_t now) {
    const mw_sync sync = {sink->next_counter};
    mw_can_frame frame;
    close_batch(sink, now);
    if (sink->instant_started) {
        sink->expected_sample_frames = sink->instant_sample_frames;
    }
    sink->instant_started = 1;
    sink->instant_closed_early = 0;
    sink->instant_sample_frames = 0;
    (void)mw_sync_encode(&sync, &frame);
    queue_can(sink, &frame);
    ++sink->counters.syncs_sent;
    ++sink->next_counter; /* wraps at 2^32 as the wire format says */
    open_batch(sink, now);
    add_to_batch(sink, &frame, now, 0);
}

static void send_status(sink_node* sink, uint64_t now) {
    mw_status status;
    mw_can_frame frame;
    status.node_id = MW_NODE_ID_SINK;
    status.state = sink->link == SINK_UPLINK_UP ? MW_NODE_RUNNING : MW_NODE_WAITING;
    status.mode = sink->config.node_config.mode;
    status.mag_present = false;
    status.accel_range = sink->config.node_config.accel_range;
    status.gyro_range = sink->config.node_config.gyro_range;
    status.error_flags = sink->can_tx_overflow_event ? MW_ERRF_CAN_TX_OVERFLOW : 0u;
    if (!sink->reset_reported) {
        status.error_flags |= MW_ERRF_RESET;
    }
    status.protocol_version = MW_CAN_PROTOCOL_VERSION;
    status.uptime_s = (uint16_t)((now - sink->start_us) / US_PER_S);
    /* For the sink this field counts CAN frames lost on reception (docs/protocol.md §1.6). */
    status.tx_overflows = (uint8_t)(sink->hal.can_rx_lost != NULL ? sink->hal.can_rx_lost(sink->hal.user) : 0u);
    status.sync_missed = 0;
    if (mw_status_encode(&status, &frame) == MW_OK) {
        sink->can_tx_overflow_event = 0;
        sink->reset_reported = 1;
        add_to_batch(sink, &frame, now, 0);
    }
}

int sink_node_send_config(sink_node* sink, const mw_config* config) {
    mw_can_frame frame;
    const int rc = mw_config_encode(config, &frame);
    if (rc != MW_OK) {
        return rc;
    }
    queue_can(sink, &frame);
    if (config->node_id == MW_NODE_ID_BROADCAST) {
        sink->config.node_config = *config;
    }
    return MW_OK;
}

/* ---- public --------------------------------------------------------------------------------- */

int sink_node_init(sink_node* sink, const sink_node_hal* hal, const sink_node_config* config) {
    if (sink == NULL || hal == NULL || config == NULL || hal->can_transmit == NULL || hal->can_receive == NULL ||
        hal->time_us == NULL || hal->uplink_connect == NULL || hal->uplink_state == NULL || hal->uplink_write == NULL ||
        hal->uplink_close == NULL) {
        return MW_ERR_ARGUMENT;
    }
    if (config->rate_hz < MW_RATE_HZ_MIN || config->rate_hz > MW_RATE_HZ_MAX || config->max_batch_frames < 2u ||
        config->max_batch_frames > SINK_NODE_MAX_BATCH_FRAMES || config->backoff_min_us == 0u ||
        config->backoff_max_us < config->backoff_min_us || config->host_count == 0u ||
        config->host_count > SINK_NODE_MAX_HOSTS) {
        return MW_ERR_RANGE;
    }
    mw_can_frame probe;
    mw_config node_config = config->node_config;
    node_config.node_id = MW_NODE_ID_BROADCAST;
    if (mw_config_encode(&node_config, &probe) != MW_OK) {
        return MW_ERR_RANGE;
    }
    /* Field by field: the struct is large and holds the packet buffer. */
    const sink_node_counters zero_counters = {0};
    sink->hal = *hal;
    sink->config = *config;
    sink->config.node_config = node_config;
    sink->counters = zero_counters;
    sink->start_us = now_us(sink);
    sink->sync_index = 0;
    sink->next_counter = config->first_counter;
    sink->next_config_us = sink->start_us;
    sink->next_status_us = sink->start_us;
    sink->link = SINK_UPLINK_DOWN;
    sink->next_connect_us = sink->start_us;
    sink->connect_started_us = 0;
    sink->backoff_us = config->backoff_min_us;
    sink->sequence = 0;
    sink->host = 0;
    sink->round_failures = 0;
    sink->keepalive_seen = 0;
    for (unsigned i = 0; i < SINK_NODE_MAX_HOSTS; ++i) {
        sink->host_tried[i] = 0;
        sink->host_attempt_us[i] = 0;
    }
    sink->last_keepalive_us = 0;
    sink->keepalive_period_us = 0;
    mw_keepalive_decoder_init(&sink->keepalives);
    sink->batch_open = 0;
    sink->batch_timestamp_us = 0;
    sink->batch_node_frames = 0;
    sink->instant_started = 0;
    sink->instant_closed_early = 0;
    sink->instant_sample_frames = 0;
    sink->expected_sample_frames = 0;
    sink->can_tx_head = 0;
    sink->can_tx_count = 0;
    sink->can_tx_overflow_event = 0;
    sink->reset_reported = 0;
    return MW_OK;
}

void sink_node_poll(sink_node* sink) {
    uint64_t now = now_us(sink);
    manage_uplink(sink, now);

    mw_can_frame frame;
    while (sink->hal.can_receive(sink->hal.user, &frame) == 1) {
        ++sink->counters.frames_in;
        receive_frame(sink, &frame, now_us(sink));
    }

    now = now_us(sink);
    if (now >= sync_due_us(sink, sink->sync_index)) {
        /* Skip instants the loop was too late for: one SYNC now, the schedule stays. */
        uint64_t next = sink->sync_index + 1u;
        while (now >= sync_due_us(sink, next)) {
            ++sink->counters.syncs_skipped;
            ++next;
        }
        sink->sync_index = next;
        send_sync(sink, now);
    }
    if (now >= sink->next_config_us) {
        (void)sink_node_send_config(sink, &sink->config.node_config);
        sink->next_config_us =
            sink->config.config_period_s != 0u ? now + (uint64_t)sink->config.config_period_s * US_PER_S : UINT64_MAX;
    }
    if (sink->config.status_period_s != 0u && now >= sink->next_status_us) {
        send_status(sink, now);
        sink->next_status_us = now + (uint64_t)sink->config.status_period_s * US_PER_S;
    }
    flush_can(sink);
}

uint64_t sink_node_next_deadline_us(const sink_node* sink) {
    if (sink->can_tx_count > 0u) {
        return now_us(sink);
    }
    uint64_t deadline = sync_due_us(sink, sink->sync_index);
    if (sink->link == SINK_UPLINK_DOWN && sink->next_connect_us < deadline) {
        deadline = sink->next_connect_us;
    }
    if (sink->link == SINK_UPLINK_UP && sink->keepalive_seen && sink->config.keepalive_timeout_us != 0u) {
        const uint64_t silent_at = sink->last_keepalive_us + keepalive_timeout_us(sink) + 1u;
        if (silent_at < deadline) {
            deadline = silent_at;
        }
    }
    if (sink->next_config_us < deadline) {
        deadline = sink->next_config_us;
    }
    return deadline;
}

uint32_t sink_node_next_counter(const sink_node* sink) {
    return sink->next_counter;
}
