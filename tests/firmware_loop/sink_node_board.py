"""The sink node as built (docs/firmware.md): an STM32F407VG with an 8 MHz crystal, CAN1 on
PD0 RX / PD1 TX (AF9) to a transceiver, USART1 on PB6 TX / PB7 RX (AF7) to an ESP8266
(esp8266_model.py), the LED on PD12; every part a model, the unmodified ELF in flash.

Memory map (RM0090 §2.3, datasheet of the F407VG): flash 1 MiB at 0x08000000 (aliased at 0
when booting from flash), main SRAM 128 KiB at 0x20000000 (the image does not use the CCM
RAM). RCC enable bits (RM0090 §7.3.10-§7.3.14): AHB1ENR GPIOBEN 1, GPIODEN 3; APB1ENR TIM2EN
0, CAN1EN 25, PWREN 28; APB2ENR USART1EN 4. Interrupts (RM0090 table 61): CAN1_RX0 20,
USART1 37, 82 in all; 28 filter banks shared by CAN1 and CAN2 (CAN2SB resets to 14: CAN1
owns banks 0-13). Core: Cortex-M4 with FPU (unicorn's cortex-m4 model), 4 priority bits.
"""

from unicorn.arm_const import UC_CPU_ARM_CORTEX_M4

from bxcan import BxCan
from cortex_m import CortexM
from esp8266_model import Esp8266
from stm32f4_gpio import GpioPort
from stm32f4_rcc import FlashInterface, Pwr, Rcc
from stm32f4_tim import Timer
from stm32f4_usart import Usart
from system_control import CPUID_CORTEX_M4_R0P1, SystemControl

CAN_RX_PIN, CAN_TX_PIN, CAN_AF = 0, 1, 9
USART_TX_PIN, USART_RX_PIN, USART_AF = 6, 7, 7
LED_PIN = 12

# What the image is built with (firmware/sink_node/stm32f407/main.c defaults).
WIFI_SSID, WIFI_PASSWORD = "mocap", "mocapmocap"
IMAGE_HOST = ("192.168.4.2", 7000)


class SinkNodeBoard:
    def __init__(self, elf_path, host_address, hse_present=True):
        """`host_address`: the real (address, port) the image's MOCAP_HOST:MOCAP_HOST_PORT
        reaches over the Wi-Fi network (mocapd's sink port)."""
        cpu = self.cpu = CortexM(0x08000000, 1024 * 1024, 0x20000000, 128 * 1024, UC_CPU_ARM_CORTEX_M4, fpu=True)
        clock = cpu.clock
        self.rcc = Rcc(clock, self._hclk_changed, hse_present=hse_present)
        self.flash = FlashInterface()
        self.pwr = Pwr(self.rcc)
        self.rcc.flash_latency = self.flash.latency
        self.rcc.vos_scale1 = self.pwr.vos_scale1
        cpu.scs = SystemControl(clock, irq_count=82, cpuid=CPUID_CORTEX_M4_R0P1, fpu=True)
        self.gpiob = GpioPort("GPIOB", 1, self.rcc)
        self.gpiod = GpioPort("GPIOD", 3, self.rcc)
        self.tim2 = Timer("TIM2", 0x40000000, self.rcc, 0, clock, self.rcc.tim_apb1_hz)
        self.usart1 = Usart("USART1", 0x40011000, clock, self.rcc, 4, self.rcc.pclk2_hz, 37, cpu.scs,
                            self._usart_pins_routed)
        self.esp = Esp8266(WIFI_SSID, WIFI_PASSWORD, {IMAGE_HOST: host_address})
        self.usart1.device = self.esp
        self.can = BxCan(0x40006400, clock, self.rcc, 25, self.rcc.pclk1_hz, self._can_pins_routed, 20, cpu.scs, 14)
        models = (self.rcc, self.flash, self.pwr, self.gpiob, self.gpiod, self.tim2, self.usart1, self.can)
        for model in (cpu.scs,) + models:
            cpu.bus.attach(model)
        cpu.timed.append(self.usart1)
        cpu.on_reset.extend(m.reset for m in models)
        cpu.program(elf_path)
        cpu.reset()

    def connect(self, bus):
        """Puts the CAN transceiver on `bus` (a can_bus.CanBus)."""
        self.can.bus = bus
        bus.attach(self.can)

    def _hclk_changed(self, hz):
        self.cpu.set_sysclk(hz)
        self.cpu.scs.set_hclk(hz)

    def _af(self, port, pin, af):
        return port.pin_mode(pin) == "af" and port.alternate(pin) == af

    def _usart_pins_routed(self):
        return self._af(self.gpiob, USART_TX_PIN, USART_AF) and self._af(self.gpiob, USART_RX_PIN, USART_AF)

    def _can_pins_routed(self):
        return self._af(self.gpiod, CAN_TX_PIN, CAN_AF) and self._af(self.gpiod, CAN_RX_PIN, CAN_AF)

    def all_violations(self):
        return self.rcc.violations + self.can.violations + self.usart1.violations

    def led_on(self):
        return self.gpiod.output_level(LED_PIN) == 1
