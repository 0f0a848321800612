/* Sink-node board support on the STM32F407VG (STM32F4-Discovery class boards, 8 MHz crystal).
 *
 * Pins:  CAN1   PD0 RX, PD1 TX (AF9)                     -> CAN transceiver
 *        USART1 PB6 TX, PB7 RX (AF7)                     -> ESP8266 RX/TX (AT firmware)
 *        LED    PD12 (green): on while the uplink is connected
 * Clocks: 168 MHz core, APB1 42 MHz (TIM2 at 84 MHz), APB2 84 MHz (USART1).
 * Time: TIM2 counts microseconds (32 bit), extended to 64 bit in software.
 * CAN: 1 Mbit/s (42 MHz / 3 = 14 tq per bit, sample point 85.7 %); filters admit the node
 * messages ACCEL..STATUS (0x080..0x1FF); frames are moved from FIFO 0 into a 64-frame ring
 * by the RX interrupt, so a slow main-loop iteration (a packet encode) loses nothing.
 * USART1: 115200 baud after reset, switched to the ESP client's configured rate; RX and TX
 * through interrupt-driven rings (1 KiB / 4 KiB). */
#ifndef MOCAP_SINK_NODE_BOARD_STM32F407_H
#define MOCAP_SINK_NODE_BOARD_STM32F407_H

#include <stdint.h>

#include "sink_node/esp_at.h"
#include "sink_node/sink_node.h"

/* Clocks, TIM2, GPIO, CAN1 (with its RX interrupt), USART1. 0, or negative if CAN did not
 * join the bus (it keeps trying in hardware). */
int board_init(void);

/* CAN, time and CAN-loss functions of the sink HAL (the uplink members are set by
 * esp_at_uplink()). */
void board_sink_hal(sink_node_hal* hal);

/* The serial port of the ESP8266. */
esp_at_serial board_serial(void);

void board_led(int on);

#endif
