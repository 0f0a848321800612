/* Sensor-node image for the STM32F103: board bring-up, then the portable core in a loop. */
#include "board_stm32f103.h"

#ifndef MOCAP_NODE_ID
#define MOCAP_NODE_ID 1
#endif

static sensor_node g_node;

int main(void)
{
    const int can_rc = board_init();
    const sensor_node_hal hal = board_hal();
    (void)sensor_node_init(&g_node, &hal, (uint8_t)MOCAP_NODE_ID);
    if (can_rc != 0) {
        g_node.event_flags |= MW_ERRF_CAN_BUS; /* reported once the bus comes up */
    }
    for (;;) {
        sensor_node_poll(&g_node);
        board_led(g_node.state == MW_NODE_RUNNING);
    }
}
