"""An ESP8266 (ESP-01) running Espressif's AT firmware, on the sink's USART, with a real TCP
socket behind AT+CIPSTART.

Written from Espressif's "ESP8266 AT Instruction Set" (v1.x/v2.x, the commands the sink
uses): the module boots at 115200 baud with echo on and prints `ready`; `AT+RST` answers `OK`
and reboots (echo on again, back at 115200: AT+UART_CUR is not kept); `ATE0` turns echo off;
`AT+UART_CUR=<baud>,8,1,0,0` answers `OK` at the old rate, then switches; `AT+CWMODE=1`;
`AT+CWJAP="ssid","pwd"` (backslash escapes) answers `WIFI CONNECTED`, `WIFI GOT IP`, `OK`
after the join time, or `+CWJAP:2` and `FAIL` for a wrong password; `AT+CIPMUX=0`;
`AT+CIPSTART="TCP","host",port` answers `CONNECT` and `OK`, or `ERROR` and `CLOSED` when the
connection fails, `ALREADY CONNECTED` and `ERROR` when one is open; `AT+CIPSEND=<n>` answers
`OK` and the prompt `> `, takes n bytes, then `Recv n bytes` and `SEND OK`, or `link is not
valid` and `ERROR` without a connection; `AT+CIPCLOSE` answers `CLOSED` and `OK`. Data from
the peer comes unsolicited as `+IPD,<n>:` and the bytes; the peer closing as `CLOSED`.

The Wi-Fi network is a routing table: `routes` maps the (host, port) the image dials to a
real (address, port), here mocapd's sink port on loopback. The socket is real (blocking
connect, non-blocking reads polled every `POLL_US` of virtual time).

Faults a test can inject: `drop_link()` (the access point or peer drops the connection: the
module reports `CLOSED`), `errors` (command prefixes answered `ERROR`), `mute` (the module
answers nothing, as a hung one; bytes it gets are lost).
"""

import select
import socket

from virtual_clock import ticks_from_us

BOOT_BAUD = 115200
COMMAND_US = 2_000  # a command's answer (the module's own processing)
RESET_US = 200_000  # AT+RST to `ready` (an ESP-01 boots in 0.2-0.5 s)
JOIN_US = 500_000  # AT+CWJAP to `WIFI GOT IP` (an access point nearby: 0.5-3 s)
SEND_US = 2_000  # the bytes of a CIPSEND in the socket to `SEND OK`
POLL_US = 1_000


def _unquote_args(text):
    """Splits `"a","b",3` into ['a', 'b', '3'] with the AT firmware's backslash escapes."""
    args, cur, quoted, i = [], "", False, 0
    while i < len(text):
        c = text[i]
        if c == "\\" and i + 1 < len(text):
            cur += text[i + 1]
            i += 2
            continue
        if c == '"':
            quoted = not quoted
        elif c == "," and not quoted:
            args.append(cur)
            cur = ""
        else:
            cur += c
        i += 1
    args.append(cur)
    return args


class Esp8266:
    def __init__(self, ssid, password, routes):
        self.ssid, self.password, self.routes = ssid, password, routes
        self.reset_us, self.join_us = RESET_US, JOIN_US  # a test may choose a quicker access point
        self.errors = set()
        self.mute = False
        self.log = []  # (tick, command line) as received
        self.lost_bytes = 0  # bytes that arrived at a rate the module was not at
        self.connects = 0
        self.sent_bytes = 0
        self.sock = None
        self._power_on()

    def _power_on(self):
        self.baud = BOOT_BAUD
        self.echo = True
        self.wifi = False
        self.out = []  # (ready tick, byte, baud)
        self.line = b""
        self.send_left = 0
        self.send_buf = b""
        self.timers = []  # (tick, callable)
        self.next_poll = 0
        self._close_socket()
        self.now = 0

    # --- USART side ---
    def peek_tx(self):
        return self.out[0] if self.out else None

    def pop_tx(self):
        self.out.pop(0)

    def _say(self, text, delay_us=0, baud=None):
        ready = max([self.now + ticks_from_us(delay_us)] + [t for t, _, _ in self.out[-1:]])
        data = text.encode() if isinstance(text, str) else text
        self.out.extend((ready, b, baud or self.baud) for b in data)

    def _after(self, delay_us, action):
        self.timers.append((self.now + ticks_from_us(delay_us), action))

    def update(self, tick):
        self.now = tick
        due = [t for t in self.timers if t[0] <= tick]
        if due:
            self.timers = [t for t in self.timers if t[0] > tick]
            for _, action in sorted(due, key=lambda t: t[0]):
                action()
        if self.sock is not None and tick >= self.next_poll:
            self.next_poll = tick + ticks_from_us(POLL_US)
            self._poll_socket()

    def receive_byte(self, byte, tick, baud):
        self.update(tick)
        if abs(baud - self.baud) > 0.03 * self.baud:
            self.lost_bytes += 1
            return
        if self.mute:
            return
        if self.send_left:
            self.send_buf += bytes([byte])
            self.send_left -= 1
            if not self.send_left:
                self._send_payload()
            return
        if self.echo:
            self._say(bytes([byte]))
        if byte == 0x0A:
            line = self.line.rstrip(b"\r").decode(errors="replace")
            self.line = b""
            if line:
                self.log.append((tick, line))
                self._command(line)
        else:
            self.line += bytes([byte])

    # --- commands ---
    def _command(self, line):
        if any(line.startswith(prefix) for prefix in self.errors):
            self._say("\r\nERROR\r\n", COMMAND_US)
            return
        name, _, arg = line.partition("=")
        handler = {"AT": self._ok, "AT+RST": self._rst, "ATE0": self._echo_off, "ATE1": self._echo_on,
                   "AT+UART_CUR": self._uart, "AT+CWMODE": self._ok, "AT+CWJAP": self._join,
                   "AT+CIPMUX": self._ok, "AT+CIPSTART": self._start, "AT+CIPSEND": self._send,
                   "AT+CIPCLOSE": self._close}.get(name)
        if handler is None:
            self._say("\r\nERROR\r\n", COMMAND_US)
        else:
            handler(arg)

    def _ok(self, _arg):
        self._say("\r\nOK\r\n", COMMAND_US)

    def _echo_off(self, _arg):
        self.echo = False
        self._ok(_arg)

    def _echo_on(self, _arg):
        self.echo = True
        self._ok(_arg)

    def _rst(self, _arg):
        self._ok(_arg)
        self._after(COMMAND_US + 1000, self._reboot)

    def _reboot(self):
        out, now = self.out, self.now
        self._power_on()
        self.now = now
        self.out = out  # what was already on the line still leaves
        self._say("\r\nready\r\n", self.reset_us)

    def _uart(self, arg):
        baud = int(_unquote_args(arg)[0])
        self._say("\r\nOK\r\n", COMMAND_US)
        self.baud = baud  # the bytes already queued keep the old rate

    def _join(self, arg):
        args = _unquote_args(arg)
        if args[:2] == [self.ssid, self.password]:
            self._after(self.join_us, self._joined)
        else:
            self._say("+CWJAP:2\r\n\r\nFAIL\r\n", self.join_us)

    def _joined(self):
        self.wifi = True
        self._say("WIFI CONNECTED\r\nWIFI GOT IP\r\n\r\nOK\r\n")

    def _start(self, arg):
        args = _unquote_args(arg)
        if self.sock is not None:
            self._say("ALREADY CONNECTED\r\n\r\nERROR\r\n", COMMAND_US)
            return
        target = self.routes.get((args[1], int(args[2]))) if self.wifi and len(args) == 3 else None
        try:
            if target is None:
                raise OSError("no route")
            self.sock = socket.create_connection(target, timeout=10)
        except OSError:
            self._say("ERROR\r\nCLOSED\r\n", COMMAND_US)
            return
        self.connects += 1
        self.sock.settimeout(10)
        self._say("CONNECT\r\n\r\nOK\r\n", COMMAND_US)

    def _send(self, arg):
        n = int(arg)
        if self.sock is None:
            self._say("link is not valid\r\n\r\nERROR\r\n", COMMAND_US)
            return
        if not 0 < n <= 2048:
            self._say("\r\nERROR\r\n", COMMAND_US)
            return
        self.send_left, self.send_buf = n, b""
        self._say("\r\nOK\r\n> ", COMMAND_US)

    def _send_payload(self):
        data = self.send_buf
        self._say(f"\r\nRecv {len(data)} bytes\r\n")
        if self.sock is None:
            self._say("\r\nSEND FAIL\r\n", SEND_US)
            return
        try:
            self.sock.sendall(data)
        except OSError:
            self._say("\r\nSEND FAIL\r\n", SEND_US)
            self._peer_closed()
            return
        self.sent_bytes += len(data)
        self._say("\r\nSEND OK\r\n", SEND_US)

    def _close(self, _arg):
        if self.sock is None:
            self._say("\r\nERROR\r\n", COMMAND_US)
            return
        self._close_socket()
        self._say("CLOSED\r\n\r\nOK\r\n", COMMAND_US)

    # --- the socket ---
    def _close_socket(self):
        if getattr(self, "sock", None) is not None:
            self.sock.close()
        self.sock = None

    def _peer_closed(self):
        self._close_socket()
        self._say("CLOSED\r\n")

    def _poll_socket(self):
        try:
            if not select.select([self.sock], [], [], 0)[0]:
                return
            data = self.sock.recv(1460)
        except OSError:
            data = b""
        if not data:
            self._peer_closed()
        elif not self.mute:
            self._say(f"\r\n+IPD,{len(data)}:".encode() + data)

    def drop_link(self):
        """The connection is lost (access point, peer, radio): `CLOSED`, as the module reports it."""
        if self.sock is not None:
            self._peer_closed()
