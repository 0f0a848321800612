/* Sensor-node image for the STM32F103: board bring-up, then the portable core in a loop. */
#include "board_stm32f103.h"

#ifndef MOCAP_NODE_ID
#define MOCAP_NODE_ID 1
#endif

static sensor_node g_node;

int main(void) {
    (void)board_init(); /* a bus not joined yet shows as MW_ERRF_CAN_BUS through the HAL */
    const sensor_node_hal hal = board_hal();
    (void)sensor_node_init(&g_node, &hal, (uint8_t)MOCAP_NODE_ID);
    for (;;) {
        sensor_node_poll(&g_node);
        board_led(g_node.state == MW_NODE_RUNNING);
    }
}
