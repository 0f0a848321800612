"""Plain value types built from the protobuf messages: numpy arrays and dicts.

Everything here is a snapshot owned by the caller; nothing refers back to the connection.
Units as on the wire: metres, radians, microseconds (CLOCK_REALTIME for the stage stamps).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np


class Fields(enum.IntFlag):
    """Bits of Subscribe.fields (mocap.v1.Field)."""

    DEFAULT = 0  # the server applies ORIENTATIONS | POSITIONS
    ORIENTATIONS = 1  # Frame.q
    POSITIONS = 2  # Frame.p
    JOINT_ANGLES = 4  # Frame.joint_angles_rad / joint_angles
    RAW = 8  # Frame.q_raw (filter output before calibration)
    ALL = 15


class SegmentFlags(enum.IntFlag):
    """Bits of SkeletonFrame.flags (one value per segment)."""

    NONE = 0
    STALE = 1  # no sample at this instant: last good pose held
    NEVER_SEEN = 2  # no sample since start: identity
    CALIBRATED = 4  # sensor-to-segment calibration applied
    FROM_NODE = 8  # orientation computed on the node
    HEADING_MAG = 16  # heading from the segment's own magnetometer
    HEADING_JOINTS = 32  # heading held by the body's joints (docs/fusion.md)
    HEADING_GYRO = 64  # heading held by the gyroscope alone (nothing observed it lately)


@dataclass(frozen=True)
class Skeleton:
    """Hello.skeleton: segment order of every frame and the joint-angle names."""

    segment_names: list[str]
    parents: list[int]  # index of the parent segment, -1 for the root
    offsets_m: np.ndarray  # (N, 3) joint position in the parent's frame
    node_ids: list[int]  # CAN node id of each segment's sensor
    joint_angle_names: list[str]  # e.g. "left_knee.flexion"

    @classmethod
    def from_proto(cls, msg) -> Skeleton:
        segs = list(msg.segments)
        offsets = np.array([[s.offset_x_m, s.offset_y_m, s.offset_z_m] for s in segs], dtype=np.float64).reshape(-1, 3)
        return cls([s.name for s in segs], [s.parent for s in segs], offsets, [s.node_id for s in segs],
                   list(msg.joint_angle_names))

    def segment_index(self, name: str) -> int:
        return self.segment_names.index(name)


@dataclass(frozen=True)
class ServerInfo:
    """The Hello every connection starts with."""

    server_version: str
    protocol_version: int
    skeleton: Skeleton
    subjects: dict[int, str]  # id -> name, as configured when this client connected
    frame_rate_hz: int
    world_frame: str  # "ENU" or "NED"
    max_client_message_bytes: int
    subscribe_timeout_ms: int

    @classmethod
    def from_proto(cls, hello) -> ServerInfo:
        return cls(hello.server_version, hello.protocol_version, Skeleton.from_proto(hello.skeleton),
                   {s.id: s.name for s in hello.subjects}, hello.frame_rate_hz, hello.world_frame,
                   hello.max_client_message_bytes, hello.subscribe_timeout_ms)


@dataclass(frozen=True)
class Subscription:
    """Subscribed: what the server applied."""

    subject_ids: list[int]  # empty = every subject
    decimation: int
    fields: Fields
    queue_frames: int  # this client's queue; the oldest frame is dropped beyond it


_STAGES = ("sink_send_us", "received_us", "filtered_us", "assembled_us", "encoded_us")


@dataclass
class Frame:
    """One subject at one SYNC instant.

    Arrays the subscription did not select are empty (shape (0, 4) / (0, 3) / (0,)).
    q: (N, 4) w, x, y, z rotating segment-frame vectors into the world frame.
    p: (N, 3) segment (joint) positions in the world frame, metres.
    """

    subject_id: int
    sync: int  # SYNC counter, extended past its wrap: only grows
    sample_us: int  # sample instant on the sink's clock
    receive_us: int  # CLOCK_REALTIME when this client read the bytes
    times: dict[str, int]  # stage stamps, CLOCK_REALTIME µs (0 = unknown)
    flags: np.ndarray  # (N,) SegmentFlags bits
    q: np.ndarray
    p: np.ndarray
    joint_angles_rad: np.ndarray  # in Skeleton.joint_angle_names order
    q_raw: np.ndarray
    skeleton: Skeleton | None = field(repr=False, default=None)  # names of segments and angles

    @classmethod
    def from_proto(cls, msg, receive_us: int, skeleton: Skeleton | None = None) -> Frame:
        t = msg.times
        return cls(
            subject_id=msg.subject_id, sync=msg.sync, sample_us=msg.sample_us, receive_us=receive_us,
            times={name: getattr(t, name) for name in _STAGES},
            flags=np.array(msg.flags, dtype=np.uint32),
            q=np.array(msg.q_world_segment_wxyz, dtype=np.float64).reshape(-1, 4),
            p=np.array(msg.position_m, dtype=np.float64).reshape(-1, 3),
            joint_angles_rad=np.array(msg.joint_angles_rad, dtype=np.float64),
            q_raw=np.array(msg.q_earth_sensor_wxyz, dtype=np.float64).reshape(-1, 4),
            skeleton=skeleton)

    @property
    def segment_count(self) -> int:
        return len(self.flags)

    @property
    def joint_angles(self) -> dict[str, float]:
        """Joint angles by name (radians); empty unless Fields.JOINT_ANGLES was subscribed."""
        names = self.skeleton.joint_angle_names if self.skeleton else []
        return dict(zip(names, self.joint_angles_rad.tolist()))

    @property
    def latency_us(self) -> int | None:
        """sink send -> this client's receive (needs agreeing clocks), None if unknown."""
        sent = self.times["sink_send_us"]
        return self.receive_us - sent if sent else None

    def all_flagged(self, bit: SegmentFlags) -> bool:
        return bool(len(self.flags)) and bool(np.all(self.flags & int(bit)))

    def to_dict(self) -> dict:
        """Plain Python (JSON-ready), in the shape of `mocap-client cat --json`."""
        out: dict = {"subject": self.subject_id, "sync": self.sync, "sample_us": self.sample_us,
                     "receive_us": self.receive_us, "times": dict(self.times)}
        segments = []
        for i in range(self.segment_count):
            s: dict = {"flags": int(self.flags[i])}
            if self.skeleton and i < len(self.skeleton.segment_names):
                s["name"] = self.skeleton.segment_names[i]
            if len(self.q):
                s["q"] = self.q[i].tolist()
            if len(self.p):
                s["p"] = self.p[i].tolist()
            if len(self.q_raw):
                s["q_raw"] = self.q_raw[i].tolist()
            segments.append(s)
        out["segments"] = segments
        if len(self.joint_angles_rad):
            out["joint_angles_rad"] = self.joint_angles
        return out


@dataclass(frozen=True)
class StageLatency:
    count: int
    p50_us: float
    p90_us: float
    p99_us: float
    max_us: float


@dataclass(frozen=True)
class Stats:
    server_time_us: int
    counters: dict[str, int]  # "<component>.<name>" -> value (only goes up)
    latencies: dict[str, StageLatency]  # stage -> percentiles

    @classmethod
    def from_proto(cls, msg) -> Stats:
        return cls(msg.server_time_us, {c.name: c.value for c in msg.counters},
                   {s.stage: StageLatency(s.count, s.p50_us, s.p90_us, s.p99_us, s.max_us) for s in msg.latencies})


@dataclass(frozen=True)
class ControlReply:
    ok: bool
    error: str  # the refusal reason; empty when ok
