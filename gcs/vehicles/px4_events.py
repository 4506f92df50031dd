"""PX4's EVENT messages (MAVLink 410): the specific reasons PX4 gives, decoded with its own event metadata.

PX4 says why it refuses to arm ("No offboard signal", "Preflight Fail: ...") only as an EVENT
(its STATUSTEXT is a generic "Arming denied"); pymavlink's dialect does not have the message,
so it arrives as ``MAVLink_unknown`` and is unpacked here (``common.xml``'s EVENT)::

    id uint32, event_time_boot_ms uint32, sequence uint16, destination_component uint8,
    destination_system uint8, log_levels uint8, arguments uint8[40]

The ``id`` is ``component << 24 | sub id``; the text and argument types come from the
firmware's event metadata, ``all_events.json.xz`` (PX4 builds install it in
``etc/extras/``; QGroundControl downloads the same file with MAVFTP).  Without the metadata
the event is reported by its id, saying that the reason came as an event.
"""

from __future__ import annotations

import json
import lzma
import os
import re
import struct
from dataclasses import dataclass
from pathlib import Path

from quadrotor.mavlink.framing import unknown_payload

__all__ = ["ENV_VAR", "EVENT_MSG_ID", "Px4Event", "EventMetadata", "parse_event", "find_event_metadata"]

#: MAVLink EVENT.
EVENT_MSG_ID = 410
#: Environment variable naming an ``all_events.json.xz`` (a vehicle's own, for a real PX4).
ENV_VAR = "GCS_PX4_EVENTS"
_HEAD = struct.Struct("<IIHBBB")
_ARG_TYPES = {"uint8_t": "<B", "int8_t": "<b", "uint16_t": "<H", "int16_t": "<h", "uint32_t": "<I",
              "int32_t": "<i", "uint64_t": "<Q", "int64_t": "<q", "float": "<f"}
_LEVELS = ("emergency", "alert", "critical", "error", "warning", "notice", "info", "debug")


@dataclass(frozen=True)
class Px4Event:
    """One EVENT as received."""

    event_id: int
    time_boot_ms: int
    sequence: int
    log_level: int
    arguments: bytes

    @property
    def component(self) -> int:
        return self.event_id >> 24

    @property
    def sub_id(self) -> int:
        return self.event_id & 0xFFFFFF

    @property
    def level(self) -> str:
        return _LEVELS[self.log_level & 0x0F] if (self.log_level & 0x0F) < len(_LEVELS) else "unknown"


def parse_event(msg) -> Px4Event | None:
    """An EVENT from a received message (pymavlink's ``UNKNOWN_410``), or None for anything else."""
    if msg.get_type() != f"UNKNOWN_{EVENT_MSG_ID}":
        return None
    payload = unknown_payload(msg).ljust(_HEAD.size + 40, b"\0")  # MAVLink 2 trims trailing zeros
    eid, t_ms, seq, _dc, _ds, levels = _HEAD.unpack_from(payload)
    return Px4Event(eid, t_ms, seq, levels, payload[_HEAD.size:_HEAD.size + 40])


class EventMetadata:
    """The firmware's event definitions (``all_events.json.xz``): the text of an event."""

    def __init__(self, doc: dict, source: str = "") -> None:
        self.source = source
        self._events: dict[int, dict] = {}
        self._enums: dict[str, dict] = {}
        for comp in doc.get("components", {}).values():
            self._enums.update(comp.get("enums", {}))
        for cid, comp in doc.get("components", {}).items():
            for group in comp.get("event_groups", {}).values():
                for sub, ev in group.get("events", {}).items():
                    self._events[(int(cid) << 24) | int(sub)] = ev

    @classmethod
    def load(cls, path: str | os.PathLike) -> EventMetadata:
        """Read an ``all_events.json(.xz)``.

        Raises
        ------
        OSError, ValueError
            Not readable, or not the metadata's JSON.
        """
        p = Path(path)
        if p.suffix == ".xz":
            with lzma.open(p) as f:
                raw = f.read()
        else:
            raw = p.read_bytes()
        try:
            return cls(json.loads(raw), str(p))
        except (json.JSONDecodeError, AttributeError, TypeError) as exc:
            raise ValueError(f"{p}: not PX4 event metadata ({exc})") from None

    def __len__(self) -> int:
        return len(self._events)

    def describe(self, event: Px4Event) -> str:
        """The event's message with its arguments filled in (markup removed)."""
        ev = self._events.get(event.event_id)
        if ev is None:
            return f"event {event.component}:{event.sub_id} (not in {self.source or 'the metadata'})"
        values: list = []
        offset = 0
        for arg in ev.get("arguments", []):
            kind = arg.get("type", "")
            enum = self._enums.get(kind)
            fmt = _ARG_TYPES.get(enum.get("type", "") if enum is not None else kind, "<B")
            size = struct.calcsize(fmt)
            v = struct.unpack_from(fmt, event.arguments.ljust(offset + size, b"\0"), offset)[0]
            values.append(v if enum is None else _enum_text(enum, v))
            offset += size

        def arg(m: re.Match) -> str:
            i = int(m.group(1)) - 1
            if not 0 <= i < len(values):
                return m.group(0)
            v = values[i]
            return f"{v:.{m.group(2)}f}" if m.group(2) and isinstance(v, float) else f"{v:g}" if isinstance(
                v, float) else str(v)

        text = re.sub(r"\{(\d+)(?::\.?(\d+))?[^}]*\}", arg, ev.get("message", ""))
        return re.sub(r"</?[a-z]+[^>]*>", "", text).strip()


def _enum_text(enum: dict, value: int) -> str:
    """An enum argument in words: its entry's description (a bitfield: those of its set bits)."""
    entries = enum.get("entries", {})

    def text(v: int) -> str:
        e = entries.get(str(v), {})
        return e.get("description") or e.get("name") or str(v)

    if enum.get("is_bitfield"):
        bits = [text(1 << b) for b in range(64) if value >> b & 1]
        return ", ".join(bits) if bits else "none"
    return text(value)


def find_event_metadata(px4_build: str | os.PathLike | None = None) -> Path | None:
    """``all_events.json.xz``: from :data:`ENV_VAR`, else the PX4 build's ``etc/extras`` (None: not found)."""
    env = os.environ.get(ENV_VAR)
    candidates = [Path(env)] if env else []
    if px4_build is not None:
        candidates.append(Path(px4_build) / "etc" / "extras" / "all_events.json.xz")
    return next((c for c in candidates if c.is_file()), None)
