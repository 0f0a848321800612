/* STM32F407 clocks: 8 MHz HSE crystal -> PLL (M=8, N=336, P=2, Q=7) -> 168 MHz SYSCLK,
 * APB1 = 42 MHz (timers 84 MHz), APB2 = 84 MHz; regulator scale 1 and five flash wait
 * states with caches and prefetch (RM0090 §3.5.1, §6.3). */
#include "stm32f407.h"

#define F407_HSE_TIMEOUT 0x80000u

void system_clock_init(void);

void system_clock_init(void) {
    F4_RCC->APB1ENR |= F4_RCC_APB1ENR_PWR;
    F4_PWR->CR |= F4_PWR_CR_VOS;
    F4_RCC->CR |= F4_RCC_CR_HSEON;
    for (uint32_t n = 0; !(F4_RCC->CR & F4_RCC_CR_HSERDY); ++n) {
        if (n > F407_HSE_TIMEOUT) {
            return; /* no crystal: stay on the 16 MHz HSI, the sink cannot time the bus */
        }
    }
    F4_RCC->PLLCFGR = F4_RCC_PLLCFGR(8u, 336u, 2u, 7u);
    F4_RCC->CR |= F4_RCC_CR_PLLON;
    while (!(F4_RCC->CR & F4_RCC_CR_PLLRDY)) {
    }
    F4_FLASH->ACR = F4_FLASH_ACR_ICEN | F4_FLASH_ACR_DCEN | F4_FLASH_ACR_PRFTEN | F4_FLASH_ACR_LATENCY(5u);
    F4_RCC->CFGR = F4_RCC_CFGR_PPRE1_DIV4 | F4_RCC_CFGR_PPRE2_DIV2;
    F4_RCC->CFGR |= F4_RCC_CFGR_SW_PLL;
    while ((F4_RCC->CFGR & F4_RCC_CFGR_SWS_MASK) != F4_RCC_CFGR_SWS_PLL) {
    }
}
