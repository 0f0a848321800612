"""Virtual time of one emulated MCU.

Time is counted in ticks of 4.032 GHz, a common multiple of every clock the models use (8 MHz
HSI/HSE, 72 MHz SYSCLK, 36 MHz APB1, the SPI and CAN bit clocks of the F103; 16 MHz HSI,
168 MHz SYSCLK, 42/84 MHz APB1/APB2 of the F407), so every conversion is exact and nothing
depends on the host. The CPU advances time by its instruction count at the
current SYSCLK (one instruction = one cycle: a lower bound for the Cortex-M3, whose loads,
branches and flash wait states take more; docs/firmware.md).
"""

TICK_HZ = 4_032_000_000  # lcm(576 MHz, 168 MHz)


def ticks_per(hz):
    """Ticks per period of a clock of `hz` (exact for the clocks of the models)."""
    if hz <= 0 or TICK_HZ % hz:
        raise ValueError(f"clock {hz} Hz is not a divisor of {TICK_HZ} Hz")
    return TICK_HZ // hz


def ticks_from_us(us):
    return us * (TICK_HZ // 1_000_000)


class Clock:
    def __init__(self):
        self.ticks = 0
        self.cycles = 0  # CPU instructions executed since power-on
