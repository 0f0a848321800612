"""Length-delimited framing of the pose service: a base-128 varint length, then the bytes.

This is protobuf's own delimited format (writeDelimitedTo / parseDelimitedFrom), the same
as server/serve/framing.hpp. No I/O here: DelimitedReader is fed bytes in any split (one
byte at a time is fine) and returns whole messages.
"""

from __future__ import annotations

#: Lengths are at most 32 bits, so a length prefix is at most 5 bytes.
MAX_LENGTH_PREFIX_BYTES = 5


class FramingError(ValueError):
    """The stream cannot be decoded (bad prefix or a message above the size limit)."""


def encode_varint(value: int) -> bytes:
    """Base-128 varint, least significant group first."""
    if value < 0:
        raise ValueError("varint of a negative number")
    out = bytearray()
    while True:
        group = value & 0x7F
        value >>= 7
        if value:
            out.append(group | 0x80)
        else:
            out.append(group)
            return bytes(out)


def decode_varint(data: bytes | bytearray | memoryview, pos: int = 0) -> tuple[int, int] | None:
    """Decodes a length prefix at `pos`.

    Returns (value, position after the prefix), or None when the prefix is incomplete.
    Raises FramingError when it is longer than 5 bytes or above 32 bits.
    """
    value = 0
    for i in range(MAX_LENGTH_PREFIX_BYTES):
        if pos + i >= len(data):
            return None
        byte = data[pos + i]
        value |= (byte & 0x7F) << (7 * i)
        if not byte & 0x80:
            if value > 0xFFFFFFFF:
                raise FramingError(f"length prefix {value} is above 32 bits")
            return value, pos + i + 1
    raise FramingError("length prefix longer than 5 bytes")


def frame_message(payload: bytes) -> bytes:
    """`payload` (a serialised message) with its length prefix."""
    return encode_varint(len(payload)) + payload


class DelimitedReader:
    """Incremental decoder of a delimited stream.

    `max_message_bytes` bounds one message (prefix not counted): a longer announced
    length is an error before any of its bytes are buffered. After an error the reader
    stays failed: a byte stream cannot be resynchronised.
    """

    def __init__(self, max_message_bytes: int = 16 << 20):
        self.max_message_bytes = max_message_bytes
        self._buf = bytearray()
        self._begin = 0  # first unconsumed byte
        self._error: FramingError | None = None

    def feed(self, data: bytes) -> None:
        if self._begin and self._begin * 2 >= len(self._buf):
            del self._buf[: self._begin]  # compact now and then, not on every message
            self._begin = 0
        self._buf += data

    def pop(self) -> bytes | None:
        """The next complete message, or None until more bytes arrive."""
        if self._error is not None:
            raise self._error
        try:
            prefix = decode_varint(self._buf, self._begin)
            if prefix is None:
                return None
            length, start = prefix
            if length > self.max_message_bytes:
                raise FramingError(f"message of {length} bytes is above the limit of {self.max_message_bytes}")
        except FramingError as e:
            self._error = e
            raise
        end = start + length
        if end > len(self._buf):
            return None
        self._begin = end
        return bytes(self._buf[start:end])

    def messages(self, data: bytes = b""):
        """Feeds `data`, then yields every complete message."""
        if data:
            self.feed(data)
        while (message := self.pop()) is not None:
            yield message

    @property
    def buffered(self) -> int:
        """Bytes received but not yet returned as messages."""
        return len(self._buf) - self._begin
