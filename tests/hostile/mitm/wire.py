"""What the proxy knows of MAVLink: directions, framing, decoding one datagram, the hostile values."""

from __future__ import annotations

import math
import os

os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = ["DOWN", "UP", "MAX_BODY_RATE", "HOSTILE_FLOATS", "mavlink", "split_frames", "new_parser",
           "decode_frames", "floats_of", "is_signed"]

DOWN = "down"  #: vehicle -> ground station
UP = "up"      #: ground station -> vehicle

#: Body-rate limit of a sane command [rad/s] (ArduCopter's ATC_RATE_*_MAX are below 20 rad/s).
MAX_BODY_RATE = 50.0
HOSTILE_FLOATS = (math.nan, math.inf, -math.inf, 1e38, -1e38)


def split_frames(data: bytes) -> list[bytes] | None:
    """The MAVLink frames of a well-formed datagram (None if it is not exactly a run of frames)."""
    out, i, n = [], 0, len(data)
    while i < n:
        magic = data[i]
        if magic == 0xFD and i + 3 <= n:
            size = 12 + data[i + 1] + (13 if data[i + 2] & 0x01 else 0)
        elif magic == 0xFE and i + 2 <= n:
            size = 8 + data[i + 1]
        else:
            return None
        if i + size > n:
            return None
        out.append(data[i:i + size])
        i += size
    return out


def is_signed(frame: bytes) -> bool:
    """A MAVLink 2 frame with the signed flag (its last 13 bytes are the signature block)."""
    return len(frame) > 13 and frame[0] == 0xFD and bool(frame[2] & 0x01)


def new_parser() -> mavlink.MAVLink:
    """A robust MAVLink 2 parser that belongs to no system (decodes only)."""
    p = mavlink.MAVLink(None)
    p.robust_parsing = True
    return p


def decode_frames(parser: mavlink.MAVLink, data: bytes) -> list:
    """Every message in one datagram (the parser starts afresh: datagrams are independent)."""
    parser.buf = bytearray()
    parser.buf_index = 0
    parser.expected_length = mavlink.HEADER_LEN_V1 + 2
    parser.have_prefix_error = False
    try:
        msgs = parser.parse_buffer(data) or []
    except Exception:  # noqa: BLE001 - the monitor must never die on what a peer sent
        return []
    return [m for m in msgs if m.get_type() != "BAD_DATA" and not m.get_type().startswith("UNKNOWN")]


def floats_of(msg) -> list[tuple[str, float]]:
    """Every float field of ``msg`` (array elements as ``name[i]``)."""
    out = []
    for name in msg.get_fieldnames():
        v = getattr(msg, name)
        if isinstance(v, float):
            out.append((name, v))
        elif isinstance(v, (list, tuple)):
            out += [(f"{name}[{i}]", x) for i, x in enumerate(v) if isinstance(x, float)]
    return out
