"""The JSON text of the log's messages: the one place each topic's message is formatted.

Fixed-field topics (state, reference, error, command, cost, truth) go through a pre-compiled
``%.17g`` template (:class:`FixedTemplate`) instead of a dict: 17 significant digits read back
as the same double; non-finite values fall back to :func:`dumps`, which writes
``NaN``/``Infinity`` as Python's json reads them.  :class:`TickText` builds the messages of a
control tick for both ``gcs fly`` and ``gcs sim``.
"""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Sequence
from typing import Any

from gcs.log import topics as T

__all__ = [
    "FIXED",
    "FixedTemplate",
    "TickText",
    "dumps",
    "mavlink_items",
    "raw_frame_json",
    "timing_json",
    "tracking_error",
]

_TWO_PI = 2.0 * math.pi


def _json_default(obj: Any) -> Any:
    if isinstance(obj, (bytes, bytearray, memoryview)):
        return base64.b64encode(bytes(obj)).decode("ascii")
    tolist = getattr(obj, "tolist", None)  # numpy scalars and arrays
    if tolist is not None:
        return tolist()
    if isinstance(obj, (set, frozenset, tuple)):
        return list(obj)
    return str(obj)


_encode = json.JSONEncoder(separators=(",", ":"), default=_json_default).encode


def dumps(obj: Any) -> bytes:
    """Compact JSON of ``obj`` as bytes; bytes become base64 strings, numpy values plain numbers."""
    return _encode(obj).encode()


class FixedTemplate:
    """``%.17g`` template of a fixed-field JSON object (17 digits read back as the same double).

    Formats straight to bytes (faster than a str and its encoding)."""

    __slots__ = ("fields", "fmt", "n_count", "size")

    def __init__(self, fields: Sequence[str]) -> None:
        self.fields = tuple(fields)
        self.size = len(self.fields)
        self.fmt = ("{" + ",".join(f'"{f}":%.17g' for f in self.fields) + "}").encode()
        # 'n' occurs in 'nan' and 'inf': a count above the template's own means a non-finite value.
        self.n_count = (self.fmt % ((0.0,) * self.size)).count(b"n")

    def encode(self, values: Any) -> bytes:
        """The message of ``values`` (a tuple is fastest; any sequence of the template's length)."""
        try:
            s = self.fmt % values
        except TypeError:
            return self._slow(values)
        if s.count(b"n") != self.n_count:
            return dumps(dict(zip(self.fields, values, strict=True)))
        return s

    def _slow(self, values: Any) -> bytes:
        vals = tuple(values)
        if len(vals) != self.size:
            raise ValueError(f"expected {self.size} values ({', '.join(self.fields)}), got {len(vals)}")
        try:
            s = self.fmt % vals
        except TypeError:  # None or other non-numbers: let json say what they are
            return dumps(dict(zip(self.fields, vals, strict=True)))
        if s.count(b"n") != self.n_count:
            return dumps(dict(zip(self.fields, vals, strict=True)))
        return s


#: The template of each fixed-field topic.
FIXED = {topic: FixedTemplate(fields) for topic, fields in T.FIXED_FIELDS.items()}
_TIMING = FixedTemplate(("k", *T.TIMING_FIELDS))


def tracking_error(reference: Sequence[float], state: Sequence[float]) -> list[float]:
    """reference - state, yaw wrapped to [-pi, pi) (``/control/error``)."""
    e = [r - s for r, s in zip(reference, state, strict=False)]  # a short state fails where it is formatted
    if len(e) == 12:
        e[8] = (e[8] + math.pi) % _TWO_PI - math.pi
    return e


def timing_json(k: int, timing: Sequence[float]) -> bytes:
    """The ``/loop/timing`` message of tick ``k`` (``timing`` in :data:`gcs.log.topics.TIMING_FIELDS` order)."""
    return _TIMING.encode((k, *timing)).replace(b'"deadline_missed":0', b'"deadline_missed":false').replace(
        b'"deadline_missed":1', b'"deadline_missed":true')


def raw_frame_json(direction: str, msg_type: str, data: bytes) -> bytes:
    """A ``/mavlink/raw`` or ``/rig/raw`` message: direction, type and the bytes in base64."""
    return dumps({"dir": direction, "type": msg_type, "data_b64": base64.b64encode(bytes(data)).decode("ascii")})


def mavlink_items(direction: str, msg: Any, raw: bool = True) -> list[tuple[str, bytes]]:
    """A pymavlink message's decoded fields on ``/mavlink/<direction>/<TYPE>`` and (``raw``) its frame."""
    mtype = msg.get_type()
    fields = msg.to_dict()
    fields.pop("mavpackettype", None)
    items = [(T.mavlink_topic(direction, mtype), dumps(fields))]
    if raw:
        buf = msg.get_msgbuf()
        if buf:
            items.append((T.MAVLINK_RAW, raw_frame_json(direction, mtype, buf)))
    return items


class TickText:
    """The messages of control ticks: ``/control/state``, ``reference``, ``error``, ``command``,
    ``command_limited``, ``horizon``, ``cost``, ``/sim/truth`` and ``/control/disturbance``, in that order.

    Keeps the last reference's text (references hold still most of a flight) and each mode's.
    """

    def __init__(self) -> None:
        self._modes: dict[str, bytes] = {}
        self._last_ref: tuple | None = None
        self._last_ref_text = b""

    def reference(self, reference: Sequence[float]) -> bytes:
        """The ``/control/reference`` message (formatted once while the reference holds still)."""
        if isinstance(reference, tuple) and reference == self._last_ref:
            return self._last_ref_text
        text = FIXED[T.REFERENCE].encode(reference)
        if isinstance(reference, tuple):
            self._last_ref, self._last_ref_text = reference, text
        return text

    def horizon(self, k: int, steps_to_go: int, mode: str) -> bytes:
        """The ``/control/horizon`` message."""
        m = self._modes.get(mode)
        if m is None:
            m = self._modes[mode] = json.dumps(str(mode)).encode()
        return b'{"k":%d,"steps_to_go":%d,"mode":%s}' % (k, steps_to_go, m)

    def items(self, state: Sequence[float], reference_text: bytes, error: Sequence[float] | None,
              command: Sequence[float], command_limited: Sequence[float] | None, k: int | None, steps_to_go: int,
              mode: str, cost: Sequence[float] | None, truth: Sequence[float] | None,
              disturbance: Sequence[float] | None = None) -> list[tuple[str, bytes]]:
        """``(topic, message)`` of one tick; None leaves a topic out (``k`` None: no horizon)."""
        items = [(T.STATE, _STATE(state)), (T.REFERENCE, reference_text)]
        if error is not None:
            items.append((T.ERROR, _ERROR(error)))
        items.append((T.COMMAND, _COMMAND(command)))
        if command_limited is not None:
            items.append((T.COMMAND_LIMITED, _LIMITED(command_limited)))
        if k is not None:
            items.append((T.HORIZON, self.horizon(k, steps_to_go, mode)))
        if cost is not None:
            items.append((T.COST, _COST(cost)))
        if truth is not None:
            items.append((T.TRUTH, _TRUTH(truth)))
        if disturbance is not None:
            items.append((T.DISTURBANCE, _DISTURBANCE(disturbance)))
        return items


_STATE, _ERROR, _COMMAND = FIXED[T.STATE].encode, FIXED[T.ERROR].encode, FIXED[T.COMMAND].encode
_LIMITED, _COST, _TRUTH = FIXED[T.COMMAND_LIMITED].encode, FIXED[T.COST].encode, FIXED[T.TRUTH].encode
_DISTURBANCE = FIXED[T.DISTURBANCE].encode
