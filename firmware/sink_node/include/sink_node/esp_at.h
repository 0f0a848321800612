/* TCP uplink through an ESP8266 (or ESP32) running Espressif's AT firmware, over a serial
 * port. Portable C99, no heap: the sink's STM32 image uses it, and host tests drive it
 * against a scripted modem.
 *
 * It implements the sink core's uplink (sink_node_hal.uplink_*; esp_at_uplink() fills them):
 * - connect: the first time, and after the module lost Wi-Fi, runs the set-up script
 *   AT+RST (wait "ready"), ATE0, AT+UART_CUR=<baud> (optional), AT+CWMODE=1,
 *   AT+CWJAP="ssid","password", AT+CIPMUX=0; then AT+CIPSTART="TCP","host",port with the
 *   host of the list the sink core asks for (config.host, then config.more_hosts).
 * - write: AT+CIPSEND=<n>, waits for the '>' prompt, sends the n bytes, waits "SEND OK".
 *   One packet is in flight at a time; a write meanwhile returns 1 (busy).
 * - state: pumps the serial port (this is where all progress happens) and reports the link;
 *   an unsolicited "CLOSED" or "WIFI DISCONNECT" takes it DOWN.
 * - read: what the host sent (its keepalives), which the module delivers unsolicited as
 *   "+IPD,<n>:" followed by n raw bytes; they wait in a small buffer (ESP_AT_RX_MAX; more is
 *   dropped and counted) until the sink core reads them.
 * Every step has a time-out; a failed step takes the link DOWN and the sink core backs off.
 *
 * Threading: single context, like the sink core. Cost per state() call: O(bytes received +
 * bytes the serial port accepted).
 */
#ifndef MOCAP_SINK_NODE_ESP_AT_H
#define MOCAP_SINK_NODE_ESP_AT_H

#include <stddef.h>
#include <stdint.h>

#include "sink_node/sink_node.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Largest packet one AT+CIPSEND may carry (the AT firmware's limit). */
#define ESP_AT_MAX_PAYLOAD 2048u
#define ESP_AT_LINE_MAX 128u
#define ESP_AT_COMMAND_MAX 160u
/* Host -> sink bytes held until read: several keepalives (16 bytes each). */
#define ESP_AT_RX_MAX 128u

/* Serial port: non-blocking, caller-owned. */
typedef struct esp_at_serial {
    void* user;
    /* Queues up to len bytes for transmission; returns how many were taken (may be 0). */
    size_t (*write)(void* user, const uint8_t* data, size_t len);
    /* Takes up to cap received bytes; returns how many (0 = none pending). */
    size_t (*read)(void* user, uint8_t* data, size_t cap);
    /* Changes the port's baud rate after the bytes already queued have left the wire (called
     * after the module acknowledged AT+UART_CUR, and after AT+RST, to return to 115200); may
     * be NULL when config.baud is 0. */
    void (*set_baud)(void* user, uint32_t baud);
    uint64_t (*time_us)(void* user);
} esp_at_serial;

typedef struct esp_at_config {
    const char* ssid; /* must stay valid while the client lives */
    const char* password;
    const char* host; /* host name or dotted IPv4 address of mocapd: host 0 of the list */
    uint16_t port;    /* mocapd's sink port (7000) */
    uint32_t baud;    /* switch the link to this rate after reset (0 = stay at 115200) */
    /* Further hosts of the ordered list (sink core host 1..more_count), e.g. a second mocapd
     * to fail over to; more_count 0 = none. The arrays must stay valid while the client lives. */
    uint8_t more_count;
    const char* const* more_hosts;
    const uint16_t* more_ports;
} esp_at_config;

typedef struct esp_at_counters {
    uint32_t resets;         /* set-up scripts started */
    uint32_t timeouts;       /* steps that timed out */
    uint32_t errors;         /* steps answered with ERROR / FAIL */
    uint32_t link_closed;    /* unsolicited CLOSED / WIFI DISCONNECT */
    uint32_t packets_sent;   /* SEND OK */
    uint32_t overlong_lines; /* response lines cut at ESP_AT_LINE_MAX */
    uint32_t rx_bytes;       /* host -> sink bytes received (+IPD) */
    uint32_t rx_dropped;     /* of which dropped: the read buffer was full */
} esp_at_counters;

typedef struct esp_at {
    esp_at_serial serial;
    esp_at_config config;
    esp_at_counters counters;
    sink_uplink_state link;
    uint8_t wifi_ready;        /* set-up script completed; only CIPSTART is needed */
    uint8_t host;              /* private: list index of the host of the current attempt */
    uint8_t step;              /* private: current script step */
    uint8_t at_line_start;     /* private: the next byte starts a response line */
    uint64_t deadline_us;      /* private: time-out of the current step */
    uint32_t baud_after_flush; /* private: port rate to set once the queued bytes are out */
    char line[ESP_AT_LINE_MAX];
    size_t line_len;
    uint8_t out[ESP_AT_COMMAND_MAX + ESP_AT_MAX_PAYLOAD]; /* private: bytes not yet taken by the port */
    size_t out_len;
    size_t out_sent;
    uint8_t payload[ESP_AT_MAX_PAYLOAD];
    size_t payload_len;
    uint32_t ipd_left; /* private: raw +IPD bytes still to come */
    uint8_t rx[ESP_AT_RX_MAX];
    size_t rx_len;
} esp_at;

/* Validates and copies the serial port and config. MW_OK or MW_ERR_ARGUMENT. */
int esp_at_init(esp_at* at, const esp_at_serial* serial, const esp_at_config* config);

/* The sink core's uplink calls; `user` is the esp_at. */
int esp_at_connect(void* user, uint8_t host);
sink_uplink_state esp_at_state(void* user);
int esp_at_write(void* user, const uint8_t* data, size_t len);
void esp_at_close(void* user);
int esp_at_read(void* user, uint8_t* data, size_t cap);

/* Fills the uplink members of a sink HAL with the functions above. The sink HAL has one user
 * pointer, so the caller's CAN/time functions must reach their own state another way (the
 * STM32 image uses file-scope state); hal->user is set to `at`. */
void esp_at_uplink(esp_at* at, sink_node_hal* hal);

#ifdef __cplusplus
}
#endif

#endif
