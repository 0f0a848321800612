"""The sensor node as built (docs/firmware.md): an STM32F103C8 with an 8 MHz crystal, an
MPU-9250 on SPI1 (PA5 SCK, PA6 MISO, PA7 MOSI, PA4 nCS) and a CAN transceiver on PB8/PB9
(AFIO CAN remap 0b10), every part a model, the unmodified ELF in flash.

Memory map (RM0008 §3.3, datasheet of the F103C8): flash 64 KiB at 0x08000000 (aliased at 0
when booting from flash), SRAM 20 KiB at 0x20000000. RCC enable bits (RM0008 §7.3.7/§7.3.8):
APB2ENR AFIOEN 0, IOPAEN 2, IOPBEN 3, IOPCEN 4, SPI1EN 12; APB1ENR CANEN 25. CAN1 RX0 is
IRQ 20 (USB_LP_CAN1_RX0, RM0008 table 63); the F103 has 43 interrupts and 14 filter banks.
"""

from bxcan import BxCan
from cortex_m import CortexM
from mpu9250_model import Mpu9250
from stm32f1_gpio import Afio, GpioPort
from stm32f1_rcc import FlashInterface, Rcc
from stm32f1_spi import Spi
from system_control import SystemControl

CS_PIN, SCK_PIN, MOSI_PIN = 4, 5, 7
CAN_RX_PIN, CAN_TX_PIN = 8, 9


class SensorNodeBoard:
    def __init__(self, elf_path, motion=None, who_am_i=0x71, hse_present=True):
        cpu = self.cpu = CortexM(0x08000000, 64 * 1024, 0x20000000, 20 * 1024)
        clock = cpu.clock
        self.rcc = Rcc(clock, self._hclk_changed, hse_present=hse_present)
        self.flash = FlashInterface()
        self.rcc.flash_latency = self.flash.latency
        cpu.scs = SystemControl(clock, irq_count=43)
        self.gpioa = GpioPort("GPIOA", 0x40010800, self.rcc, 2)
        self.gpiob = GpioPort("GPIOB", 0x40010C00, self.rcc, 3)
        self.gpioc = GpioPort("GPIOC", 0x40011000, self.rcc, 4)
        self.afio = Afio(self.rcc)
        self.spi1 = Spi("SPI1", 0x40013000, clock, self.rcc, 12, self.rcc.pclk2_hz, self._spi_pins_routed)
        self.can = BxCan(0x40006400, clock, self.rcc, 25, self.rcc.pclk1_hz, self._can_pins_routed, 20, cpu.scs, 14)
        self.mpu = Mpu9250(clock, motion, who_am_i=who_am_i)
        self.spi1.slave = self.mpu
        self.gpioa.watch(CS_PIN, self._chip_select)
        self.violations = []
        models = (self.rcc, self.flash, self.gpioa, self.gpiob, self.gpioc, self.afio, self.spi1, self.can)
        for model in (cpu.scs,) + models:
            cpu.bus.attach(model)
        cpu.on_reset.extend(m.reset for m in models)
        cpu.program(elf_path)
        cpu.reset()

    def connect(self, bus):
        """Puts the CAN transceiver on `bus` (a can_bus.CanBus on this board's clock)."""
        self.can.bus = bus
        bus.attach(self.can)

    def _hclk_changed(self, hz):
        self.cpu.set_sysclk(hz)
        self.cpu.scs.set_hclk(hz)

    def _spi_pins_routed(self):
        return self.gpioa.pin_mode(SCK_PIN) == "af" and self.gpioa.pin_mode(MOSI_PIN) == "af"

    def _can_pins_routed(self):
        return (self.afio.can_remap() == 2 and self.gpiob.pin_mode(CAN_TX_PIN) == "af"
                and self.gpiob.pin_mode(CAN_RX_PIN) == "input")

    def _chip_select(self, level):
        if level != 0 and self.spi1.busy():
            self.violations.append("nCS raised while SPI1 was still shifting")
        self.mpu.chip_select(level)

    def all_violations(self):
        return self.violations + self.rcc.violations + self.can.violations + self.mpu.violations

    def led_on(self):
        return self.gpioc.output_level(13) == 0
