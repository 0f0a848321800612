/* STM32F103 medium-density vector table: 16 core entries + 43 interrupts (RM0008 table 63).
 * Interrupts the image does not enable stay on default_handler. */
#include <stdint.h>

#include "vectors.h"

__attribute__((section(".isr_vector"), used)) const vector_fn vector_table[16 + 43] = {
    MOCAP_CORE_VECTORS,   default_handler, default_handler, default_handler, default_handler, /* IRQ 0-3 */
    default_handler,      default_handler, default_handler, default_handler,                  /* IRQ 4-7 */
    default_handler,      default_handler, default_handler, default_handler,                  /* IRQ 8-11 */
    default_handler,      default_handler, default_handler, default_handler,                  /* IRQ 12-15 */
    default_handler,      default_handler, default_handler, default_handler,                  /* IRQ 16-19 */
    can1_rx0_irq_handler, default_handler, default_handler, default_handler,                  /* IRQ 20-23 */
    default_handler,      default_handler, default_handler, default_handler,                  /* IRQ 24-27 */
    default_handler,      default_handler, default_handler, default_handler,                  /* IRQ 28-31 */
    default_handler,      default_handler, default_handler, default_handler,                  /* IRQ 32-35 */
    default_handler,      default_handler, default_handler, default_handler,                  /* IRQ 36-39 */
    default_handler,      default_handler, default_handler,                                   /* IRQ 40-42 */
};
