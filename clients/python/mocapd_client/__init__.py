"""mocapd_client: a small Python client of mocapd's pose service (docs/client-protocol.md).

    import mocapd_client as mc
    with mc.Client("127.0.0.1", 7001) as c:
        c.subscribe(fields=mc.Fields.ORIENTATIONS | mc.Fields.JOINT_ANGLES)
        for f in c.frames(duration=5):
            print(f.sync, f.q.shape, f.joint_angles["left_knee.flexion"])

Takes (list, download, start, stop, delete) over the web endpoint: `mc.Takes("127.0.0.1:8080")`.

Pure Python; needs python3-protobuf and python3-numpy, and the classes generated from
proto/mocap/v1/mocap.proto (see mocapd_client.proto for where they are found).
"""

from .client import Client, ConnectionClosed, ProtocolError, parse_endpoint, wall_clock_us
from .framing import DelimitedReader, FramingError, decode_varint, encode_varint, frame_message
from .proto import pb
from .takes import TakeError, Takes
from .types import (ControlReply, Fields, Frame, SegmentFlags, ServerInfo, Skeleton, StageLatency, Stats,
                    Subscription)

__all__ = [
    "Client", "ConnectionClosed", "ProtocolError", "parse_endpoint", "wall_clock_us",
    "DelimitedReader", "FramingError", "decode_varint", "encode_varint", "frame_message", "pb",
    "ControlReply", "Fields", "Frame", "SegmentFlags", "ServerInfo", "Skeleton", "StageLatency", "Stats",
    "Subscription", "TakeError", "Takes",
]
