"""Blocking client of the mocapd pose service (TCP, default port 7001).

The conversation (docs/client-protocol.md): the server greets with Hello, the client
subscribes, frames flow; Stats, Control and Ping requests may be sent at any time and
their replies are never dropped. Every call is bounded by a timeout; nothing waits forever.

Frames that arrive while a call waits for its reply are kept (up to `frame_buffer`, the
oldest dropped beyond and counted in `frames_discarded`) and come out of frames() next.

Thread-safety: none; use one Client per thread.
"""

from __future__ import annotations

import collections
import socket
import time
from collections.abc import Iterable, Iterator

from google.protobuf.message import DecodeError

from .framing import DelimitedReader, FramingError, frame_message
from .proto import pb
from .types import ControlReply, Fields, Frame, ServerInfo, Stats, Subscription

DEFAULT_PORT = 7001


class ProtocolError(Exception):
    """The server sent something that is not a valid ServerMessage stream."""


class ConnectionClosed(ConnectionError):
    """The server closed the connection; `goodbye` is its reason (None if it gave none)."""

    def __init__(self, goodbye=None):
        self.goodbye = goodbye
        if goodbye is None:
            text = "connection closed by the server"
        else:
            text = f"server said goodbye: {pb.GoodbyeReason.Name(goodbye.reason)} {goodbye.message}".rstrip()
        super().__init__(text)


def parse_endpoint(text: str, default_port: int = DEFAULT_PORT) -> tuple[str, int]:
    """"HOST:PORT", "[v6-address]:PORT", "HOST" (default port)."""
    if text.startswith("["):
        host, sep, rest = text[1:].partition("]")
        if not sep:
            raise ValueError(f"bad endpoint {text!r}: missing ']'")
        port = rest[1:] if rest.startswith(":") else ""
    elif text.count(":") == 1:
        host, _, port = text.partition(":")
    else:
        host, port = text, ""
    if not host:
        raise ValueError(f"bad endpoint {text!r}: no host")
    if not port:
        return host, default_port
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"bad endpoint {text!r}: port must be 1..65535")
    return host, int(port)


def wall_clock_us() -> int:
    """CLOCK_REALTIME in µs since the epoch: the clock of the frames' stage stamps."""
    return time.time_ns() // 1000


class Client:
    """One connection to the pose service.

        with Client("127.0.0.1", 7001) as c:          # connects and reads the Hello
            c.subscribe(fields=Fields.ORIENTATIONS | Fields.JOINT_ANGLES)
            for frame in c.frames(duration=10):
                frame.q, frame.joint_angles["left_knee.flexion"]
    """

    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT, *, timeout: float = 5.0,
                 max_message_bytes: int = 16 << 20, frame_buffer: int = 4096):
        self.host = host
        self.port = port
        self.timeout = timeout
        self.max_message_bytes = max_message_bytes
        self.frame_buffer = frame_buffer
        self.info: ServerInfo | None = None
        self.subscription: Subscription | None = None
        self.goodbye = None  # the server's Goodbye message, once it sent one
        self.drops_announced = 0  # frames the server dropped for this client (DropNotices)
        self.frames_discarded = 0  # frames this client dropped from its own buffer
        self.last_receive_us = 0  # CLOCK_REALTIME µs of the last read from the socket
        self._sock: socket.socket | None = None
        self._reader = DelimitedReader(max_message_bytes)
        self._pending: collections.deque = collections.deque()  # (SkeletonFrame, receive_us)
        self._next_request_id = 1

    @classmethod
    def from_endpoint(cls, endpoint: str, **kwargs) -> Client:
        host, port = parse_endpoint(endpoint)
        return cls(host, port, **kwargs)

    # -- connection ----------------------------------------------------------------------

    def connect(self) -> ServerInfo:
        """Connects (TCP_NODELAY) and waits for the Hello."""
        self.close()
        self._reader = DelimitedReader(self.max_message_bytes)
        self._pending.clear()
        self.goodbye = None
        self._sock = socket.create_connection((self.host, self.port), timeout=self.timeout)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        hello = self._wait_for("hello", self.timeout)
        self.info = ServerInfo.from_proto(hello)
        return self.info

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    @property
    def is_open(self) -> bool:
        return self._sock is not None

    def __enter__(self) -> Client:
        if self._sock is None:
            self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- requests ------------------------------------------------------------------------

    def subscribe(self, subjects: Iterable[int] | None = None, decimation: int = 1,
                  fields: Fields | int = Fields.DEFAULT) -> Subscription:
        """Replaces the subscription. subjects: None/empty = every subject, also later ones;
        decimation: every n-th frame of each subject; fields: Fields bits (DEFAULT =
        orientations + positions). Returns what the server applied."""
        msg = pb.ClientMessage()
        msg.subscribe.subject_ids.extend(list(subjects or []))
        msg.subscribe.decimation = decimation
        msg.subscribe.fields = int(fields)
        self._send(msg)
        s = self._wait_for("subscribed", self.timeout)
        self.subscription = Subscription(list(s.subject_ids), s.decimation, Fields(s.fields), s.queue_frames)
        return self.subscription

    def stats(self) -> Stats:
        """The daemon's counters and per-stage latency percentiles."""
        msg = pb.ClientMessage()
        msg.stats_request.request_id = request_id = self._request_id()
        return Stats.from_proto(self._exchange(msg, "stats", request_id))

    def control(self, token: str, *, calibrate: int | None = None, pose: str = "T",
                start_recording: str | None = None, stop_recording: bool = False,
                reload: bool = False) -> ControlReply:
        """One control action (exactly one of calibrate=SUBJECT_ID [pose "T"|"N"],
        start_recording=PATH ("" = the daemon's default), stop_recording, reload).
        A refusal (no/bad token, not loopback, control disabled) is a reply with ok=False."""
        actions = [calibrate is not None, start_recording is not None, stop_recording, reload]
        if sum(actions) != 1:
            raise ValueError("control needs exactly one action")
        msg = pb.ClientMessage()
        req = msg.control
        req.request_id = request_id = self._request_id()
        req.token = token
        if calibrate is not None:
            poses = {"T": pb.POSE_T, "N": pb.POSE_N}
            if pose not in poses:
                raise ValueError(f"pose must be T or N, not {pose!r}")
            req.calibrate.subject_id = calibrate
            req.calibrate.pose = poses[pose]
        elif start_recording is not None:
            req.start_recording.path = start_recording
        elif stop_recording:
            req.stop_recording.SetInParent()
        else:
            req.reload.SetInParent()
        reply = self._exchange(msg, "control_reply", request_id)
        return ControlReply(reply.ok, reply.error)

    def ping(self) -> float:
        """Round trip in seconds. Keeps an unsubscribed connection alive as well."""
        msg = pb.ClientMessage()
        msg.ping.nonce = nonce = self._request_id()
        msg.ping.client_time_us = wall_clock_us()
        start = time.monotonic()
        self._exchange(msg, "pong", nonce, id_field="nonce")
        return time.monotonic() - start

    # -- frames --------------------------------------------------------------------------

    def next_frame(self, timeout: float | None = None, raw: bool = False):
        """The next frame (a Frame, or the SkeletonFrame message when raw), or None when none
        arrived within `timeout` seconds (None = self.timeout). Raises ConnectionClosed."""
        if not self._pending:
            wait = self.timeout if timeout is None else timeout
            deadline = time.monotonic() + wait
            while not self._pending:
                msg = self._read(deadline)
                if msg is None:
                    return None
                self._note(msg)
        message, receive_us = self._pending.popleft()
        if raw:
            return message
        return Frame.from_proto(message, receive_us, self.info.skeleton if self.info else None)

    def frames(self, *, duration: float | None = None, count: int | None = None,
               idle_timeout: float | None = 5.0, raw: bool = False) -> Iterator:
        """Yields frames until `duration` seconds passed or `count` frames came, or the server
        closed the connection (then `goodbye` says why, if it did). Raises TimeoutError when
        no frame arrives for `idle_timeout` seconds (None = wait as long as it takes)."""
        end = None if duration is None else time.monotonic() + duration
        delivered = 0
        while (count is None or delivered < count) and (end is None or time.monotonic() < end):
            limit = idle_timeout
            if end is not None:
                left = max(0.0, end - time.monotonic())
                limit = left if limit is None else min(limit, left)
            try:
                frame = self.next_frame(limit if limit is not None else 1e9, raw=raw)
            except ConnectionClosed:
                return
            if frame is None:
                if end is not None and time.monotonic() >= end:
                    return
                raise TimeoutError(f"no frame within {idle_timeout} s")
            delivered += 1
            yield frame

    # -- internals -----------------------------------------------------------------------

    def _request_id(self) -> int:
        rid = self._next_request_id
        self._next_request_id += 1
        return rid

    def _send(self, msg) -> None:
        if self._sock is None:
            raise ConnectionError("not connected")
        self._sock.settimeout(self.timeout)
        self._sock.sendall(frame_message(msg.SerializeToString()))

    def _exchange(self, msg, kind: str, request_id: int, id_field: str = "request_id"):
        self._send(msg)
        return self._wait_for(kind, self.timeout, lambda m: getattr(m, id_field) == request_id)

    def _wait_for(self, kind: str, timeout: float, match=None):
        """Reads until a ServerMessage whose body is `kind` (and `match` accepts it)."""
        deadline = time.monotonic() + timeout
        while True:
            msg = self._read(deadline)
            if msg is None:
                raise TimeoutError(f"no {kind} within {timeout} s")
            self._note(msg)
            if msg.WhichOneof("body") == kind:
                body = getattr(msg, kind)
                if match is None or match(body):
                    return body

    def _note(self, msg) -> None:
        body = msg.WhichOneof("body")
        if body == "frame":
            if len(self._pending) >= self.frame_buffer:
                self._pending.popleft()
                self.frames_discarded += 1
            self._pending.append((msg.frame, self.last_receive_us))
        elif body == "drops":
            self.drops_announced += msg.drops.dropped
        elif body == "goodbye":
            self.goodbye = msg.goodbye

    def _read(self, deadline: float):
        """The next ServerMessage, or None at the deadline. Raises ConnectionClosed."""
        if self._sock is None:
            raise ConnectionClosed(self.goodbye)
        while True:
            try:
                payload = self._reader.pop()
            except FramingError as e:
                self.close()
                raise ProtocolError(str(e)) from e
            if payload is not None:
                try:
                    return pb.ServerMessage.FromString(payload)
                except DecodeError as e:
                    self.close()
                    raise ProtocolError(f"unparseable ServerMessage: {e}") from e
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            self._sock.settimeout(left)
            try:
                data = self._sock.recv(1 << 16)
            except socket.timeout:
                return None
            except OSError as e:  # reset by the peer
                self.close()
                raise ConnectionClosed(self.goodbye) from e
            if not data:
                self.close()
                raise ConnectionClosed(self.goodbye)
            self.last_receive_us = wall_clock_us()
            self._reader.feed(data)
