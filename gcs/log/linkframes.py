"""Link frames as messages: MAVLink frames decoded with pymavlink, rig frames with the rig protocol's decoder.

What the link saw travels to the writer as the bytes on the wire
(:class:`~gcs.log.records.LinkFrame`, :class:`~gcs.log.records.Garbage`); :class:`LinkDecoder`
decodes them there: a MAVLink frame to ``/mavlink/<dir>/<TYPE>`` and ``/mavlink/raw``, a rig
frame to ``/rig/<dir>/<NAME>`` and ``/rig/raw`` (the received stream is replayed through one
:class:`quadrotor.rig_protocol.RigDecoder` per direction, as it came).
"""

from __future__ import annotations

import base64
import dataclasses
import os
from typing import Any

from gcs.log import topics as T
from gcs.log.jsonfmt import FixedTemplate, dumps, mavlink_items, raw_frame_json
from gcs.log.records import Garbage, LinkFrame

__all__ = ["LinkDecoder"]


def _plain(v: Any) -> Any:
    if isinstance(v, (bytes, bytearray)):
        return base64.b64encode(bytes(v)).decode("ascii")
    if isinstance(v, tuple):
        return [_plain(x) for x in v]
    if isinstance(v, bool):
        return v
    if isinstance(v, int):
        return int(v)  # IntFlag / IntEnum as numbers
    return v


class LinkDecoder:
    """The messages of link frames and garbage; counts the MAVLink frames that did not decode."""

    def __init__(self) -> None:
        self._mav = None
        self._rig: dict[str, Any] = {}
        self._rig_templates: dict = {}
        self.undecodable = 0

    def _mavlink_parser(self):
        if self._mav is None:
            os.environ.setdefault("MAVLINK20", "1")
            from pymavlink.dialects.v20 import ardupilotmega as mavlink

            self._mav = mavlink.MAVLink(None)
            self._mav.robust_parsing = True
        return self._mav

    def _rig_decoder(self, direction: str):
        dec = self._rig.get(direction)
        if dec is None:
            from quadrotor import rig_protocol as rp

            dec = self._rig[direction] = rp.RigDecoder(rp.MESSAGE_TYPES.values())
        return dec

    def _rig_json(self, direction: str, msg: Any) -> tuple[str, bytes]:
        """``(topic, JSON)`` of a rig message; all-number messages through a cached template."""
        cls = type(msg)
        cached = self._rig_templates.get((direction, cls))
        if cached is None:
            names = tuple(f.name for f in dataclasses.fields(msg))
            numeric = all(isinstance(getattr(msg, n), (int, float)) for n in names)
            cached = self._rig_templates[(direction, cls)] = (T.rig_topic(direction, msg.NAME), names,
                                                              FixedTemplate(names) if numeric else None)
        topic, names, tmpl = cached
        if tmpl is not None:
            try:
                return topic, tmpl.encode(tuple(getattr(msg, n) for n in names))
            except (TypeError, ValueError):
                pass
        return topic, dumps({n: _plain(getattr(msg, n)) for n in names})

    def _mavlink_items(self, direction: str, data: bytes, decoded: bool) -> list[tuple[str, bytes]]:
        msg = None
        if decoded:
            try:
                msg = self._mavlink_parser().decode(bytearray(data))
            except Exception:  # noqa: BLE001  pymavlink raises its own MAVError and struct/index errors on odd frames
                self.undecodable += 1
        if msg is not None and msg.get_type() != "BAD_DATA":
            return mavlink_items(direction, msg)
        return [(T.MAVLINK_RAW, raw_frame_json(direction, "" if decoded else "DROPPED", data))]

    def _rig_items(self, direction: str, data: bytes, decoded: bool) -> list[tuple[str, bytes]]:
        msgs = self._rig_decoder(direction).feed(data) if decoded else []
        name = msgs[0].NAME if len(msgs) == 1 else ""
        items = [self._rig_json(direction, m) for m in msgs]
        items.append((T.RIG_RAW, raw_frame_json(direction, name, data)))
        return items

    def frame(self, rec: LinkFrame) -> list[tuple[str, bytes]]:
        """The messages of a frame (a protocol other than "mavlink" is the rig's)."""
        if rec.protocol == "mavlink":
            return self._mavlink_items(rec.direction, rec.data, rec.decoded)
        return self._rig_items(rec.direction, rec.data, rec.decoded)

    @staticmethod
    def garbage(rec: Garbage) -> list[tuple[str, bytes]]:
        """The raw message of bytes that held no frame: MAVLink ``BAD_DATA``, rig ``GARBAGE``."""
        if rec.protocol == "mavlink":
            return [(T.MAVLINK_RAW, raw_frame_json(rec.direction, "BAD_DATA", rec.data))]
        return [(T.RIG_RAW, raw_frame_json(rec.direction, "GARBAGE", rec.data))]
