"""PARAM_VALUE / PARAM_SET's float field: what it means per parameter type and encoding.

ArduPilot sends every parameter as a float (C cast: an INT32 of 4 travels as 4.0); PX4
encodes integer parameters *bytewise* (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE: the
float field's four bytes are the integer's), and ignores a REAL32 PARAM_SET of an INT32
parameter.  One place converts both ways.
"""

from __future__ import annotations

import math
import struct

from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = ["decode_param", "encode_param", "same_float32", "ParamEncodingError", "param_id"]


class ParamEncodingError(ValueError):
    """A value its integer parameter type cannot hold."""


_INT_TYPES = {mavlink.MAV_PARAM_TYPE_UINT8: "<B", mavlink.MAV_PARAM_TYPE_INT8: "<b",
              mavlink.MAV_PARAM_TYPE_UINT16: "<H", mavlink.MAV_PARAM_TYPE_INT16: "<h",
              mavlink.MAV_PARAM_TYPE_UINT32: "<I", mavlink.MAV_PARAM_TYPE_INT32: "<i"}


def decode_param(wire: float, ptype: int, bytewise: bool) -> float:
    """A parameter's value from PARAM_VALUE's float field: an integer type under bytewise encoding is the
    float's bytes read as that integer (little-endian, the low bytes); anything else is the float itself."""
    fmt = _INT_TYPES.get(ptype)
    if not bytewise or fmt is None:
        return wire
    raw = struct.pack("<f", wire)
    return float(struct.unpack(fmt, raw[:struct.calcsize(fmt)])[0])


def encode_param(value: float, ptype: int, bytewise: bool) -> float:
    """PARAM_SET's float field for ``value`` of type ``ptype`` (the inverse of :func:`decode_param`).

    Raises
    ------
    ParamEncodingError
        An integer parameter given a value its type cannot hold (not whole, or out of range).
    """
    fmt = _INT_TYPES.get(ptype)
    if not bytewise or fmt is None:
        return float(value)
    if not math.isfinite(value) or value != int(value):
        raise ParamEncodingError(f"integer parameter given {value!r}")
    try:
        raw = struct.pack(fmt, int(value)).ljust(4, b"\0")
    except struct.error:
        raise ParamEncodingError(f"{value!r} out of range for its integer type") from None
    return struct.unpack("<f", raw)[0]


def same_float32(a: float, b: float) -> bool:
    """Equal once both are rounded to float32 (PARAM_VALUE carries a float32)."""
    pack = struct.Struct("<f")
    try:
        return pack.pack(a) == pack.pack(b)
    except (OverflowError, struct.error):
        return False


def param_id(msg) -> str:
    """A PARAM_VALUE's or PARAM_SET's parameter name as text."""
    pid = msg.param_id
    if isinstance(pid, bytes):
        pid = pid.decode(errors="replace")
    return pid.rstrip("\x00")
