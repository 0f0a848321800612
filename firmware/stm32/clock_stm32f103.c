/* STM32F103 clocks: 8 MHz HSE crystal -> PLL x9 -> 72 MHz SYSCLK and APB2, APB1 = 36 MHz
 * (its maximum), flash with two wait states and prefetch (RM0008 §3.3.3, §7.3). */
#include "stm32f103.h"

#define F103_HSE_TIMEOUT 0x80000u

void system_clock_init(void);

void system_clock_init(void) {
    F1_FLASH->ACR = F1_FLASH_ACR_PRFTBE | F1_FLASH_ACR_LATENCY_2;
    F1_RCC->CR |= F1_RCC_CR_HSEON;
    for (uint32_t n = 0; !(F1_RCC->CR & F1_RCC_CR_HSERDY); ++n) {
        if (n > F103_HSE_TIMEOUT) {
            return; /* no crystal: stay on the 8 MHz HSI; the CAN bit timing will be wrong
                       and board_init() keeps the node off the bus rather than disturbing it */
        }
    }
    F1_RCC->CFGR = F1_RCC_CFGR_PLLSRC_HSE | F1_RCC_CFGR_PLLMUL(9u) | F1_RCC_CFGR_PPRE1_DIV2;
    F1_RCC->CR |= F1_RCC_CR_PLLON;
    while (!(F1_RCC->CR & F1_RCC_CR_PLLRDY)) {
    }
    F1_RCC->CFGR |= F1_RCC_CFGR_SW_PLL;
    while ((F1_RCC->CFGR & F1_RCC_CFGR_SWS_MASK) != F1_RCC_CFGR_SWS_PLL) {
    }
}
