/* STM32F407 vector table: 16 core entries + 82 interrupts (RM0090 table 61).
 * Interrupts the image does not enable stay on default_handler. */
#include <stdint.h>

#include "vectors.h"

__attribute__((section(".isr_vector"), used)) const vector_fn vector_table[16 + 82] = {
    MOCAP_CORE_VECTORS,   default_handler,    default_handler, default_handler, default_handler, /* IRQ 0-3 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 4-7 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 8-11 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 12-15 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 16-19 */
    can1_rx0_irq_handler, default_handler,    default_handler, default_handler,                  /* IRQ 20-23 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 24-27 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 28-31 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 32-35 */
    default_handler,      usart1_irq_handler, default_handler, default_handler,                  /* IRQ 36-39 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 40-43 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 44-47 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 48-51 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 52-55 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 56-59 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 60-63 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 64-67 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 68-71 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 72-75 */
    default_handler,      default_handler,    default_handler, default_handler,                  /* IRQ 76-79 */
    default_handler,      default_handler,                                                       /* IRQ 80-81 */
};
