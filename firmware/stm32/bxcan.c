/* bxCAN set-up and mailbox access shared by both images (the controller is the same on the
 * F103 and the F407). Standard 11-bit data frames only, as the wire format uses. */
#include "bxcan_driver.h"

#define INIT_TIMEOUT 0x100000u

int bxcan_start(uint32_t btr, const bxcan_filter* filters, unsigned filter_count) {
    CAN1->MCR &= ~CAN_MCR_SLEEP;
    CAN1->MCR |= CAN_MCR_INRQ;
    for (uint32_t n = 0; !(CAN1->MSR & CAN_MSR_INAK); ++n) {
        if (n > INIT_TIMEOUT) {
            return -1;
        }
    }
    /* Automatic bus-off recovery; transmit in request order so a sample's three frames
     * leave in the order they were queued. */
    CAN1->MCR = (CAN1->MCR & ~(CAN_MCR_SLEEP | CAN_MCR_NART | CAN_MCR_RFLM)) | CAN_MCR_ABOM | CAN_MCR_TXFP;
    CAN1->BTR = btr;

    CAN1->FMR |= CAN_FMR_FINIT;
    CAN1->FA1R = 0;
    for (unsigned i = 0; i < filter_count; ++i) {
        const uint32_t bit = 1u << i;
        CAN1->FS1R |= bit;   /* one 32-bit filter per bank */
        CAN1->FM1R &= ~bit;  /* identifier/mask mode */
        CAN1->FFA1R &= ~bit; /* to FIFO 0 */
        CAN1->FB[i].FR1 = CAN_FILTER32_STD(filters[i].id);
        CAN1->FB[i].FR2 = CAN_FILTER32_STD_MASK(filters[i].mask);
        CAN1->FA1R |= bit;
    }
    CAN1->FMR &= ~CAN_FMR_FINIT;

    /* Leaving initialisation needs 11 recessive bits on the bus: without a bus (or with a
     * shorted one) this times out and the caller reports it. */
    CAN1->MCR &= ~CAN_MCR_INRQ;
    for (uint32_t n = 0; CAN1->MSR & CAN_MSR_INAK; ++n) {
        if (n > INIT_TIMEOUT) {
            return -2;
        }
    }
    return 0;
}

int bxcan_transmit(const mw_can_frame* frame) {
    const uint32_t tsr = CAN1->TSR;
    if (!(tsr & CAN_TSR_TME_ALL)) {
        return 1;
    }
    bxcan_tx_mailbox* mb = &CAN1->TX[(tsr >> CAN_TSR_CODE_SHIFT) & 3u];
    const uint8_t* d = frame->data;
    mb->TDTR = frame->dlc & 0xFu;
    mb->TDLR = (uint32_t)d[0] | ((uint32_t)d[1] << 8) | ((uint32_t)d[2] << 16) | ((uint32_t)d[3] << 24);
    mb->TDHR = (uint32_t)d[4] | ((uint32_t)d[5] << 8) | ((uint32_t)d[6] << 16) | ((uint32_t)d[7] << 24);
    mb->TIR = ((uint32_t)(frame->id & 0x7FFu) << CAN_TIR_STID_SHIFT) | CAN_TIR_TXRQ;
    return 0;
}

int bxcan_receive_fifo0(mw_can_frame* frame) {
    if ((CAN1->RF0R & CAN_RFR_FMP_MASK) == 0u) {
        return 0;
    }
    const bxcan_rx_fifo* rx = &CAN1->RX[0];
    const uint32_t rir = rx->RIR;
    const uint32_t dlc = rx->RDTR & 0xFu;
    const uint32_t lo = rx->RDLR;
    const uint32_t hi = rx->RDHR;
    CAN1->RF0R = CAN_RFR_RFOM; /* release the FIFO slot */
    if (rir & (CAN_RIR_IDE | CAN_RIR_RTR)) {
        return -1; /* the filters admit neither; count it as noise */
    }
    frame->id = (uint16_t)((rir >> CAN_RIR_STID_SHIFT) & 0x7FFu);
    frame->dlc = (uint8_t)(dlc > 8u ? 8u : dlc);
    for (unsigned i = 0; i < 4u; ++i) {
        frame->data[i] = (uint8_t)(lo >> (8u * i));
        frame->data[4u + i] = (uint8_t)(hi >> (8u * i));
    }
    return 1;
}

int bxcan_bus_error(void) {
    return (CAN1->ESR & (CAN_ESR_EPVF | CAN_ESR_BOFF)) != 0u || (CAN1->MSR & CAN_MSR_INAK) != 0u;
}
