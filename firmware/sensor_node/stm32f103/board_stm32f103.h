/* Sensor-node board support on the STM32F103C8 ("blue pill" class boards, 8 MHz crystal).
 *
 * Pins:  SPI1  PA5 SCK, PA6 MISO, PA7 MOSI, PA4 MPU9250 nCS (GPIO)   -> MPU9250 (mode 3)
 *        CAN   PB8 RX, PB9 TX (AFIO remap 2)                          -> CAN transceiver
 *        LED   PC13 (active low): on while the node is sampling
 * Clocks: 72 MHz core and APB2, 36 MHz APB1. SysTick gives the microsecond clock.
 * CAN: 1 Mbit/s (36 MHz / 2 = 18 tq per bit, sample point 88.9 %); the filter admits only
 * SYNC and CONFIG (IDs 0x000..0x07F), the node ignores all other traffic anyway. */
#ifndef MOCAP_SENSOR_NODE_BOARD_STM32F103_H
#define MOCAP_SENSOR_NODE_BOARD_STM32F103_H

#include <stddef.h>
#include <stdint.h>

#include "sensor_node/sensor_node.h"

/* Clocks, SysTick, GPIO, SPI1 and CAN. Returns 0, or negative if CAN did not join the bus
 * (-3: the core is not on the PLL, e.g. no crystal, so CAN stays off the bus). */
int board_init(void);

/* The HAL over this board's peripherals (user pointer unused). */
sensor_node_hal board_hal(void);

void board_led(int on);

#endif
