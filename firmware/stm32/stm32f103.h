/* STM32F103 (medium density, e.g. F103C8) peripheral registers used by the sensor node.
 * Written from RM0008; only RCC, FLASH, GPIO, AFIO and SPI are defined here (bxCAN is in
 * bxcan.h, SysTick/NVIC in cortex_m.h). */
#ifndef MOCAP_STM32F103_H
#define MOCAP_STM32F103_H

#include "bxcan.h"
#include "cortex_m.h"

typedef struct {
    volatile uint32_t CR;
    volatile uint32_t CFGR;
    volatile uint32_t CIR;
    volatile uint32_t APB2RSTR;
    volatile uint32_t APB1RSTR;
    volatile uint32_t AHBENR;
    volatile uint32_t APB2ENR;
    volatile uint32_t APB1ENR;
    volatile uint32_t BDCR;
    volatile uint32_t CSR;
} f1_rcc_regs;
#define F1_RCC ((f1_rcc_regs*)0x40021000u)

#define F1_RCC_CR_HSION (1u << 0)
#define F1_RCC_CR_HSEON (1u << 16)
#define F1_RCC_CR_HSERDY (1u << 17)
#define F1_RCC_CR_PLLON (1u << 24)
#define F1_RCC_CR_PLLRDY (1u << 25)
#define F1_RCC_CFGR_SW_PLL (2u << 0)
#define F1_RCC_CFGR_SWS_MASK (3u << 2)
#define F1_RCC_CFGR_SWS_PLL (2u << 2)
#define F1_RCC_CFGR_PPRE1_DIV2 (4u << 8)
#define F1_RCC_CFGR_PLLSRC_HSE (1u << 16)
#define F1_RCC_CFGR_PLLMUL(m) ((uint32_t)((m)-2u) << 18)
#define F1_RCC_APB2ENR_AFIOEN (1u << 0)
#define F1_RCC_APB2ENR_IOPAEN (1u << 2)
#define F1_RCC_APB2ENR_IOPBEN (1u << 3)
#define F1_RCC_APB2ENR_IOPCEN (1u << 4)
#define F1_RCC_APB2ENR_SPI1EN (1u << 12)
#define F1_RCC_APB1ENR_CANEN (1u << 25)

typedef struct {
    volatile uint32_t ACR;
} f1_flash_regs;
#define F1_FLASH ((f1_flash_regs*)0x40022000u)
#define F1_FLASH_ACR_LATENCY_2 (2u << 0)
#define F1_FLASH_ACR_PRFTBE (1u << 4)

typedef struct {
    volatile uint32_t CRL;
    volatile uint32_t CRH;
    volatile uint32_t IDR;
    volatile uint32_t ODR;
    volatile uint32_t BSRR;
    volatile uint32_t BRR;
    volatile uint32_t LCKR;
} f1_gpio_regs;
#define F1_GPIOA ((f1_gpio_regs*)0x40010800u)
#define F1_GPIOB ((f1_gpio_regs*)0x40010C00u)
#define F1_GPIOC ((f1_gpio_regs*)0x40011000u)

/* 4-bit pin configurations (CNF[1:0] MODE[1:0]). */
#define F1_GPIO_IN_FLOATING 0x4u
#define F1_GPIO_IN_PULL 0x8u /* pull-up/down chosen by ODR */
#define F1_GPIO_OUT_PP_50MHZ 0x3u
#define F1_GPIO_OUT_PP_2MHZ 0x2u
#define F1_GPIO_AF_PP_50MHZ 0xBu

static inline void f1_gpio_config(f1_gpio_regs* port, unsigned pin, uint32_t cfg) {
    volatile uint32_t* reg = pin < 8u ? &port->CRL : &port->CRH;
    unsigned shift = (pin & 7u) * 4u;
    *reg = (*reg & ~(0xFu << shift)) | (cfg << shift);
}

typedef struct {
    volatile uint32_t EVCR;
    volatile uint32_t MAPR;
} f1_afio_regs;
#define F1_AFIO ((f1_afio_regs*)0x40010000u)
#define F1_AFIO_MAPR_CAN_PB8_PB9 (2u << 13)
#define F1_AFIO_MAPR_CAN_MASK (3u << 13)
#define F1_AFIO_MAPR_SWJ_NOJTAG (2u << 24) /* keep SWD, free PB3/PB4/PA15 */

typedef struct {
    volatile uint32_t CR1;
    volatile uint32_t CR2;
    volatile uint32_t SR;
    volatile uint32_t DR;
} f1_spi_regs;
#define F1_SPI1 ((f1_spi_regs*)0x40013000u)
#define SPI_CR1_CPHA (1u << 0)
#define SPI_CR1_CPOL (1u << 1)
#define SPI_CR1_MSTR (1u << 2)
#define SPI_CR1_BR(div_log2_minus1) ((uint32_t)(div_log2_minus1) << 3) /* fPCLK / 2^(n+1) */
#define SPI_CR1_BR_MASK (7u << 3)
#define SPI_CR1_SPE (1u << 6)
#define SPI_CR1_SSI (1u << 8)
#define SPI_CR1_SSM (1u << 9)
#define SPI_SR_RXNE (1u << 0)
#define SPI_SR_TXE (1u << 1)
#define SPI_SR_BSY (1u << 7)

/* Interrupt numbers (RM0008 table 63) of the handlers the sensor node uses. */
#define F1_IRQ_USB_LP_CAN1_RX0 20u

#endif
