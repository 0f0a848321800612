/* Exception handlers named in both vector tables; each is weak and defaults to
 * default_handler, so an image defines only the handlers it uses. */
#ifndef MOCAP_STM32_VECTORS_H
#define MOCAP_STM32_VECTORS_H

#include <stdint.h>

typedef void (*vector_fn)(void);

void reset_handler(void);
void default_handler(void);
void nmi_handler(void);
void hard_fault_handler(void);
void svc_handler(void);
void pendsv_handler(void);
void systick_handler(void);
void can1_rx0_irq_handler(void);
void usart1_irq_handler(void);

extern uint32_t _estack; /* top of RAM, from the linker script */

/* The 16 Cortex-M entries: initial stack pointer, reset, faults (MemManage, BusFault and
 * UsageFault are not enabled, so they escalate to hard fault), SVC, PendSV, SysTick. */
#define MOCAP_CORE_VECTORS                                                                                   \
    (vector_fn)(uintptr_t) & _estack, reset_handler, nmi_handler, hard_fault_handler, hard_fault_handler,    \
        hard_fault_handler, hard_fault_handler, 0, 0, 0, 0, svc_handler, default_handler, 0, pendsv_handler, \
        systick_handler

#endif
