/* STM32F407 peripheral registers used by the sink node. Written from RM0090; only RCC, PWR,
 * FLASH, GPIO, USART and TIM are defined here (bxCAN in bxcan.h, core in cortex_m.h). */
#ifndef MOCAP_STM32F407_H
#define MOCAP_STM32F407_H

#include "bxcan.h"
#include "cortex_m.h"

typedef struct {
    volatile uint32_t CR;       /* 0x00 */
    volatile uint32_t PLLCFGR;  /* 0x04 */
    volatile uint32_t CFGR;     /* 0x08 */
    volatile uint32_t CIR;      /* 0x0C */
    volatile uint32_t AHB1RSTR; /* 0x10 */
    volatile uint32_t AHB2RSTR; /* 0x14 */
    volatile uint32_t AHB3RSTR; /* 0x18 */
    uint32_t reserved0;
    volatile uint32_t APB1RSTR; /* 0x20 */
    volatile uint32_t APB2RSTR; /* 0x24 */
    uint32_t reserved1[2];
    volatile uint32_t AHB1ENR; /* 0x30 */
    volatile uint32_t AHB2ENR; /* 0x34 */
    volatile uint32_t AHB3ENR; /* 0x38 */
    uint32_t reserved2;
    volatile uint32_t APB1ENR; /* 0x40 */
    volatile uint32_t APB2ENR; /* 0x44 */
} f4_rcc_regs;
#define F4_RCC ((f4_rcc_regs*)0x40023800u)

#define F4_RCC_CR_HSEON (1u << 16)
#define F4_RCC_CR_HSERDY (1u << 17)
#define F4_RCC_CR_PLLON (1u << 24)
#define F4_RCC_CR_PLLRDY (1u << 25)
#define F4_RCC_PLLCFGR(m, n, p, q) \
    ((uint32_t)(m) | ((uint32_t)(n) << 6) | ((uint32_t)(((p) / 2u) - 1u) << 16) | (1u << 22) | ((uint32_t)(q) << 24))
#define F4_RCC_CFGR_SW_PLL (2u << 0)
#define F4_RCC_CFGR_SWS_MASK (3u << 2)
#define F4_RCC_CFGR_SWS_PLL (2u << 2)
#define F4_RCC_CFGR_PPRE1_DIV4 (5u << 10)
#define F4_RCC_CFGR_PPRE2_DIV2 (4u << 13)
#define F4_RCC_AHB1ENR_GPIOA (1u << 0)
#define F4_RCC_AHB1ENR_GPIOB (1u << 1)
#define F4_RCC_AHB1ENR_GPIOD (1u << 3)
#define F4_RCC_APB1ENR_TIM2 (1u << 0)
#define F4_RCC_APB1ENR_CAN1 (1u << 25)
#define F4_RCC_APB1ENR_PWR (1u << 28)
#define F4_RCC_APB2ENR_USART1 (1u << 4)

typedef struct {
    volatile uint32_t CR;
    volatile uint32_t CSR;
} f4_pwr_regs;
#define F4_PWR ((f4_pwr_regs*)0x40007000u)
#define F4_PWR_CR_VOS (1u << 14)

typedef struct {
    volatile uint32_t ACR;
} f4_flash_regs;
#define F4_FLASH ((f4_flash_regs*)0x40023C00u)
#define F4_FLASH_ACR_LATENCY(ws) ((uint32_t)(ws))
#define F4_FLASH_ACR_PRFTEN (1u << 8)
#define F4_FLASH_ACR_ICEN (1u << 9)
#define F4_FLASH_ACR_DCEN (1u << 10)

typedef struct {
    volatile uint32_t MODER;
    volatile uint32_t OTYPER;
    volatile uint32_t OSPEEDR;
    volatile uint32_t PUPDR;
    volatile uint32_t IDR;
    volatile uint32_t ODR;
    volatile uint32_t BSRR;
    volatile uint32_t LCKR;
    volatile uint32_t AFR[2];
} f4_gpio_regs;
#define F4_GPIOA ((f4_gpio_regs*)0x40020000u)
#define F4_GPIOB ((f4_gpio_regs*)0x40020400u)
#define F4_GPIOD ((f4_gpio_regs*)0x40020C00u)

#define F4_GPIO_MODE_OUTPUT 1u
#define F4_GPIO_MODE_AF 2u

/* Alternate function `af` on `pin`, very high speed, push-pull, pull-up when `pull_up`. */
static inline void f4_gpio_af(f4_gpio_regs* port, unsigned pin, unsigned af, int pull_up) {
    port->MODER = (port->MODER & ~(3u << (2u * pin))) | (F4_GPIO_MODE_AF << (2u * pin));
    port->OSPEEDR |= 3u << (2u * pin);
    port->PUPDR = (port->PUPDR & ~(3u << (2u * pin))) | ((pull_up ? 1u : 0u) << (2u * pin));
    port->AFR[pin >> 3] = (port->AFR[pin >> 3] & ~(0xFu << (4u * (pin & 7u)))) | ((uint32_t)af << (4u * (pin & 7u)));
}

static inline void f4_gpio_output(f4_gpio_regs* port, unsigned pin) {
    port->MODER = (port->MODER & ~(3u << (2u * pin))) | (F4_GPIO_MODE_OUTPUT << (2u * pin));
}

typedef struct {
    volatile uint32_t SR;
    volatile uint32_t DR;
    volatile uint32_t BRR;
    volatile uint32_t CR1;
    volatile uint32_t CR2;
    volatile uint32_t CR3;
    volatile uint32_t GTPR;
} f4_usart_regs;
#define F4_USART1 ((f4_usart_regs*)0x40011000u)
#define USART_SR_ORE (1u << 3)
#define USART_SR_RXNE (1u << 5)
#define USART_SR_TC (1u << 6)
#define USART_SR_TXE (1u << 7)
#define USART_CR1_RE (1u << 2)
#define USART_CR1_TE (1u << 3)
#define USART_CR1_RXNEIE (1u << 5)
#define USART_CR1_TXEIE (1u << 7)
#define USART_CR1_UE (1u << 13)

typedef struct {
    volatile uint32_t CR1;  /* 0x00 */
    volatile uint32_t CR2;  /* 0x04 */
    volatile uint32_t SMCR; /* 0x08 */
    volatile uint32_t DIER; /* 0x0C */
    volatile uint32_t SR;   /* 0x10 */
    volatile uint32_t EGR;  /* 0x14 */
    volatile uint32_t CCMR1;
    volatile uint32_t CCMR2;
    volatile uint32_t CCER;
    volatile uint32_t CNT; /* 0x24 */
    volatile uint32_t PSC; /* 0x28 */
    volatile uint32_t ARR; /* 0x2C */
} f4_tim_regs;
#define F4_TIM2 ((f4_tim_regs*)0x40000000u) /* 32-bit general-purpose timer */
#define TIM_CR1_CEN (1u << 0)
#define TIM_EGR_UG (1u << 0)

/* Interrupt numbers (RM0090 table 61). */
#define F4_IRQ_CAN1_RX0 20u
#define F4_IRQ_USART1 37u

#endif
