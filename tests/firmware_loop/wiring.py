"""The wiring tables of docs/hardware.md, from the pins the firmware configures.

Sensor node: the image the build produces (FIRMWARE_F103_ELF) runs from its reset vector on the
emulated STM32F103 (sensor_node_board.py) through its board set-up; every pin whose
configuration register left its reset value (floating input) is a row, with the mode the
firmware wrote and the pin's function from the F103's pin table (datasheet DS5319, table 5
"pin definitions", and RM0008 §9.3.12 for the CAN remap that AFIO_MAPR selects).

Sink node: its image does not run in the harness yet (no STM32F407 models), so its rows are
read from the calls that configure the pins in firmware/sink_node/stm32f407/board_stm32f407.c
(`f4_gpio_af(port, pin, af, pull_up)`, `f4_gpio_output(port, pin)`), with the function of each
alternate-function number from the F407's table (datasheet DS8626, table 9).

  wiring.py --check docs/hardware.md   exits 1 and prints the difference when the document's
                                       tables are not the ones the firmware gives
  wiring.py --write docs/hardware.md   rewrites them
  wiring.py                            prints them
"""

import argparse
import difflib
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SINK_BOARD = os.path.join(ROOT, "firmware", "sink_node", "stm32f407", "board_stm32f407.c")

# STM32F103C8 (LQFP48, "blue pill"): the functions of the pins this firmware can use.
# (port, pin, mode) -> function; CAN_RX/CAN_TX depend on AFIO_MAPR CAN_REMAP.
F103_FUNCTIONS = {
    ("A", 4, "output"): "GPIO (MPU-9250 chip select)",
    ("A", 5, "af"): "SPI1_SCK",
    ("A", 6, "input"): "SPI1_MISO",
    ("A", 7, "af"): "SPI1_MOSI",
    ("C", 13, "output"): "GPIO (status LED, active low)",
}
F103_CAN_PINS = {0: {("A", 11): "CAN_RX", ("A", 12): "CAN_TX"}, 2: {("B", 8): "CAN_RX", ("B", 9): "CAN_TX"},
                 3: {("D", 0): "CAN_RX", ("D", 1): "CAN_TX"}}

# Where each function goes on the parts of docs/hardware.md's bill of materials.
SENSOR_PARTNER = {
    "GPIO (MPU-9250 chip select)": "MPU-9250 breakout NCS",
    "SPI1_SCK": "MPU-9250 breakout SCL/SCLK",
    "SPI1_MISO": "MPU-9250 breakout AD0/SDO",
    "SPI1_MOSI": "MPU-9250 breakout SDA/SDI",
    "CAN_RX": "transceiver R (CRX on SN65HVD230 boards)",
    "CAN_TX": "transceiver D (CTX on SN65HVD230 boards)",
    "GPIO (status LED, active low)": "on-board LED (blue pill), nothing to wire",
}

# STM32F407 alternate functions (DS8626 table 9) of the pins the sink can use.
F407_AF = {
    ("B", 6, 7): "USART1_TX",
    ("B", 7, 7): "USART1_RX",
    ("A", 9, 7): "USART1_TX",
    ("A", 10, 7): "USART1_RX",
    ("D", 0, 9): "CAN1_RX",
    ("D", 1, 9): "CAN1_TX",
    ("B", 8, 9): "CAN1_RX",
    ("B", 9, 9): "CAN1_TX",
    ("A", 11, 9): "CAN1_RX",
    ("A", 12, 9): "CAN1_TX",
}
SINK_PARTNER = {
    "USART1_TX": "ESP-01 RX",
    "USART1_RX": "ESP-01 TX",
    "CAN1_RX": "transceiver R (CRX on SN65HVD230 boards)",
    "CAN1_TX": "transceiver D (CTX on SN65HVD230 boards)",
    "GPIO output": "on-board green LED LD4 (STM32F4-Discovery), nothing to wire",
}
MODE_TEXT = {"input": "floating input", "output": "push-pull output", "af": "alternate-function push-pull"}


def sensor_rows(elf):
    """(pin, mode, function, partner) of every pin the sensor-node image configured."""
    from sensor_node_board import SensorNodeBoard
    from virtual_clock import ticks_from_us

    board = SensorNodeBoard(elf)
    # The board set-up is the first thing main() does; 20 ms of virtual time is well past it.
    board.cpu.run_until(ticks_from_us(20_000))
    if board.cpu.fault is not None:
        raise SystemExit(f"the sensor-node image faulted during its set-up: {board.cpu.fault}")
    can_pins = F103_CAN_PINS.get(board.afio.can_remap(), {})
    # SPI1 as master takes MISO (PA6) from a pin left as a floating input, its reset value.
    inputs_in_use = {("A", 6)} if board.spi1.enabled_master() else set()
    rows = []
    for port in (board.gpioa, board.gpiob, board.gpioc):
        letter = port.name[-1]
        for pin in range(16):
            if port.pin_config(pin) == 0x4 and (letter, pin) not in inputs_in_use:
                continue  # reset value (floating input) and no peripheral reads it
            mode = port.pin_mode(pin)
            function = can_pins.get((letter, pin)) or F103_FUNCTIONS.get((letter, pin, mode))
            if function is None:
                raise SystemExit(f"P{letter}{pin} is configured as {mode} but has no known function here")
            text = MODE_TEXT[mode]
            if mode == "input" and port.pin_config(pin) == 0x8:  # CNF 10: pull-up/down, ODR picks
                text = "input with pull-up" if (port.odr >> pin) & 1 else "input with pull-down"
            rows.append((f"P{letter}{pin}", text, function, SENSOR_PARTNER[function]))
    return rows


def sink_rows(path=SINK_BOARD):
    """(pin, mode, function, partner) of every pin the sink's board set-up configures."""
    text = open(path, encoding="utf-8").read()
    defines = dict(re.findall(r"#define\s+(\w+)\s+(\d+)u", text))

    def number(token):
        token = token.strip()
        return int(defines.get(token, token.rstrip("u")))

    rows = []
    for port, pin, af, pull in re.findall(r"f4_gpio_af\(F4_GPIO([A-K]),\s*(\w+),\s*(\w+),\s*(\d)\)", text):
        function = F407_AF.get((port, number(pin), number(af)))
        if function is None:
            raise SystemExit(f"P{port}{number(pin)} AF{number(af)} has no known function here")
        mode = f"alternate function {number(af)}" + (" with pull-up" if pull == "1" else "")
        rows.append((f"P{port}{number(pin)}", mode, function, SINK_PARTNER[function]))
    for port, pin in re.findall(r"f4_gpio_output\(F4_GPIO([A-K]),\s*(\w+)\)", text):
        rows.append((f"P{port}{number(pin)}", "push-pull output", "GPIO output", SINK_PARTNER["GPIO output"]))
    if not rows:
        raise SystemExit(f"no pin set-up found in {path}")
    return sorted(rows, key=lambda r: (r[0][1], int(r[0][2:])))


def table(rows):
    lines = ["| MCU pin | configured as | function | goes to |", "|---|---|---|---|"]
    lines += [f"| {pin} | {mode} | {function} | {partner} |" for pin, mode, function, partner in rows]
    return lines


def replace_block(doc, name, lines):
    begin, end = f"<!-- wiring:{name} (tests/firmware_loop/wiring.py) -->", f"<!-- /wiring:{name} -->"
    pattern = re.compile(re.escape(begin) + r"\n.*?" + re.escape(end), re.S)
    if not pattern.search(doc):
        raise SystemExit(f"the document has no {begin} ... {end} block")
    return pattern.sub(lambda _: "\n".join([begin] + lines + [end]), doc)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--check", metavar="DOC")
    group.add_argument("--write", metavar="DOC")
    parser.add_argument("--elf", default=os.environ.get("FIRMWARE_F103_ELF", ""),
                        help="sensor_node_f103.elf (default: $FIRMWARE_F103_ELF)")
    args = parser.parse_args()
    if not args.elf:
        raise SystemExit("the sensor-node image is needed: --elf or FIRMWARE_F103_ELF")
    blocks = {"sensor_node": table(sensor_rows(args.elf)), "sink_node": table(sink_rows())}
    path = args.check or args.write
    if path is None:
        for name, lines in blocks.items():
            print(f"{name}:\n" + "\n".join(lines) + "\n")
        return 0
    doc = open(path, encoding="utf-8").read()
    new = doc
    for name, lines in blocks.items():
        new = replace_block(new, name, lines)
    if args.write:
        if new != doc:
            with open(path, "w", encoding="utf-8") as f:
                f.write(new)
        return 0
    if new != doc:
        sys.stdout.writelines(difflib.unified_diff(doc.splitlines(True), new.splitlines(True), path, "from the firmware"))
        print(f"\n{path}: the wiring tables differ from the pins the firmware configures; "
              f"regenerate with tests/firmware_loop/wiring.py --write {path}")
        return 1
    print(f"{path}: wiring tables agree with the firmware ({len(blocks['sensor_node']) - 2} sensor-node pins, "
          f"{len(blocks['sink_node']) - 2} sink pins)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
