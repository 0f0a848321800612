/* Sink-node image for the STM32F407: board bring-up, the ESP8266 uplink, then the portable
 * sink core in a loop. Wi-Fi and host settings are build options (firmware/CMakeLists.txt). */
#include "board_stm32f407.h"
#include "cortex_m.h"

#ifndef MOCAP_SINK_ID
#define MOCAP_SINK_ID 1
#endif
#ifndef MOCAP_WIFI_SSID
#define MOCAP_WIFI_SSID "mocap"
#endif
#ifndef MOCAP_WIFI_PASSWORD
#define MOCAP_WIFI_PASSWORD "mocapmocap"
#endif
#ifndef MOCAP_HOST
#define MOCAP_HOST "192.168.4.2"
#endif
#ifndef MOCAP_HOST_PORT
#define MOCAP_HOST_PORT 7000
#endif
/* MOCAP_HOST2 (optional): second host of the ordered list; the sink fails over to it when
 * the first dies (docs/firmware.md, "Host list and failover"). */
#ifndef MOCAP_HOST2_PORT
#define MOCAP_HOST2_PORT 7000
#endif
#ifndef MOCAP_ESP_BAUD
#define MOCAP_ESP_BAUD 921600u
#endif

static esp_at g_at;
static sink_node g_sink;

int main(void) {
    (void)board_init();

    const esp_at_serial serial = board_serial();
#ifdef MOCAP_HOST2
    static const char* const more_hosts[1] = {MOCAP_HOST2};
    static const uint16_t more_ports[1] = {MOCAP_HOST2_PORT};
    const esp_at_config wifi = {MOCAP_WIFI_SSID, MOCAP_WIFI_PASSWORD, MOCAP_HOST, MOCAP_HOST_PORT, MOCAP_ESP_BAUD, 1u,
                                more_hosts,      more_ports};
#else
    const esp_at_config wifi = {
        MOCAP_WIFI_SSID, MOCAP_WIFI_PASSWORD, MOCAP_HOST, MOCAP_HOST_PORT, MOCAP_ESP_BAUD, 0u, NULL, NULL};
#endif
    (void)esp_at_init(&g_at, &serial, &wifi);

    sink_node_hal hal = {0};
    board_sink_hal(&hal);
    esp_at_uplink(&g_at, &hal);

    sink_node_config config;
    sink_node_default_config(&config);
    config.sink_id = MOCAP_SINK_ID;
    /* One packet per AT+CIPSEND: (2048 - 26) / 13 = 155 frames at most. */
    config.max_batch_frames = 128u;
    config.host_count = (uint8_t)(1u + wifi.more_count);
    if (sink_node_init(&g_sink, &hal, &config) != MW_OK) {
        for (;;) {
            wait_for_interrupt(); /* a build with an invalid configuration: stay off the bus */
        }
    }
    for (;;) {
        sink_node_poll(&g_sink);
        board_led(g_sink.link == SINK_UPLINK_UP);
    }
}
