/* Register-level HAL of the sensor node on the STM32F103 (RM0008). */
#include "board_stm32f103.h"

#include "bxcan_driver.h"
#include "stm32f103.h"

#define CORE_HZ 72000000u
#define SYSTICK_RELOAD (CORE_HZ / 1000u - 1u) /* 1 ms */
#define CS_PIN 4u
#define LED_PIN 13u
/* SPI clock dividers (2^(n+1)): configuration at <= 1 MHz, sensor reads at <= 20 MHz
 * (MPU-9250 datasheet §7.5): 72 MHz / 128 = 0.56 MHz, 72 MHz / 8 = 9 MHz. */
#define SPI_BR_SLOW 6u
#define SPI_BR_FAST 2u

static volatile uint64_t g_ms;

void systick_handler(void) {
    ++g_ms;
}

static uint64_t hal_time_us(void* user) {
    (void)user;
    const uint32_t primask = irq_save();
    uint64_t ms = g_ms;
    uint32_t val = SYSTICK->VAL;
    if (SCB_ICSR & SCB_ICSR_PENDSTSET) { /* wrapped, handler not run yet */
        ++ms;
        val = SYSTICK->VAL;
    }
    irq_restore(primask);
    return ms * 1000u + (SYSTICK_RELOAD - val) / (CORE_HZ / 1000000u);
}

static void spi_set_divider(uint32_t br) {
    if (((F1_SPI1->CR1 & SPI_CR1_BR_MASK) >> 3) == br) {
        return;
    }
    F1_SPI1->CR1 &= ~SPI_CR1_SPE; /* BR must not change while enabled */
    F1_SPI1->CR1 = (F1_SPI1->CR1 & ~SPI_CR1_BR_MASK) | SPI_CR1_BR(br);
    F1_SPI1->CR1 |= SPI_CR1_SPE;
}

static int hal_spi_transfer(void* user, const uint8_t* tx, uint8_t* rx, size_t len) {
    (void)user;
    if (len == 0u) {
        return 0;
    }
    /* Reads of the sensor and EXT_SENS_DATA registers (0x3A..0x60) may run fast. */
    const uint8_t reg = (uint8_t)(tx[0] & 0x7Fu);
    const int fast = (tx[0] & 0x80u) && reg >= 0x3Au && reg <= 0x60u;
    spi_set_divider(fast ? SPI_BR_FAST : SPI_BR_SLOW);
    F1_GPIOA->BRR = 1u << CS_PIN;
    for (size_t i = 0; i < len; ++i) {
        while (!(F1_SPI1->SR & SPI_SR_TXE)) {
        }
        F1_SPI1->DR = tx[i];
        while (!(F1_SPI1->SR & SPI_SR_RXNE)) {
        }
        rx[i] = (uint8_t)F1_SPI1->DR;
    }
    while (F1_SPI1->SR & SPI_SR_BSY) {
    }
    F1_GPIOA->BSRR = 1u << CS_PIN;
    return 0;
}

static int hal_can_transmit(void* user, const mw_can_frame* frame) {
    (void)user;
    return bxcan_transmit(frame);
}

static int hal_can_receive(void* user, mw_can_frame* frame) {
    (void)user;
    for (;;) {
        const int rc = bxcan_receive_fifo0(frame);
        if (rc >= 0) {
            return rc;
        }
    }
}

static int hal_can_bus_error(void* user) {
    (void)user;
    return bxcan_bus_error();
}

sensor_node_hal board_hal(void) {
    sensor_node_hal hal = {NULL, hal_spi_transfer, hal_can_transmit, hal_can_receive, hal_time_us, hal_can_bus_error};
    return hal;
}

void board_led(int on) {
    if (on) {
        F1_GPIOC->BRR = 1u << LED_PIN;
    } else {
        F1_GPIOC->BSRR = 1u << LED_PIN;
    }
}

int board_init(void) {
    F1_RCC->APB2ENR |= F1_RCC_APB2ENR_AFIOEN | F1_RCC_APB2ENR_IOPAEN | F1_RCC_APB2ENR_IOPBEN | F1_RCC_APB2ENR_IOPCEN |
                       F1_RCC_APB2ENR_SPI1EN;
    F1_RCC->APB1ENR |= F1_RCC_APB1ENR_CANEN;

    SYSTICK->LOAD = SYSTICK_RELOAD;
    SYSTICK->VAL = 0;
    SYSTICK->CTRL = SYSTICK_CTRL_CLKSOURCE | SYSTICK_CTRL_TICKINT | SYSTICK_CTRL_ENABLE;

    /* LED off, MPU9250 deselected before the pins become outputs. */
    F1_GPIOC->BSRR = 1u << LED_PIN;
    f1_gpio_config(F1_GPIOC, LED_PIN, F1_GPIO_OUT_PP_2MHZ);
    F1_GPIOA->BSRR = 1u << CS_PIN;
    f1_gpio_config(F1_GPIOA, CS_PIN, F1_GPIO_OUT_PP_50MHZ);
    f1_gpio_config(F1_GPIOA, 5u, F1_GPIO_AF_PP_50MHZ);
    f1_gpio_config(F1_GPIOA, 6u, F1_GPIO_IN_FLOATING);
    f1_gpio_config(F1_GPIOA, 7u, F1_GPIO_AF_PP_50MHZ);

    /* SPI mode 3, master, 8 bit, MSB first, software slave select. */
    F1_SPI1->CR1 =
        SPI_CR1_MSTR | SPI_CR1_SSM | SPI_CR1_SSI | SPI_CR1_CPOL | SPI_CR1_CPHA | SPI_CR1_BR(SPI_BR_SLOW) | SPI_CR1_SPE;

    F1_AFIO->MAPR = (F1_AFIO->MAPR & ~F1_AFIO_MAPR_CAN_MASK) | F1_AFIO_MAPR_CAN_PB8_PB9;
    F1_GPIOB->BSRR = 1u << 8; /* pull-up on RX */
    f1_gpio_config(F1_GPIOB, 8u, F1_GPIO_IN_PULL);
    f1_gpio_config(F1_GPIOB, 9u, F1_GPIO_AF_PP_50MHZ);

    /* The bit timing below needs APB1 at 36 MHz from the PLL. Without the crystal the clock
     * set-up leaves the core on the 8 MHz HSI, where it would give 222 kbit/s: every frame
     * the node started would be an error for the 1 Mbit/s bus, again after each bus-off
     * recovery. The controller then stays asleep, off the bus (the sink reports the node lost). */
    if ((F1_RCC->CFGR & F1_RCC_CFGR_SWS_MASK) != F1_RCC_CFGR_SWS_PLL) {
        return -3;
    }
    /* 1 Mbit/s from 36 MHz: prescaler 2, 1 + 15 + 2 = 18 tq, SJW 1. */
    static const bxcan_filter filters[] = {{0x000u, 0x780u}}; /* SYNC and CONFIG */
    return bxcan_start(CAN_BTR(1u, 14u, 1u, 0u), filters, 1u);
}
