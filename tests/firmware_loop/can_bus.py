"""A virtual CAN bus on virtual time: frames take their real length in bits (with bit
stuffing, ISO 11898-1), the bus is idle in between, and when several senders have a frame
ready the lowest identifier wins arbitration, as the wired-AND bit-by-bit arbitration decides
it. A frame that starts inside one of `error_windows` (a disturbed or shorted line) ends in
an error frame, as one nobody acknowledges does. Senders are bxCAN models (bxcan.py) and `HostPort`s (frames the test injects, e.g. the
sink's SYNC). Every frame on the bus is logged with its start and end tick.
"""

from virtual_clock import ticks_per

CRC15_POLY = 0x4599


def _crc15(bits):
    crc = 0
    for b in bits:
        nxt = b ^ ((crc >> 14) & 1)
        crc = (crc << 1) & 0x7FFF
        if nxt:
            crc ^= CRC15_POLY
    return crc


def frame_bits(can_id, data):
    """Length in bits of a standard data frame on the wire: SOF through CRC with stuff bits,
    then CRC delimiter, ACK slot and delimiter, 7 EOF bits and 3 intermission bits."""
    bits = [0] + [(can_id >> (10 - i)) & 1 for i in range(11)] + [0, 0, 0]  # SOF, ID, RTR, IDE, r0
    bits += [(len(data) >> (3 - i)) & 1 for i in range(4)]
    for byte in data:
        bits += [(byte >> (7 - i)) & 1 for i in range(8)]
    crc = _crc15(bits)
    bits += [(crc >> (14 - i)) & 1 for i in range(15)]
    stuffed, run, last = 0, 0, None
    for b in bits:
        run = run + 1 if b == last else 1
        last = b
        if run == 5:
            stuffed += 1
            last, run = 1 - b, 1  # the stuff bit starts a new run
    return len(bits) + stuffed + 1 + 2 + 7 + 3


class HostPort:
    """A sender/receiver driven by the test: queue frames with the tick they are ready at."""

    def __init__(self):
        self.queue = []  # (ready_tick, can_id, data)
        self.received = []

    def send(self, ready_tick, can_id, data):
        self.queue.append((ready_tick, can_id, bytes(data)))

    def contender(self, tick):
        ready = [f for f in self.queue if f[0] <= tick]
        if not ready:
            return None
        return min(ready, key=lambda f: (f[1], f[0]))

    def next_ready(self):
        return min((f[0] for f in self.queue), default=None)

    def transmitted(self, frame, ok):
        self.queue.remove(frame)

    def receive(self, can_id, data, tick):
        self.received.append((tick, can_id, bytes(data)))

    def joined(self, bit_ticks):
        return True


class CanBus:
    def __init__(self, clock, bitrate):
        self.clock = clock
        self.bit_ticks = ticks_per(bitrate)
        self.nodes = []
        self.idle_at = 0  # tick from which the bus is idle
        self.log = []  # (start tick, end tick, sender index, can_id, data)
        self.errors = []  # (start tick, sender index, can_id) of attempts nobody acknowledged
        self.error_windows = []  # (from tick, to tick): every frame started inside fails
        self.next_event = None

    def attach(self, node):
        self.nodes.append(node)
        return len(self.nodes) - 1

    def update(self):
        """Runs the bus up to the current time. Afterwards `next_event` is the tick at which
        the bus has something to do next as far as it knows (a frame in progress ends, a
        queued frame becomes ready), or None: a scheduler that steps the CPUs to it delivers
        each frame to its receivers at its end. Frames a CPU requests meanwhile are seen at
        the next update, with the tick they were requested at."""
        now = self.clock.ticks
        self.next_event = None
        while True:
            ready = [n.next_ready() for n in self.nodes]
            ready = [t for t in ready if t is not None]
            if not ready:
                return
            start = max(self.idle_at, min(ready))
            if start > now:
                self.next_event = start
                return
            contenders = []
            for i, n in enumerate(self.nodes):
                frame = n.contender(start)
                if frame is not None:
                    contenders.append((frame[1], i, frame))
            if not contenders:
                self.idle_at = start + 1
                continue
            can_id, sender, frame = min(contenders)
            node = self.nodes[sender]
            disturbed = any(a <= start < b for a, b in self.error_windows)
            if disturbed or not node.joined(self.bit_ticks):
                # Wrong bit rate, TX pin not on the bus, or a disturbance on the wires: the
                # frame is not acknowledged (or its bits are destroyed) and an error frame
                # (6 dominant + 8 delimiter bits) follows the first bits.
                self.idle_at = start + 20 * self.bit_ticks
                self.errors.append((start, sender, can_id))
                node.transmitted(frame, False)
                continue
            data = frame[2]
            end = start + frame_bits(can_id, data) * self.bit_ticks
            if end > now:
                self.next_event = end
                return  # completes later; look again then
            self.idle_at = end
            self.log.append((start, end, sender, can_id, data))
            node.transmitted(frame, True)
            for j, other in enumerate(self.nodes):
                if j != sender:
                    other.receive(can_id, data, end)
