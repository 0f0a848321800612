/* Reset handler and default exception handlers shared by both node images.
 * The vector tables are per part (vectors_stm32f103.c, vectors_stm32f407.c); the linker
 * scripts define the symbols used here. */
#include <stdint.h>

#include "cortex_m.h"
#include "vectors.h"

extern uint32_t _sidata; /* .data load address in flash */
extern uint32_t _sdata, _edata, _sbss, _ebss;
extern void (*__preinit_array_start[])(void);
extern void (*__preinit_array_end[])(void);
extern void (*__init_array_start[])(void);
extern void (*__init_array_end[])(void);

void system_clock_init(void); /* per part: clocks and flash wait states */
int main(void);

void reset_handler(void) {
#if defined(__ARM_FP)
    /* Full access to CP10/CP11 before any floating-point instruction runs. */
    SCB_CPACR |= (0xFu << 20);
    __asm__ volatile("dsb\n isb");
#endif
    const uint32_t* src = &_sidata;
    for (uint32_t* dst = &_sdata; dst < &_edata;) {
        *dst++ = *src++;
    }
    for (uint32_t* dst = &_sbss; dst < &_ebss;) {
        *dst++ = 0u;
    }
    system_clock_init();
    for (void (**f)(void) = __preinit_array_start; f < __preinit_array_end; ++f) {
        (*f)();
    }
    for (void (**f)(void) = __init_array_start; f < __init_array_end; ++f) {
        (*f)();
    }
    (void)main();
    system_reset();
}

/* An unexpected exception or interrupt: stop here so a debugger shows where; the
 * watchdog-less node then stays silent on the bus, which the sink reports as node loss. */
void default_handler(void) {
    irq_disable();
    for (;;) {
    }
}

#define WEAK_DEFAULT __attribute__((weak, alias("default_handler")))
void nmi_handler(void) WEAK_DEFAULT;
void hard_fault_handler(void) WEAK_DEFAULT;
void svc_handler(void) WEAK_DEFAULT;
void pendsv_handler(void) WEAK_DEFAULT;
void systick_handler(void) WEAK_DEFAULT;
void can1_rx0_irq_handler(void) WEAK_DEFAULT;
void usart1_irq_handler(void) WEAK_DEFAULT;
