"""The wire checker: every datagram decoded before any fault touches it.

* gcs -> vehicle ("up"): every SET_ATTITUDE_TARGET, SET_ACTUATOR_CONTROL_TARGET, COMMAND_LONG,
  COMMAND_INT and PARAM_SET the ground station sent is checked (all floats finite; quaternion of
  unit norm, thrust in [0, 1], body rates within ``MAX_BODY_RATE``, actuator controls in [-1, 1] /
  [0, 1]): "0 non-finite commands on the wire";
* vehicle -> gcs ("down"): the vehicle's own HEARTBEAT (armed, mode), LOCAL_POSITION_NED (the
  altitude and the distance from the takeoff point: ceiling and fence), PARAM_VALUE (what a
  parameter was and what it is now), STATUSTEXT.  This is the truth a test checks the flight's
  end against.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

from .wire import MAX_BODY_RATE, decode_frames, floats_of, is_signed, mavlink, new_parser

__all__ = ["Violation", "Monitor"]

#: The ground station's messages checked on the wire.
CHECKED_COMMANDS = ("SET_ATTITUDE_TARGET", "SET_ACTUATOR_CONTROL_TARGET", "COMMAND_LONG", "COMMAND_INT",
                    "PARAM_SET")
_BODY_RATES = ("body_roll_rate", "body_pitch_rate", "body_yaw_rate")


@dataclass
class Violation:
    t_wall: float
    kind: str
    text: str


def _text(value) -> str:
    """A char[] field of pymavlink (bytes or str), without its NUL padding."""
    return (value.decode(errors="replace") if isinstance(value, bytes) else str(value)).rstrip("\x00")


class Monitor:
    """What really went over the link, decoded before any fault (see the module docstring)."""

    def __init__(self, vehicle_sysid: int = 1, vehicle_compid: int = 1) -> None:
        self.vehicle_sysid = vehicle_sysid
        self.vehicle_compid = vehicle_compid
        self._up = new_parser()
        self._down = new_parser()
        self.lock = threading.Lock()
        self.up_counts: dict[str, int] = {}
        self.down_counts: dict[str, int] = {}
        self.commands_checked = 0
        self.violations: list[Violation] = []
        self.armed: bool | None = None
        self.ever_armed = False
        self.custom_mode: int | None = None
        self.last_heartbeat_wall: float | None = None
        self.last_down_wall: float | None = None
        self.vehicle_time_ms = 0
        self.origin: tuple[float, float, float] | None = None
        self.position: tuple[float, float, float] | None = None
        self.max_altitude_m = 0.0      # above the first position
        self.max_horizontal_m = 0.0    # from the first position
        self.armed_at_wall: float | None = None
        self.param_first: dict[str, float] = {}
        self.param_last: dict[str, float] = {}
        self.statustext: list[str] = []
        self.gcs_ids: tuple[int, int] | None = None
        self.up_link_id: int | None = None
        self.down_link_id: int | None = None
        self.up_signed = 0
        self.down_signed = 0
        self.up_frames_raw: list[bytes] = []   # kept when keep_up_raw (signing tests capture frames)
        self.keep_up_raw = False

    # ------------------------------------------------------------------ up: the ground station's commands
    def _violate(self, kind: str, text: str) -> None:
        if len(self.violations) < 200:
            self.violations.append(Violation(time.monotonic(), kind, text))

    def check_command(self, m) -> None:
        t = m.get_type()
        self.commands_checked += 1
        bad = [(n, v) for n, v in floats_of(m) if not math.isfinite(v)]
        if bad:
            self._violate("non-finite", f"{t} {', '.join(f'{n}={v!r}' for n, v in bad)}")
            return
        if t == "SET_ATTITUDE_TARGET":
            self._check_attitude_target(m)
        elif t == "SET_ACTUATOR_CONTROL_TARGET":
            c = list(m.controls)
            if any(abs(x) > 1.0 for x in c[:3]) or not 0.0 <= c[3] <= 1.0 or any(abs(x) > 1.0 for x in c[4:]):
                self._violate("limit", f"SET_ACTUATOR_CONTROL_TARGET controls = {c}")

    def _check_attitude_target(self, m) -> None:
        if not m.type_mask & 128:  # the attitude is not ignored
            norm = math.sqrt(sum(x * x for x in m.q))
            if abs(norm - 1.0) > 1e-3:
                self._violate("limit", f"SET_ATTITUDE_TARGET |q| = {norm:.6f}")
        if not m.type_mask & 64 and not 0.0 <= m.thrust <= 1.0:
            self._violate("limit", f"SET_ATTITUDE_TARGET thrust = {m.thrust!r}")
        for name in _BODY_RATES:
            if abs(getattr(m, name)) > MAX_BODY_RATE:
                self._violate("limit", f"SET_ATTITUDE_TARGET {name} = {getattr(m, name)!r}")

    def up(self, data: bytes) -> None:
        msgs = decode_frames(self._up, data)
        with self.lock:
            if self.keep_up_raw:
                self.up_frames_raw.append(bytes(data))
            for m in msgs:
                t = m.get_type()
                self.up_counts[t] = self.up_counts.get(t, 0) + 1
                if self.gcs_ids is None:
                    self.gcs_ids = (m.get_srcSystem(), m.get_srcComponent())
                buf = m.get_msgbuf()
                if is_signed(buf):
                    self.up_signed += 1
                    self.up_link_id = buf[-13]
                if t in CHECKED_COMMANDS:
                    self.check_command(m)

    # ------------------------------------------------------------------ down: the vehicle's truth
    def down(self, data: bytes) -> None:
        msgs = decode_frames(self._down, data)
        now = time.monotonic()
        with self.lock:
            self.last_down_wall = now
            for m in msgs:
                if m.get_srcSystem() != self.vehicle_sysid or m.get_srcComponent() != self.vehicle_compid:
                    continue
                t = m.get_type()
                self.down_counts[t] = self.down_counts.get(t, 0) + 1
                buf = m.get_msgbuf()
                if is_signed(buf):
                    self.down_signed += 1
                    self.down_link_id = buf[-13]
                handler = self._DOWN_HANDLERS.get(t)
                if handler is not None:
                    handler(self, m, now)

    def _on_heartbeat(self, m, now: float) -> None:
        armed = bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        if armed and not self.ever_armed:
            self.armed_at_wall = now
        self.ever_armed |= armed
        self.armed = armed
        self.custom_mode = int(m.custom_mode)
        self.last_heartbeat_wall = now

    def _on_position(self, m, now: float) -> None:
        p = (float(m.x), float(m.y), float(m.z))
        if all(math.isfinite(v) for v in p):
            if self.origin is None:
                self.origin = p
            self.position = p
            o = self.origin
            self.max_altitude_m = max(self.max_altitude_m, -(p[2] - o[2]))
            self.max_horizontal_m = max(self.max_horizontal_m, math.hypot(p[0] - o[0], p[1] - o[1]))
        else:
            self._violate("vehicle", f"the vehicle reported a non-finite position {p}")
        self._on_attitude(m, now)

    def _on_attitude(self, m, now: float) -> None:
        self.vehicle_time_ms = max(self.vehicle_time_ms, int(m.time_boot_ms))

    def _on_param(self, m, now: float) -> None:
        pid = _text(m.param_id)
        self.param_first.setdefault(pid, float(m.param_value))
        self.param_last[pid] = float(m.param_value)

    def _on_statustext(self, m, now: float) -> None:
        self.statustext.append(_text(m.text))

    _DOWN_HANDLERS: ClassVar[dict[str, Callable]] = {
        "HEARTBEAT": _on_heartbeat, "LOCAL_POSITION_NED": _on_position, "ATTITUDE": _on_attitude,
        "PARAM_VALUE": _on_param, "STATUSTEXT": _on_statustext}

    # ------------------------------------------------------------------ summary
    def altitude_m(self) -> float | None:
        if self.position is None or self.origin is None:
            return None
        return -(self.position[2] - self.origin[2])

    def snapshot(self) -> dict:
        with self.lock:
            return {"armed": self.armed, "ever_armed": self.ever_armed, "custom_mode": self.custom_mode,
                    "altitude_m": self.altitude_m(), "max_altitude_m": self.max_altitude_m,
                    "max_horizontal_m": self.max_horizontal_m, "vehicle_time_ms": self.vehicle_time_ms,
                    "commands_checked": self.commands_checked,
                    "violations": [f"{v.kind}: {v.text}" for v in self.violations],
                    "param_first": dict(self.param_first), "param_last": dict(self.param_last),
                    "up_counts": dict(self.up_counts), "down_counts": dict(self.down_counts),
                    "up_signed": self.up_signed, "down_signed": self.down_signed,
                    "statustext": list(self.statustext[-20:])}
