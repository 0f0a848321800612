/* ESP8266 AT-command uplink. Why it is shaped this way:
 * - Everything is a non-blocking state machine pumped from esp_at_state(), because the sink
 *   core must keep sending SYNC while the module joins Wi-Fi (seconds) or sends a packet.
 * - AT+UART_CUR is not persistent, so after AT+RST the port goes back to 115200 baud, the
 *   rate the module boots with.
 * - Responses are matched as whole lines; the CIPSEND prompt "> " has no line end, so a '>'
 *   at the start of a line is taken as the prompt only while one is expected.
 * - Received data ("+IPD,<n>:" and n raw bytes) is cut out of the line stream by its count,
 *   since the bytes may contain anything, line ends included. */
#include "sink_node/esp_at.h"

#define BOOT_BAUD 115200u
#define TIMEOUT_RESET_US 5000000u
#define TIMEOUT_COMMAND_US 1000000u
#define TIMEOUT_JOIN_US 20000000u
#define TIMEOUT_START_US 10000000u
#define TIMEOUT_SEND_US 2000000u

enum {
    STEP_IDLE = 0,
    STEP_RESET,
    STEP_ECHO_OFF,
    STEP_BAUD,
    STEP_MODE,
    STEP_JOIN,
    STEP_MUX,
    STEP_START,
    STEP_SEND_PROMPT,
    STEP_SEND_DATA
};

static uint64_t now_us(const esp_at* at) {
    return at->serial.time_us(at->serial.user);
}

/* ---- output --------------------------------------------------------------------------------- */

static void out_reset(esp_at* at) {
    at->out_len = 0;
    at->out_sent = 0;
}

static void out_bytes(esp_at* at, const uint8_t* data, size_t len) {
    for (size_t i = 0; i < len && at->out_len < sizeof at->out; ++i) {
        at->out[at->out_len++] = data[i];
    }
}

static void out_str(esp_at* at, const char* s) {
    while (*s != '\0' && at->out_len < sizeof at->out) {
        at->out[at->out_len++] = (uint8_t)*s++;
    }
}

/* A quoted AT string argument: '"', ',' and '\' are escaped with a backslash. */
static void out_quoted(esp_at* at, const char* s) {
    out_str(at, "\"");
    for (; *s != '\0'; ++s) {
        if (*s == '"' || *s == ',' || *s == '\\') {
            out_str(at, "\\");
        }
        const uint8_t c = (uint8_t)*s;
        out_bytes(at, &c, 1u);
    }
    out_str(at, "\"");
}

static void out_u32(esp_at* at, uint32_t v) {
    char digits[10];
    unsigned n = 0;
    do {
        digits[n++] = (char)('0' + (v % 10u));
        v /= 10u;
    } while (v != 0u);
    while (n > 0u) {
        const uint8_t c = (uint8_t)digits[--n];
        out_bytes(at, &c, 1u);
    }
}

static void pump_out(esp_at* at) {
    if (at->out_sent < at->out_len) {
        at->out_sent += at->serial.write(at->serial.user, at->out + at->out_sent, at->out_len - at->out_sent);
    }
    if (at->out_sent == at->out_len) {
        out_reset(at);
        if (at->baud_after_flush != 0u) {
            at->serial.set_baud(at->serial.user, at->baud_after_flush);
            at->baud_after_flush = 0;
        }
    }
}

/* ---- script --------------------------------------------------------------------------------- */

static void begin_step(esp_at* at, uint8_t step, uint32_t timeout_us) {
    at->step = step;
    at->deadline_us = now_us(at) + timeout_us;
    switch (step) {
        case STEP_RESET:
            out_str(at, "AT+RST\r\n");
            break;
        case STEP_ECHO_OFF:
            out_str(at, "ATE0\r\n");
            break;
        case STEP_BAUD:
            out_str(at, "AT+UART_CUR=");
            out_u32(at, at->config.baud);
            out_str(at, ",8,1,0,0\r\n");
            break;
        case STEP_MODE:
            out_str(at, "AT+CWMODE=1\r\n");
            break;
        case STEP_JOIN:
            out_str(at, "AT+CWJAP=");
            out_quoted(at, at->config.ssid);
            out_str(at, ",");
            out_quoted(at, at->config.password);
            out_str(at, "\r\n");
            break;
        case STEP_MUX:
            out_str(at, "AT+CIPMUX=0\r\n");
            break;
        case STEP_START:
            out_str(at, "AT+CIPSTART=\"TCP\",");
            out_quoted(at, at->host == 0u ? at->config.host : at->config.more_hosts[at->host - 1u]);
            out_str(at, ",");
            out_u32(at, at->host == 0u ? at->config.port : at->config.more_ports[at->host - 1u]);
            out_str(at, "\r\n");
            break;
        case STEP_SEND_PROMPT:
            out_str(at, "AT+CIPSEND=");
            out_u32(at, (uint32_t)at->payload_len);
            out_str(at, "\r\n");
            break;
        case STEP_SEND_DATA:
            out_bytes(at, at->payload, at->payload_len);
            break;
        default:
            break;
    }
}

static void start_reset(esp_at* at) {
    ++at->counters.resets;
    at->wifi_ready = 0;
    out_reset(at);
    /* AT+RST goes out at the rate the module was last set to; the module then boots at
     * 115200, so the port follows once the command has left. (A module that rebooted on its
     * own is already at 115200: that attempt times out and the next one, now at 115200, works.) */
    begin_step(at, STEP_RESET, TIMEOUT_RESET_US);
    if (at->config.baud != 0u) {
        at->baud_after_flush = BOOT_BAUD;
    }
}

static int in_setup(const esp_at* at) {
    return at->step >= STEP_RESET && at->step <= STEP_MUX;
}

static void fail(esp_at* at) {
    if (in_setup(at)) {
        at->wifi_ready = 0;
    }
    at->step = STEP_IDLE;
    at->link = SINK_UPLINK_DOWN;
    at->payload_len = 0;
    at->ipd_left = 0;
    at->rx_len = 0;
    out_reset(at);
}

static void next_setup_step(esp_at* at) {
    switch (at->step) {
        case STEP_RESET:
            begin_step(at, STEP_ECHO_OFF, TIMEOUT_COMMAND_US);
            break;
        case STEP_ECHO_OFF:
            if (at->config.baud != 0u) {
                begin_step(at, STEP_BAUD, TIMEOUT_COMMAND_US);
            } else {
                begin_step(at, STEP_MODE, TIMEOUT_COMMAND_US);
            }
            break;
        case STEP_BAUD:
            at->serial.set_baud(at->serial.user, at->config.baud);
            begin_step(at, STEP_MODE, TIMEOUT_COMMAND_US);
            break;
        case STEP_MODE:
            begin_step(at, STEP_JOIN, TIMEOUT_JOIN_US);
            break;
        case STEP_JOIN:
            begin_step(at, STEP_MUX, TIMEOUT_COMMAND_US);
            break;
        case STEP_MUX:
            at->wifi_ready = 1;
            begin_step(at, STEP_START, TIMEOUT_START_US);
            break;
        default:
            break;
    }
}

/* ---- input ---------------------------------------------------------------------------------- */

static int line_is(const esp_at* at, const char* s) {
    size_t i = 0;
    for (; s[i] != '\0'; ++i) {
        if (i >= at->line_len || at->line[i] != s[i]) {
            return 0;
        }
    }
    return i == at->line_len;
}

static int line_ends_with(const esp_at* at, const char* s) {
    size_t n = 0;
    while (s[n] != '\0') {
        ++n;
    }
    if (n > at->line_len) {
        return 0;
    }
    for (size_t i = 0; i < n; ++i) {
        if (at->line[at->line_len - n + i] != s[i]) {
            return 0;
        }
    }
    return 1;
}

static void on_line(esp_at* at) {
    const int error = line_is(at, "ERROR") || line_is(at, "FAIL");
    if (line_ends_with(at, "CLOSED")) { /* "CLOSED" or "<id>,CLOSED" */
        if (at->link != SINK_UPLINK_DOWN) {
            ++at->counters.link_closed;
            fail(at);
        }
        return;
    }
    if (line_is(at, "WIFI DISCONNECT") && at->step != STEP_JOIN && !in_setup(at)) {
        at->wifi_ready = 0;
        if (at->link != SINK_UPLINK_DOWN) {
            ++at->counters.link_closed;
            fail(at);
        }
        return;
    }
    switch (at->step) {
        case STEP_RESET:
            if (line_is(at, "ready")) {
                next_setup_step(at);
            }
            break;
        case STEP_ECHO_OFF:
        case STEP_BAUD:
        case STEP_MODE:
        case STEP_JOIN:
        case STEP_MUX:
            if (line_is(at, "OK")) {
                next_setup_step(at);
            } else if (error) {
                ++at->counters.errors;
                fail(at);
            }
            break;
        case STEP_START:
            if (line_is(at, "OK") || line_is(at, "ALREADY CONNECTED")) {
                at->step = STEP_IDLE;
                at->link = SINK_UPLINK_UP;
            } else if (error) {
                ++at->counters.errors;
                fail(at);
            }
            break;
        case STEP_SEND_PROMPT:
        case STEP_SEND_DATA:
            if (line_is(at, "SEND OK")) {
                ++at->counters.packets_sent;
                at->payload_len = 0;
                at->step = STEP_IDLE;
            } else if (error || line_is(at, "SEND FAIL")) {
                ++at->counters.errors;
                fail(at);
            }
            break;
        default:
            break;
    }
}

/* "+IPD,<n>" is in the line and ':' arrived: n raw bytes follow. */
static int start_ipd(esp_at* at) {
    static const char prefix[] = "+IPD,";
    const size_t plen = sizeof prefix - 1u;
    if (at->line_len <= plen || at->line_len > sizeof at->line) {
        return 0;
    }
    for (size_t i = 0; i < plen; ++i) {
        if (at->line[i] != prefix[i]) {
            return 0;
        }
    }
    uint32_t n = 0;
    for (size_t i = plen; i < at->line_len; ++i) {
        if (at->line[i] < '0' || at->line[i] > '9' || n > 100000u) {
            return 0;
        }
        n = n * 10u + (uint32_t)(at->line[i] - '0');
    }
    at->ipd_left = n;
    at->line_len = 0;
    return 1;
}

static void on_byte(esp_at* at, uint8_t c) {
    if (at->ipd_left > 0u) {
        --at->ipd_left;
        ++at->counters.rx_bytes;
        if (at->rx_len < sizeof at->rx) {
            at->rx[at->rx_len++] = c;
        } else {
            ++at->counters.rx_dropped;
        }
        if (at->ipd_left == 0u) {
            at->at_line_start = 1;
        }
        return;
    }
    if (c == ':' && start_ipd(at)) {
        at->at_line_start = 0;
        return;
    }
    if (at->step == STEP_SEND_PROMPT && at->at_line_start && c == '>') {
        begin_step(at, STEP_SEND_DATA, TIMEOUT_SEND_US);
        at->at_line_start = 0;
        return;
    }
    if (c == '\n') {
        on_line(at);
        at->line_len = 0;
        at->at_line_start = 1;
        return;
    }
    at->at_line_start = 0;
    if (c == '\r') {
        return;
    }
    if (at->line_len < sizeof at->line) {
        at->line[at->line_len++] = (char)c;
    } else if (at->line_len == sizeof at->line) {
        ++at->counters.overlong_lines;
        at->line_len = sizeof at->line + 1u; /* counted once; the line is ignored */
    }
}

static void pump(esp_at* at) {
    pump_out(at);
    uint8_t buf[64];
    size_t n;
    while ((n = at->serial.read(at->serial.user, buf, sizeof buf)) > 0u) {
        for (size_t i = 0; i < n; ++i) {
            on_byte(at, buf[i]);
        }
    }
    pump_out(at);
    if (at->step != STEP_IDLE && now_us(at) > at->deadline_us) {
        ++at->counters.timeouts;
        /* A module that stops answering has hung or restarted by itself (brown-out, its
         * watchdog): then it is at 115200 baud with no Wi-Fi and hears nothing at our rate.
         * Only the reset script brings either back, so the next connect runs it. */
        at->wifi_ready = 0;
        fail(at);
    }
}

/* ---- public --------------------------------------------------------------------------------- */

int esp_at_init(esp_at* at, const esp_at_serial* serial, const esp_at_config* config) {
    if (at == NULL || serial == NULL || config == NULL || serial->write == NULL || serial->read == NULL ||
        serial->time_us == NULL || (config->baud != 0u && serial->set_baud == NULL) || config->ssid == NULL ||
        config->password == NULL || config->host == NULL || config->port == 0u ||
        (config->more_count > 0u && (config->more_hosts == NULL || config->more_ports == NULL))) {
        return MW_ERR_ARGUMENT;
    }
    for (uint8_t i = 0; i < config->more_count; ++i) {
        if (config->more_hosts[i] == NULL || config->more_ports[i] == 0u) {
            return MW_ERR_ARGUMENT;
        }
    }
    const esp_at_counters zero = {0};
    at->serial = *serial;
    at->config = *config;
    at->counters = zero;
    at->link = SINK_UPLINK_DOWN;
    at->wifi_ready = 0;
    at->host = 0;
    at->step = STEP_IDLE;
    at->at_line_start = 1;
    at->deadline_us = 0;
    at->baud_after_flush = 0;
    at->line_len = 0;
    at->payload_len = 0;
    at->ipd_left = 0;
    at->rx_len = 0;
    out_reset(at);
    return MW_OK;
}

int esp_at_connect(void* user, uint8_t host) {
    esp_at* at = (esp_at*)user;
    if (at->step != STEP_IDLE || host > at->config.more_count) {
        return -1;
    }
    at->host = host;
    at->link = SINK_UPLINK_CONNECTING;
    if (at->wifi_ready) {
        begin_step(at, STEP_START, TIMEOUT_START_US);
    } else {
        start_reset(at);
    }
    pump(at);
    return 0;
}

sink_uplink_state esp_at_state(void* user) {
    esp_at* at = (esp_at*)user;
    pump(at);
    return at->link;
}

int esp_at_write(void* user, const uint8_t* data, size_t len) {
    esp_at* at = (esp_at*)user;
    if (at->link != SINK_UPLINK_UP) {
        return -1;
    }
    if (at->step != STEP_IDLE || len > ESP_AT_MAX_PAYLOAD || len == 0u) {
        return 1;
    }
    for (size_t i = 0; i < len; ++i) {
        at->payload[i] = data[i];
    }
    at->payload_len = len;
    begin_step(at, STEP_SEND_PROMPT, TIMEOUT_COMMAND_US);
    pump(at);
    return 0;
}

void esp_at_close(void* user) {
    esp_at* at = (esp_at*)user;
    const int was_setup = in_setup(at);
    fail(at);
    if (was_setup) {
        return; /* the next connect resets the module anyway */
    }
    out_str(at, "AT+CIPCLOSE\r\n"); /* its answer is ignored in STEP_IDLE */
    pump_out(at);
}

int esp_at_read(void* user, uint8_t* data, size_t cap) {
    esp_at* at = (esp_at*)user;
    if (at->link != SINK_UPLINK_UP) {
        return -1;
    }
    size_t n = at->rx_len < cap ? at->rx_len : cap;
    if (n > 0x7FFFu) {
        n = 0x7FFFu; /* the return value is an int */
    }
    for (size_t i = 0; i < n; ++i) {
        data[i] = at->rx[i];
    }
    for (size_t i = n; i < at->rx_len; ++i) {
        at->rx[i - n] = at->rx[i];
    }
    at->rx_len -= n;
    return (int)n;
}

void esp_at_uplink(esp_at* at, sink_node_hal* hal) {
    hal->user = at;
    hal->uplink_connect = esp_at_connect;
    hal->uplink_state = esp_at_state;
    hal->uplink_write = esp_at_write;
    hal->uplink_close = esp_at_close;
    hal->uplink_read = esp_at_read;
}
