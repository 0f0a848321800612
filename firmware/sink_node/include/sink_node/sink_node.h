/* Sink-node core: the portable part of the sink firmware (C99, no heap, no OS). The same core
 * runs on the STM32F407 sink and inside `mocap-sim stream` on Linux.
 *
 * What it does:
 * - SYNC: sends a SYNC frame (mocap_wire/mw_can.h) at config.rate_hz; SYNC n is due at
 *   start + n * 1e6 / rate_hz microseconds (no drift). The counter increments by one per
 *   SYNC and wraps at 2^32. If the loop stalls past several due times, the missed instants
 *   are skipped (counted in syncs_skipped), never sent in a burst.
 * - CONFIG: broadcasts config.node_config (node id 0) at start and every
 *   config.config_period_s, so nodes that reboot pick it up.
 * - Batching: every CAN frame received between SYNC n and SYNC n+1 goes into one sink->host
 *   packet (mocap_wire/mw_packet.h) whose timestamp_us is the time SYNC n was sent and whose
 *   first record is SYNC n itself (offset 0), followed by the frames in arrival order with
 *   offset_us = arrival - timestamp. The packet is closed when SYNC n+1 is sent, or earlier
 *   when it holds config.max_batch_frames frames (the rest of the instant then follows in a
 *   continuation packet with the same timestamp and no SYNC record), or when a frame arrives
 *   more than 65535 us after the timestamp (the continuation is stamped with that frame's
 *   time; only at rates below ~16 Hz). A packet goes out even if some nodes sent nothing
 *   (node loss is the host's to see).
 * - Early close: waiting for SYNC n+1 adds a whole sample period of latency. The core
 *   therefore remembers how many sample frames (ACCEL, GYRO, MAG, ATT; not STATUS) arrived
 *   during the previous complete instant and closes the packet of instant n as soon as
 *   instant n holds that many (counted in early_closes). Anything else that arrives before
 *   SYNC n+1 goes into a continuation packet (same timestamp, no SYNC record) closed by
 *   SYNC n+1. A node that drops out makes the instant fall short, so its packet waits for
 *   SYNC n+1 as before, and the next instant learns the smaller count; a node that comes
 *   back adds a continuation for one instant, then the larger count is learnt. The first
 *   instant after init has nothing to learn from and closes at the next SYNC. Deterministic:
 *   it depends only on the frames received. config.early_close = 0 restores the plain
 *   close-at-next-SYNC behaviour.
 *   Every status_period_s the sink's own STATUS (node id 0) is appended to the batch.
 * - Uplink: packets are written whole through the HAL. The packet sequence is per connection
 *   (0 for the first packet after a connect); a packet the uplink refused as busy still uses
 *   its sequence number, so the host sees the gap. While the uplink is down, packets are
 *   dropped and counted. After a drop or a failed attempt the next attempt waits
 *   backoff_min_us, doubling per failed attempt up to backoff_max_us; a successful connect
 *   resets it. An attempt still CONNECTING after connect_timeout_us is closed and failed.
 * - Host list and failover: config.host_count hosts, tried in order (uplink_connect gets the
 *   index; the HAL knows the addresses). A lost connection, a failed attempt or a silent host
 *   moves to the next host, wrapping; the back-off doubles only once every host has failed
 *   in turn, and with more than one host an attempt to a host waits at least host_retry_us
 *   (1 s) after the previous attempt to that same host, so a dead list is never hammered.
 * - Keepalive (stream version 2, docs/protocol.md §3.5): with uplink_read, the core reads what
 *   the host sends and decodes keepalives. Once it has received one keepalive (from any
 *   host, since init), a connection without a keepalive for keepalive_timeout_us (750 ms),
 *   or for three of the periods the connected host announces in its keepalives if that is
 *   longer (a period counts up to 60 s),
 *   is taken for a dead host: closed, counted, and the next host is tried. A sink that never
 *   heard one (version-1 hosts send none) never times out.
 *
 * HAL (libcanard style): a struct of function pointers plus one user pointer, filled by the
 * caller and copied at init. The core calls it only from sink_node_init() and
 * sink_node_poll(), from one thread; it never calls back into the core.
 *
 * Ownership: the caller allocates `sink_node` (about 4 KiB with the default
 * SINK_NODE_MAX_BATCH_FRAMES) and keeps it alive; nothing is allocated.
 * Threading: not thread-safe; one thread owns a sink_node (several independent instances
 * may run on one thread, as the simulator does).
 * Cost: sink_node_poll() is O(frames received + one packet encode when a batch closes).
 */
#ifndef MOCAP_SINK_NODE_SINK_NODE_H
#define MOCAP_SINK_NODE_SINK_NODE_H

#include <stddef.h>
#include <stdint.h>

#include "mocap_wire/mw_can.h"
#include "mocap_wire/mw_keepalive.h"
#include "mocap_wire/mw_packet.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Most frames one packet built by the sink holds (compile-time; config can lower it). */
#ifndef SINK_NODE_MAX_BATCH_FRAMES
#define SINK_NODE_MAX_BATCH_FRAMES 256u
#endif
#define SINK_NODE_PACKET_CAPACITY \
    (MW_PACKET_HEADER_SIZE + SINK_NODE_MAX_BATCH_FRAMES * MW_PACKET_RECORD_MAX + MW_PACKET_CRC_SIZE)
/* Most hosts in the ordered host list. */
#define SINK_NODE_MAX_HOSTS 8u
/* CAN frames (SYNC, CONFIG) the core holds while the controller's mailboxes are busy. */
#define SINK_NODE_CAN_TX_QUEUE_LEN 8u

typedef enum sink_uplink_state {
    SINK_UPLINK_DOWN = 0,       /* no connection and no attempt in progress */
    SINK_UPLINK_CONNECTING = 1, /* an attempt started by uplink_connect is in progress */
    SINK_UPLINK_UP = 2          /* connected; uplink_write may be called */
} sink_uplink_state;

typedef struct sink_node_hal {
    void* user; /* passed to every call */
    /* Offers one frame to the CAN controller: 0 = accepted, nonzero = mailboxes busy (the core
     * keeps it queued and offers it again on the next poll). */
    int (*can_transmit)(void* user, const mw_can_frame* frame);
    /* Takes one received frame: 1 = *frame filled, 0 = nothing pending. The core stamps it
     * with time_us() when it takes it. */
    int (*can_receive)(void* user, mw_can_frame* frame);
    /* Monotonic microseconds since an arbitrary origin. */
    uint64_t (*time_us)(void* user);
    /* Starts a connection attempt to host `host` (0..config.host_count-1, the ordered host
     * list; it may complete before returning): 0 = started or connected, negative = failed at
     * once. Called only when uplink_state() is DOWN. */
    int (*uplink_connect)(void* user, uint8_t host);
    /* Current connection state; the HAL reports a connection the peer dropped as DOWN. */
    sink_uplink_state (*uplink_state)(void* user);
    /* Writes one whole packet or nothing: 0 = taken, 1 = busy (the packet is dropped and
     * counted), negative = the connection failed (the core calls uplink_close). */
    int (*uplink_write)(void* user, const uint8_t* data, size_t len);
    /* Closes the connection or abandons the attempt; uplink_state() is DOWN afterwards. */
    void (*uplink_close)(void* user);
    /* Optional (may be NULL: no keepalive supervision, a stream-version-1 sink): takes up to
     * cap bytes the host sent, without blocking: >= 0 = bytes read (0 = none pending),
     * negative = the connection failed (the core closes it). Called only while UP. */
    int (*uplink_read)(void* user, uint8_t* data, size_t cap);
    /* Optional (may be NULL): CAN frames lost on reception so far (controller FIFO or driver
     * ring overruns), reported in the sink's STATUS. */
    uint32_t (*can_rx_lost)(void* user);
} sink_node_hal;

typedef struct sink_node_config {
    uint8_t sink_id;               /* written into every packet header */
    uint16_t rate_hz;              /* SYNC rate, MW_RATE_HZ_MIN..MW_RATE_HZ_MAX */
    uint32_t first_counter;        /* counter of the first SYNC (tests start near the wrap) */
    uint16_t max_batch_frames;     /* packet size limit in frames, 2..SINK_NODE_MAX_BATCH_FRAMES */
    uint32_t backoff_min_us;       /* first reconnect delay */
    uint32_t backoff_max_us;       /* largest reconnect delay */
    uint32_t connect_timeout_us;   /* a CONNECTING attempt older than this has failed */
    uint8_t status_period_s;       /* sink STATUS into the stream every N s, 0 = never */
    uint8_t config_period_s;       /* CONFIG broadcast every N s, 0 = only at start */
    mw_config node_config;         /* what the nodes are told (node_id is forced to 0) */
    uint8_t early_close;           /* 1 = close an instant's packet once it is complete (above) */
    uint8_t host_count;            /* hosts in the ordered list, 1..SINK_NODE_MAX_HOSTS */
    uint32_t host_retry_us;        /* with several hosts: least time between attempts to one host */
    uint32_t keepalive_timeout_us; /* no keepalive for this long (or for three announced periods,
                                      if longer) = dead host (0 = never) */
} sink_node_config;

/* Counters only go up (wrap at 2^32). */
typedef struct sink_node_counters {
    uint32_t frames_in;          /* CAN frames received */
    uint32_t frames_dropped;     /* received frames in packets that were not delivered */
    uint32_t packets_out;        /* packets the uplink took */
    uint32_t packets_dropped;    /* packets built while down, or refused as busy */
    uint32_t packets_busy;       /* of which refused as busy */
    uint32_t batch_splits;       /* packets closed early (max_batch_frames or offset_us range) */
    uint32_t bytes_out;          /* bytes the uplink took */
    uint32_t syncs_sent;         /* SYNC frames queued for the bus */
    uint32_t syncs_skipped;      /* SYNC instants skipped because the loop was late */
    uint32_t can_tx_overflows;   /* SYNC/CONFIG frames dropped, CAN TX queue full */
    uint32_t connect_attempts;   /* uplink_connect calls */
    uint32_t connect_failures;   /* attempts that failed or timed out */
    uint32_t connects;           /* attempts that reached UP */
    uint32_t reconnects;         /* connects after the first one */
    uint32_t disconnects;        /* UP -> DOWN transitions (peer drop, write error, keepalive time-out) */
    uint32_t early_closes;       /* packets closed before the next SYNC: instant complete */
    uint32_t keepalives_in;      /* valid keepalives received from hosts */
    uint32_t keepalive_timeouts; /* connections closed for want of a keepalive */
    uint32_t host_switches;      /* moves to the next host of the list */
} sink_node_counters;

typedef struct sink_node {
    sink_node_hal hal;
    sink_node_config config;
    sink_node_counters counters;
    /* SYNC schedule */
    uint64_t start_us;
    uint64_t sync_index;   /* index of the next SYNC since start */
    uint32_t next_counter; /* counter of the next SYNC */
    uint64_t next_config_us;
    uint64_t next_status_us;
    /* uplink */
    sink_uplink_state link; /* state seen at the last poll */
    uint64_t next_connect_us;
    uint64_t connect_started_us;
    uint32_t backoff_us;    /* delay before the next attempt */
    uint32_t sequence;      /* of the next packet on this connection */
    uint8_t host;           /* index of the host being tried or connected */
    uint8_t round_failures; /* failures in a row since the last connect, for the back-off */
    uint8_t keepalive_seen; /* a keepalive has been received since init: supervise */
    uint8_t host_tried[SINK_NODE_MAX_HOSTS];
    uint64_t host_attempt_us[SINK_NODE_MAX_HOSTS]; /* last attempt per host */
    uint64_t last_keepalive_us;                    /* on this connection (its start until the first) */
    uint32_t keepalive_period_us;                  /* announced on this connection (0 before the first) */
    mw_keepalive_decoder keepalives;
    /* batch */
    uint8_t batch_open;
    uint64_t batch_timestamp_us;
    uint32_t batch_node_frames;      /* received frames in the open batch (not SYNC/STATUS) */
    uint8_t instant_started;         /* a SYNC has been sent: later frames belong to its instant */
    uint8_t instant_closed_early;    /* this instant's packet has been closed early */
    uint32_t instant_sample_frames;  /* sample frames received since the last SYNC */
    uint32_t expected_sample_frames; /* sample frames of the previous complete instant */
    mw_packet_builder builder;
    uint8_t packet[SINK_NODE_PACKET_CAPACITY];
    /* CAN TX */
    mw_can_frame can_tx[SINK_NODE_CAN_TX_QUEUE_LEN];
    uint8_t can_tx_head;
    uint8_t can_tx_count;
    uint8_t can_tx_overflow_event; /* for the next sink STATUS */
    uint8_t reset_reported;        /* the first STATUS (MW_ERRF_RESET) has been built */
} sink_node;

/* Defaults: 100 Hz, 128 frames per packet, back-off 100 ms .. 5 s, connect timeout 10 s,
 * STATUS every 1 s, CONFIG every 1 s, nodes at +-16 g, +-2000 dps, raw mode, STATUS 1 s,
 * early close on, one host, 1 s between attempts to one host, keepalive time-out 750 ms. */
void sink_node_default_config(sink_node_config* config);

/* Validates the config, copies the HAL, starts the schedule (the first SYNC is due at once)
 * and the first connection attempt (at the first poll). Returns MW_OK, or MW_ERR_ARGUMENT
 * (NULL / missing HAL function) or MW_ERR_RANGE (a config field out of range). */
int sink_node_init(sink_node* sink, const sink_node_hal* hal, const sink_node_config* config);

/* Does everything due now: uplink attempts/time-outs, drains CAN RX into the batch, sends a
 * due SYNC (closing the batch first), CONFIG and STATUS, and offers queued CAN frames. */
void sink_node_poll(sink_node* sink);

/* Time at which the next poll has scheduled work (next SYNC, next connect attempt, or a
 * pending CAN frame: now). A caller without CAN interrupts may sleep until then, but frames
 * arriving meanwhile are stamped late. */
uint64_t sink_node_next_deadline_us(const sink_node* sink);

/* Counter of the next SYNC to be sent. */
uint32_t sink_node_next_counter(const sink_node* sink);

/* Queues a CONFIG for the nodes (node_id 0 = all) and makes it the periodic broadcast when
 * it is addressed to all. Returns MW_OK or the encoder's error (invalid fields). */
int sink_node_send_config(sink_node* sink, const mw_config* config);

#ifdef __cplusplus
}
#endif

#endif
