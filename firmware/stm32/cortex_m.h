/* Cortex-M core registers used by the node images (SysTick, NVIC, SCB).
 * Written from the ARMv7-M Architecture Reference Manual; only what the images use. */
#ifndef MOCAP_STM32_CORTEX_M_H
#define MOCAP_STM32_CORTEX_M_H

#include <stdint.h>

#define MMIO32(addr) (*(volatile uint32_t*)(uintptr_t)(addr))

typedef struct {
    volatile uint32_t CTRL;
    volatile uint32_t LOAD;
    volatile uint32_t VAL;
    volatile uint32_t CALIB;
} systick_regs;

#define SYSTICK ((systick_regs*)0xE000E010u)
#define SYSTICK_CTRL_ENABLE (1u << 0)
#define SYSTICK_CTRL_TICKINT (1u << 1)
#define SYSTICK_CTRL_CLKSOURCE (1u << 2) /* processor clock */
#define SYSTICK_CTRL_COUNTFLAG (1u << 16)

#define NVIC_ISER(n) MMIO32(0xE000E100u + 4u * (n))
#define NVIC_IPR_BYTE(irq) (*(volatile uint8_t*)(uintptr_t)(0xE000E400u + (irq)))
#define SCB_ICSR MMIO32(0xE000ED04u)
#define SCB_ICSR_PENDSTSET (1u << 26)
#define SCB_VTOR MMIO32(0xE000ED08u)
#define SCB_AIRCR MMIO32(0xE000ED0Cu)
#define SCB_CPACR MMIO32(0xE000ED88u)
#define SCB_AIRCR_SYSRESET ((0x5FAu << 16) | (1u << 2))

static inline void nvic_enable_irq(unsigned irq, uint8_t priority) {
    NVIC_IPR_BYTE(irq) = priority;
    NVIC_ISER(irq >> 5) = 1u << (irq & 31u);
}

static inline void irq_disable(void) {
    __asm__ volatile("cpsid i" ::: "memory");
}
static inline void irq_enable(void) {
    __asm__ volatile("cpsie i" ::: "memory");
}
static inline void wait_for_interrupt(void) {
    __asm__ volatile("wfi");
}

/* Saves PRIMASK and disables interrupts; restore with irq_restore(). */
static inline uint32_t irq_save(void) {
    uint32_t primask;
    __asm__ volatile("mrs %0, primask\n cpsid i" : "=r"(primask)::"memory");
    return primask;
}
static inline void irq_restore(uint32_t primask) {
    __asm__ volatile("msr primask, %0" ::"r"(primask) : "memory");
}

static inline void system_reset(void) {
    SCB_AIRCR = SCB_AIRCR_SYSRESET;
    for (;;) {
    }
}

#endif
