"""Framing and message handling of mocapd_client, without a daemon (a fake server where
the stream itself is under test)."""

from __future__ import annotations

import socket
import threading

import pytest

import mocapd_client as mc
from mocapd_client import pb


@pytest.mark.parametrize("value, encoded", [
    (0, b"\x00"), (1, b"\x01"), (127, b"\x7f"), (128, b"\x80\x01"), (300, b"\xac\x02"),
    (0xFFFFFFFF, b"\xff\xff\xff\xff\x0f"),
])
def test_varint_known_bytes_and_round_trip(value, encoded):
    assert mc.encode_varint(value) == encoded
    assert mc.decode_varint(encoded) == (value, len(encoded))
    assert mc.decode_varint(b"xx" + encoded + b"tail", 2) == (value, 2 + len(encoded))


def test_ping_example_from_the_protocol_document():
    msg = pb.ClientMessage()
    msg.ping.nonce = 1
    assert mc.frame_message(msg.SerializeToString()) == bytes([0x04, 0x22, 0x02, 0x08, 0x01])


def test_incomplete_prefix_waits_for_more():
    assert mc.decode_varint(b"") is None
    assert mc.decode_varint(b"\x80\x80") is None


def test_prefix_longer_than_five_bytes_or_above_32_bits_is_an_error():
    with pytest.raises(mc.FramingError):
        mc.decode_varint(b"\x80\x80\x80\x80\x80\x01")
    with pytest.raises(mc.FramingError):
        mc.decode_varint(b"\xff\xff\xff\xff\x1f")  # 2^37 - 1


def server_messages():
    out = []
    hello = pb.ServerMessage()
    hello.hello.server_version = "mocapd test"
    hello.hello.protocol_version = 1
    seg = hello.hello.skeleton.segments.add()
    seg.name, seg.parent = "pelvis", -1
    out.append(hello)
    for sync in range(3):
        f = pb.ServerMessage()
        f.frame.subject_id, f.frame.sync, f.frame.segment_count = 1, 100 + sync, 1
        f.frame.flags.append(0)
        f.frame.q_world_segment_wxyz.extend([1.0, 0.0, 0.0, 0.0])
        out.append(f)
    empty = pb.ServerMessage()  # a zero-length message is legal
    out.append(empty)
    big = pb.ServerMessage()
    big.frame.position_m.extend([float(i) for i in range(3000)])  # prefix of 2+ bytes
    out.append(big)
    return out


def test_round_trip_through_the_reader_in_any_split():
    messages = server_messages()
    stream = b"".join(mc.frame_message(m.SerializeToString()) for m in messages)
    for chunk in (1, 2, 7, len(stream)):
        reader = mc.DelimitedReader(1 << 20)
        got = []
        for i in range(0, len(stream), chunk):
            got.extend(pb.ServerMessage.FromString(p) for p in reader.messages(stream[i:i + chunk]))
        assert got == messages, f"chunk {chunk}"
        assert reader.buffered == 0


def test_oversized_message_fails_before_its_bytes_arrive_and_stays_failed():
    reader = mc.DelimitedReader(max_message_bytes=100)
    reader.feed(mc.encode_varint(101))
    with pytest.raises(mc.FramingError):
        reader.pop()
    reader.feed(b"\x00" * 101)
    with pytest.raises(mc.FramingError):
        reader.pop()
    ok = mc.DelimitedReader(max_message_bytes=100)
    assert list(ok.messages(mc.frame_message(b"\x00" * 100))) == [b"\x00" * 100]


@pytest.mark.parametrize("text, expected", [
    ("127.0.0.1:7001", ("127.0.0.1", 7001)), ("localhost", ("localhost", 7001)),
    ("[::1]:9000", ("::1", 9000)), ("[::1]", ("::1", 7001)),
])
def test_parse_endpoint(text, expected):
    assert mc.parse_endpoint(text) == expected


@pytest.mark.parametrize("text", ["", ":7001", "host:0", "host:65536", "host:x", "[::1:7001"])
def test_parse_endpoint_rejects(text):
    with pytest.raises(ValueError):
        mc.parse_endpoint(text)


class FakeServer:
    """Accepts one connection, sends `data`, then closes its side (or, with close=False,
    stays silent) until the client closes."""

    def __init__(self, data: bytes, close: bool = True):
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.thread = threading.Thread(target=self.run, args=(data, close), daemon=True)
        self.thread.start()

    def run(self, data: bytes, close: bool):
        conn, _ = self.sock.accept()
        with conn:
            conn.sendall(data)
            if close:
                conn.shutdown(socket.SHUT_WR)
            while conn.recv(1 << 16):
                pass
        self.sock.close()


def hello_then(*messages) -> bytes:
    return b"".join(mc.frame_message(m.SerializeToString()) for m in (server_messages()[0], *messages))


def test_garbage_prefix_is_a_protocol_error():
    server = FakeServer(b"\xff" * 6)
    c = mc.Client("127.0.0.1", server.port, timeout=2)
    with pytest.raises(mc.ProtocolError):
        c.connect()
    assert not c.is_open


def test_unparseable_message_is_a_protocol_error():
    server = FakeServer(mc.frame_message(b"\x0a\xff"))  # field 1 with a length beyond the bytes
    with pytest.raises(mc.ProtocolError):
        mc.Client("127.0.0.1", server.port, timeout=2).connect()


def test_frames_end_at_goodbye_and_drop_notices_are_summed():
    frames = server_messages()[1:4]
    drops = pb.ServerMessage()
    drops.drops.dropped, drops.drops.dropped_total = 5, 5
    bye = pb.ServerMessage()
    bye.goodbye.reason = pb.GOODBYE_SHUTDOWN
    server = FakeServer(hello_then(frames[0], drops, frames[1], frames[2], bye))
    with mc.Client("127.0.0.1", server.port, timeout=2) as c:
        assert c.info.server_version == "mocapd test"
        got = list(c.frames(idle_timeout=2))
    assert [f.sync for f in got] == [100, 101, 102]
    assert got[0].q.shape == (1, 4) and got[0].p.shape == (0, 3)
    assert got[0].to_dict()["segments"] == [{"flags": 0, "name": "pelvis", "q": [1.0, 0.0, 0.0, 0.0]}]
    assert c.drops_announced == 5
    assert c.goodbye.reason == pb.GOODBYE_SHUTDOWN


def test_a_request_without_reply_times_out():
    server = FakeServer(hello_then(), close=False)
    with mc.Client("127.0.0.1", server.port, timeout=0.3) as c:
        with pytest.raises(TimeoutError):
            c.stats()
        assert c.next_frame(timeout=0.1) is None
