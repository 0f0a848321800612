/* Register-level HAL of the sink node on the STM32F407 (RM0090). */
#include "board_stm32f407.h"

#include "bxcan_driver.h"
#include "stm32f407.h"

#define APB2_HZ 84000000u
#define BOOT_BAUD 115200u
#define LED_PIN 12u
#define CAN_RING_LEN 64u  /* power of two */
#define UART_RX_LEN 1024u /* power of two */
#define UART_TX_LEN 4096u /* power of two */

/* ---- time ----------------------------------------------------------------------------------- */

static uint32_t g_time_last;
static uint64_t g_time_high;

/* Main-loop context only (it extends the 32-bit counter without locking). */
static uint64_t hal_time_us(void* user) {
    (void)user;
    const uint32_t now = F4_TIM2->CNT;
    if (now < g_time_last) {
        g_time_high += 1ull << 32;
    }
    g_time_last = now;
    return g_time_high | now;
}

/* ---- CAN: RX interrupt into a ring ---------------------------------------------------------- */

static mw_can_frame g_can_ring[CAN_RING_LEN];
static volatile uint32_t g_can_head; /* written by the interrupt */
static volatile uint32_t g_can_tail; /* written by the main loop */
static volatile uint32_t g_can_overruns;

void can1_rx0_irq_handler(void) {
    mw_can_frame frame;
    int rc;
    while ((rc = bxcan_receive_fifo0(&frame)) != 0) {
        if (rc < 0) {
            continue;
        }
        const uint32_t head = g_can_head;
        if (head - g_can_tail >= CAN_RING_LEN) {
            ++g_can_overruns;
            continue;
        }
        g_can_ring[head & (CAN_RING_LEN - 1u)] = frame;
        g_can_head = head + 1u;
    }
    if (CAN1->RF0R & CAN_RFR_FOVR) {
        CAN1->RF0R = CAN_RFR_FOVR;
        ++g_can_overruns;
    }
}

static int hal_can_receive(void* user, mw_can_frame* frame) {
    (void)user;
    const uint32_t tail = g_can_tail;
    if (tail == g_can_head) {
        return 0;
    }
    *frame = g_can_ring[tail & (CAN_RING_LEN - 1u)];
    g_can_tail = tail + 1u;
    return 1;
}

static int hal_can_transmit(void* user, const mw_can_frame* frame) {
    (void)user;
    return bxcan_transmit(frame);
}

static uint32_t hal_can_rx_lost(void* user) {
    (void)user;
    return g_can_overruns;
}

/* ---- USART1: interrupt-driven rings --------------------------------------------------------- */

static uint8_t g_rx[UART_RX_LEN];
static uint8_t g_tx[UART_TX_LEN];
static volatile uint32_t g_rx_head, g_rx_tail, g_tx_head, g_tx_tail;

void usart1_irq_handler(void) {
    const uint32_t sr = F4_USART1->SR;
    if (sr & (USART_SR_RXNE | USART_SR_ORE)) {
        const uint8_t c = (uint8_t)F4_USART1->DR; /* also clears ORE */
        if (g_rx_head - g_rx_tail < UART_RX_LEN) {
            g_rx[g_rx_head & (UART_RX_LEN - 1u)] = c;
            g_rx_head = g_rx_head + 1u;
        }
    }
    if ((sr & USART_SR_TXE) && (F4_USART1->CR1 & USART_CR1_TXEIE)) {
        if (g_tx_tail != g_tx_head) {
            F4_USART1->DR = g_tx[g_tx_tail & (UART_TX_LEN - 1u)];
            g_tx_tail = g_tx_tail + 1u;
        } else {
            F4_USART1->CR1 &= ~USART_CR1_TXEIE;
        }
    }
}

static size_t serial_write(void* user, const uint8_t* data, size_t len) {
    (void)user;
    size_t n = 0;
    while (n < len && g_tx_head - g_tx_tail < UART_TX_LEN) {
        g_tx[g_tx_head & (UART_TX_LEN - 1u)] = data[n++];
        g_tx_head = g_tx_head + 1u;
    }
    if (n > 0u) {
        F4_USART1->CR1 |= USART_CR1_TXEIE;
    }
    return n;
}

static size_t serial_read(void* user, uint8_t* data, size_t cap) {
    (void)user;
    size_t n = 0;
    while (n < cap && g_rx_tail != g_rx_head) {
        data[n++] = g_rx[g_rx_tail & (UART_RX_LEN - 1u)];
        g_rx_tail = g_rx_tail + 1u;
    }
    return n;
}

static void serial_set_baud(void* user, uint32_t baud) {
    (void)user;
    while (g_tx_tail != g_tx_head) { /* let queued bytes leave at the old rate */
    }
    while (!(F4_USART1->SR & USART_SR_TC)) {
    }
    F4_USART1->CR1 &= ~USART_CR1_UE;
    F4_USART1->BRR = (APB2_HZ + baud / 2u) / baud; /* 16x oversampling: BRR = fck / baud */
    F4_USART1->CR1 |= USART_CR1_UE;
}

static uint64_t serial_time_us(void* user) {
    return hal_time_us(user);
}

esp_at_serial board_serial(void) {
    esp_at_serial serial = {NULL, serial_write, serial_read, serial_set_baud, serial_time_us};
    return serial;
}

/* ---- board ---------------------------------------------------------------------------------- */

void board_sink_hal(sink_node_hal* hal) {
    hal->can_transmit = hal_can_transmit;
    hal->can_receive = hal_can_receive;
    hal->time_us = hal_time_us;
    hal->can_rx_lost = hal_can_rx_lost;
}

void board_led(int on) {
    F4_GPIOD->BSRR = on ? (1u << LED_PIN) : (1u << (LED_PIN + 16u));
}

int board_init(void) {
    F4_RCC->AHB1ENR |= F4_RCC_AHB1ENR_GPIOB | F4_RCC_AHB1ENR_GPIOD;
    F4_RCC->APB1ENR |= F4_RCC_APB1ENR_TIM2 | F4_RCC_APB1ENR_CAN1;
    F4_RCC->APB2ENR |= F4_RCC_APB2ENR_USART1;

    /* TIM2: 84 MHz / 84 = 1 MHz, free-running over 32 bits. */
    F4_TIM2->PSC = 84u - 1u;
    F4_TIM2->ARR = 0xFFFFFFFFu;
    F4_TIM2->EGR = TIM_EGR_UG; /* load the prescaler */
    F4_TIM2->CR1 = TIM_CR1_CEN;

    f4_gpio_output(F4_GPIOD, LED_PIN);
    board_led(0);

    f4_gpio_af(F4_GPIOB, 6u, 7u, 0);
    f4_gpio_af(F4_GPIOB, 7u, 7u, 1);
    F4_USART1->BRR = (APB2_HZ + BOOT_BAUD / 2u) / BOOT_BAUD;
    F4_USART1->CR1 = USART_CR1_UE | USART_CR1_TE | USART_CR1_RE | USART_CR1_RXNEIE;
    nvic_enable_irq(F4_IRQ_USART1, 0x40u);

    f4_gpio_af(F4_GPIOD, 0u, 9u, 1);
    f4_gpio_af(F4_GPIOD, 1u, 9u, 0);
    /* Node messages only: ACCEL, GYRO (0x080..0x0FF) and MAG, ATT, STATUS (0x100..0x1FF). */
    static const bxcan_filter filters[] = {{0x080u, 0x780u}, {0x100u, 0x700u}};
    /* 1 Mbit/s from 42 MHz: prescaler 3, 1 + 11 + 2 = 14 tq, SJW 1. */
    const int rc = bxcan_start(CAN_BTR(2u, 10u, 1u, 0u), filters, 2u);
    CAN1->IER |= CAN_IER_FMPIE0;
    nvic_enable_irq(F4_IRQ_CAN1_RX0, 0x20u); /* above the UART: the CAN FIFO is 3 deep */
    return rc;
}
