/* bxCAN controller registers, identical on STM32F1 (RM0008 §24.9) and STM32F4 (RM0090 §32.9).
 * Only standard (11-bit) identifiers are used by the mocap wire format. */
#ifndef MOCAP_STM32_BXCAN_H
#define MOCAP_STM32_BXCAN_H

#include <stdint.h>

typedef struct {
    volatile uint32_t TIR;
    volatile uint32_t TDTR;
    volatile uint32_t TDLR;
    volatile uint32_t TDHR;
} bxcan_tx_mailbox;

typedef struct {
    volatile uint32_t RIR;
    volatile uint32_t RDTR;
    volatile uint32_t RDLR;
    volatile uint32_t RDHR;
} bxcan_rx_fifo;

typedef struct {
    volatile uint32_t FR1;
    volatile uint32_t FR2;
} bxcan_filter_bank;

typedef struct {
    volatile uint32_t MCR;  /* 0x000 */
    volatile uint32_t MSR;  /* 0x004 */
    volatile uint32_t TSR;  /* 0x008 */
    volatile uint32_t RF0R; /* 0x00C */
    volatile uint32_t RF1R; /* 0x010 */
    volatile uint32_t IER;  /* 0x014 */
    volatile uint32_t ESR;  /* 0x018 */
    volatile uint32_t BTR;  /* 0x01C */
    uint32_t reserved0[88]; /* 0x020 - 0x17F */
    bxcan_tx_mailbox TX[3]; /* 0x180 */
    bxcan_rx_fifo RX[2];    /* 0x1B0 */
    uint32_t reserved1[12]; /* 0x1D0 - 0x1FF */
    volatile uint32_t FMR;  /* 0x200 */
    volatile uint32_t FM1R; /* 0x204 */
    uint32_t reserved2;
    volatile uint32_t FS1R; /* 0x20C */
    uint32_t reserved3;
    volatile uint32_t FFA1R; /* 0x214 */
    uint32_t reserved4;
    volatile uint32_t FA1R; /* 0x21C */
    uint32_t reserved5[8];
    bxcan_filter_bank FB[28]; /* 0x240; the F103 has 14 banks, the F407 28 (shared with CAN2) */
} bxcan_regs;

#define CAN1 ((bxcan_regs*)0x40006400u)

#define CAN_MCR_INRQ (1u << 0)
#define CAN_MCR_SLEEP (1u << 1)
#define CAN_MCR_TXFP (1u << 2) /* transmit in request order, not by identifier */
#define CAN_MCR_RFLM (1u << 3)
#define CAN_MCR_NART (1u << 4)
#define CAN_MCR_AWUM (1u << 5)
#define CAN_MCR_ABOM (1u << 6) /* automatic bus-off recovery */
#define CAN_MCR_RESET (1u << 15)
#define CAN_MSR_INAK (1u << 0)
#define CAN_MSR_SLAK (1u << 1)
#define CAN_TSR_TME0 (1u << 26)
#define CAN_TSR_TME_ALL (7u << 26)
#define CAN_TSR_CODE_SHIFT 24
#define CAN_RFR_FMP_MASK 3u
#define CAN_RFR_FULL (1u << 3)
#define CAN_RFR_FOVR (1u << 4)
#define CAN_RFR_RFOM (1u << 5)
#define CAN_IER_FMPIE0 (1u << 1)
#define CAN_TIR_TXRQ (1u << 0)
#define CAN_TIR_RTR (1u << 1)
#define CAN_TIR_IDE (1u << 2)
#define CAN_TIR_STID_SHIFT 21
#define CAN_RIR_IDE (1u << 2)
#define CAN_RIR_RTR (1u << 1)
#define CAN_RIR_STID_SHIFT 21
#define CAN_FMR_FINIT (1u << 0)
#define CAN_ESR_EPVF (1u << 1)
#define CAN_ESR_BOFF (1u << 2)

/* Bit timing: BRP = prescaler - 1, TS1 = segment1 - 1, TS2 = segment2 - 1, SJW = jump - 1. */
#define CAN_BTR(brp, ts1, ts2, sjw) \
    ((uint32_t)(brp) | ((uint32_t)(ts1) << 16) | ((uint32_t)(ts2) << 20) | ((uint32_t)(sjw) << 24))

/* A 32-bit mask-mode filter register value for a standard identifier (data frames, IDE = 0). */
#define CAN_FILTER32_STD(id) ((uint32_t)(id) << 21)
/* The matching mask: compare these identifier bits, and IDE and RTR (only standard data frames). */
#define CAN_FILTER32_STD_MASK(idmask) (((uint32_t)(idmask) << 21) | CAN_RIR_IDE | CAN_RIR_RTR)

#endif
