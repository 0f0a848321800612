/* Minimal bxCAN driver shared by the node images: start with bit timing and filters, offer a
 * frame to a free mailbox, take a frame from FIFO 0. Polling; the caller decides on interrupts. */
#ifndef MOCAP_STM32_BXCAN_DRIVER_H
#define MOCAP_STM32_BXCAN_DRIVER_H

#include "bxcan.h"
#include "mocap_wire/mw_can.h"

/* A filter bank accepting standard data frames whose id matches `id` on the bits of `mask`. */
typedef struct {
    uint16_t id;
    uint16_t mask;
} bxcan_filter;

/* Enters init mode, sets BTR and filter banks 0..filter_count-1 (to FIFO 0), and joins the
 * bus. 0 = on the bus, negative = the controller did not enter/leave init mode. */
int bxcan_start(uint32_t btr, const bxcan_filter* filters, unsigned filter_count);

/* 0 = placed in a free mailbox, 1 = all three busy. */
int bxcan_transmit(const mw_can_frame* frame);

/* 1 = *frame filled, 0 = FIFO empty, -1 = an extended/remote frame was discarded. */
int bxcan_receive_fifo0(mw_can_frame* frame);

/* Nonzero while the controller is error-passive, bus-off, or still waiting to join the bus. */
int bxcan_bus_error(void);

#endif
