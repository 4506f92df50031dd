"""A hostile man-in-the-middle UDP proxy between ``gcs fly`` and ``sitl`` (the hostile-link suite).

Topology (all on loopback)::

    sitl --udp 127.0.0.1:V  --->  [V: vehicle socket]  MitmProxy  [ground socket]  --->  gcs fly --connect udpin:127.0.0.1:G
                                          ^                              |
                                          +---- [alt socket: a second source address, for injections]

Every datagram is forwarded through a list of seeded :class:`Fault` objects (one
``random.Random(seed)`` for the whole proxy), which may drop, mutate, delay,
duplicate, split, reorder it or inject more datagrams next to it.  Before any
fault touches it, every datagram is decoded by the :class:`Monitor`:

* gcs -> vehicle ("up"): every SET_ATTITUDE_TARGET, SET_ACTUATOR_CONTROL_TARGET,
  COMMAND_LONG and PARAM_SET the ground station sent is checked (all floats
  finite; quaternion of unit norm, thrust in [0, 1], body rates within
  ``MAX_BODY_RATE``, actuator controls in [-1, 1] / [0, 1]): "0 non-finite
  commands on the wire";
* vehicle -> gcs ("down"): the vehicle's own HEARTBEAT (armed, mode),
  LOCAL_POSITION_NED (the altitude and the distance from the takeoff point: ceiling
  and fence), PARAM_VALUE (what a parameter was and what it is now), STATUSTEXT.
  This is the truth a test checks the flight's end against.

Faults count what they did (:class:`FaultStats`): ``injected_bytes`` are bytes put
on the wire that the legitimate peer never sent (garbage, copies, forged frames,
appended bytes), ``mutated_bytes`` the size of the legitimate datagrams they
changed (bit flips, truncations, re-encoded fields).

Nothing here imports ``gcs`` or ``sitl``: only pymavlink and the standard library.
"""

from __future__ import annotations

import collections
import heapq
import math
import os
import random
import selectors
import socket
import threading
import time
from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

__all__ = ["MitmProxy", "Monitor", "Fault", "FaultStats", "Out", "DOWN", "UP", "split_frames", "FAULTS",
           "make_faults", "StreamClobberer", "MAX_BODY_RATE"]

DOWN = "down"  #: vehicle -> ground station
UP = "up"      #: ground station -> vehicle

#: Body-rate limit of a sane command [rad/s] (ArduCopter's ATC_RATE_*_MAX are below 20 rad/s).
MAX_BODY_RATE = 50.0
_HOSTILE_FLOATS = (math.nan, math.inf, -math.inf, 1e38, -1e38)


# ----------------------------------------------------------------------------- framing helpers
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


def _parser() -> mavlink.MAVLink:
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


def _floats_of(msg) -> list[tuple[str, float]]:
    out = []
    for name in msg.get_fieldnames():
        v = getattr(msg, name)
        if isinstance(v, float):
            out.append((name, v))
        elif isinstance(v, (list, tuple)):
            out += [(f"{name}[{i}]", x) for i, x in enumerate(v) if isinstance(x, float)]
    return out


# ----------------------------------------------------------------------------- the monitor
@dataclass
class Violation:
    t_wall: float
    kind: str
    text: str


class Monitor:
    """What really went over the link, decoded before any fault (see the module docstring)."""

    def __init__(self, vehicle_sysid: int = 1, vehicle_compid: int = 1) -> None:
        self.vehicle_sysid = vehicle_sysid
        self.vehicle_compid = vehicle_compid
        self._up = _parser()
        self._down = _parser()
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
        bad = [(n, v) for n, v in _floats_of(m) if not math.isfinite(v)]
        if bad:
            self._violate("non-finite", f"{t} {', '.join(f'{n}={v!r}' for n, v in bad)}")
            return
        if t == "SET_ATTITUDE_TARGET":
            ignore_att = bool(m.type_mask & 128)
            if not ignore_att:
                norm = math.sqrt(sum(x * x for x in m.q))
                if abs(norm - 1.0) > 1e-3:
                    self._violate("limit", f"SET_ATTITUDE_TARGET |q| = {norm:.6f}")
            if not m.type_mask & 64 and not 0.0 <= m.thrust <= 1.0:
                self._violate("limit", f"SET_ATTITUDE_TARGET thrust = {m.thrust!r}")
            for name in ("body_roll_rate", "body_pitch_rate", "body_yaw_rate"):
                if abs(getattr(m, name)) > MAX_BODY_RATE:
                    self._violate("limit", f"SET_ATTITUDE_TARGET {name} = {getattr(m, name)!r}")
        elif t == "SET_ACTUATOR_CONTROL_TARGET":
            c = list(m.controls)
            if any(abs(x) > 1.0 for x in c[:3]) or not 0.0 <= c[3] <= 1.0 or any(abs(x) > 1.0 for x in c[4:]):
                self._violate("limit", f"SET_ACTUATOR_CONTROL_TARGET controls = {c}")

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
                if len(buf) > 13 and buf[0] == 0xFD and buf[2] & 0x01:
                    self.up_signed += 1
                    self.up_link_id = buf[-13]
                if t in ("SET_ATTITUDE_TARGET", "SET_ACTUATOR_CONTROL_TARGET", "COMMAND_LONG", "COMMAND_INT",
                         "PARAM_SET"):
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
                if len(buf) > 13 and buf[0] == 0xFD and buf[2] & 0x01:
                    self.down_signed += 1
                    self.down_link_id = buf[-13]
                if t == "HEARTBEAT":
                    armed = bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                    if armed and not self.ever_armed:
                        self.armed_at_wall = now
                    self.ever_armed |= armed
                    self.armed = armed
                    self.custom_mode = int(m.custom_mode)
                    self.last_heartbeat_wall = now
                elif t == "LOCAL_POSITION_NED":
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
                    self.vehicle_time_ms = max(self.vehicle_time_ms, int(m.time_boot_ms))
                elif t == "ATTITUDE":
                    self.vehicle_time_ms = max(self.vehicle_time_ms, int(m.time_boot_ms))
                elif t == "PARAM_VALUE":
                    pid = m.param_id
                    pid = (pid.decode(errors="replace") if isinstance(pid, bytes) else str(pid)).rstrip("\x00")
                    self.param_first.setdefault(pid, float(m.param_value))
                    self.param_last[pid] = float(m.param_value)
                elif t == "STATUSTEXT":
                    txt = m.text.decode(errors="replace") if isinstance(m.text, bytes) else str(m.text)
                    self.statustext.append(txt.rstrip("\x00"))

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


# ----------------------------------------------------------------------------- faults
@dataclass
class Out:
    """One datagram leaving the proxy: after ``delay`` s, from the alternate socket if ``alt``."""

    data: bytes
    delay: float = 0.0
    alt: bool = False


@dataclass
class FaultStats:
    events: int = 0
    injected_bytes: int = 0
    mutated_bytes: int = 0
    injected_datagrams: int = 0
    dropped_datagrams: int = 0


class Fault:
    """A seeded transformation of the datagrams of one or both directions.

    ``process(proxy, direction, items)`` gets the datagrams produced so far from one
    received datagram (a list of :class:`Out`) and returns the new list.  ``p`` is
    the probability per received datagram that the fault acts.
    """

    name = "fault"

    def __init__(self, p: float = 0.1, directions: Sequence[str] = (DOWN, UP)) -> None:
        self.p = p
        self.directions = tuple(directions)
        self.stats = FaultStats()

    def wants(self, proxy: "MitmProxy", direction: str) -> bool:
        return direction in self.directions and proxy.rng.random() < self.p

    def process(self, proxy: "MitmProxy", direction: str, items: list[Out]) -> list[Out]:
        return items

    def injected(self, data: bytes) -> None:
        self.stats.injected_bytes += len(data)
        self.stats.injected_datagrams += 1

    def __repr__(self) -> str:
        return f"{type(self).__name__}(p={self.p}, {'/'.join(self.directions)})"


def _garbage(rng: random.Random, n: int, magic_rich: bool = False) -> bytes:
    b = bytearray(rng.randbytes(n))
    if magic_rich:
        for i in range(0, n, max(1, rng.randint(3, 40))):
            b[i] = rng.choice((0xFD, 0xFE))
    return bytes(b)


class GarbageDatagrams(Fault):
    """Random datagrams (1..``max_len`` bytes) next to the real one; ``magic_rich``: many 0xFD/0xFE."""

    name = "garbage_datagrams"

    def __init__(self, p=0.2, max_len=1400, count=(1, 3), magic_rich=False, directions=(DOWN, UP)) -> None:
        super().__init__(p, directions)
        self.max_len, self.count, self.magic_rich = max_len, count, magic_rich
        if magic_rich:
            self.name = "magic_garbage"

    def process(self, proxy, direction, items):
        if not self.wants(proxy, direction):
            return items
        rng = proxy.rng
        self.stats.events += 1
        extra = []
        for _ in range(rng.randint(*self.count)):
            g = _garbage(rng, rng.randint(1, self.max_len), self.magic_rich)
            self.injected(g)
            extra.append(Out(g, items[0].delay if items else 0.0))
        return extra + items if rng.random() < 0.5 else items + extra


class LoneMagic(Fault):
    """1-byte datagrams of a frame start (0xFD, sometimes 0xFE) just before the real datagram."""

    name = "lone_magic"

    def process(self, proxy, direction, items):
        if not self.wants(proxy, direction):
            return items
        self.stats.events += 1
        g = bytes((0xFD if proxy.rng.random() < 0.8 else 0xFE,))
        self.injected(g)
        return [Out(g, items[0].delay if items else 0.0)] + items


class InlineGarbage(Fault):
    """Random bytes prepended and/or appended inside the real datagram."""

    name = "inline_garbage"

    def __init__(self, p=0.2, max_len=64, directions=(DOWN, UP)) -> None:
        super().__init__(p, directions)
        self.max_len = max_len

    def process(self, proxy, direction, items):
        if not items or not self.wants(proxy, direction):
            return items
        rng = proxy.rng
        it = rng.choice(items)
        where = rng.choice(("pre", "post", "both"))
        pre = _garbage(rng, rng.randint(1, self.max_len)) if where in ("pre", "both") else b""
        post = _garbage(rng, rng.randint(1, self.max_len)) if where in ("post", "both") else b""
        self.stats.events += 1
        self.stats.injected_bytes += len(pre) + len(post)
        self.stats.mutated_bytes += len(it.data)
        it.data = pre + it.data + post
        return items


class Truncate(Fault):
    """A datagram cut short, or one of its frames cut in the middle with the following frames kept."""

    name = "truncate"

    def process(self, proxy, direction, items):
        if not items or not self.wants(proxy, direction):
            return items
        rng = proxy.rng
        it = rng.choice(items)
        frames = split_frames(it.data)
        self.stats.events += 1
        self.stats.mutated_bytes += len(it.data)
        if frames and len(frames) > 1 and rng.random() < 0.5:
            k = rng.randrange(len(frames))
            f = frames[k]
            frames[k] = f[:rng.randint(1, len(f) - 1)]
            it.data = b"".join(frames)
        elif len(it.data) > 1:
            it.data = it.data[:rng.randint(1, len(it.data) - 1)]
        return items


class BitFlip(Fault):
    """1..``max_bits`` random bits flipped (a bad CRC, mostly)."""

    name = "bit_flip"

    def __init__(self, p=0.1, max_bits=3, directions=(DOWN, UP)) -> None:
        super().__init__(p, directions)
        self.max_bits = max_bits

    def process(self, proxy, direction, items):
        if not items or not self.wants(proxy, direction):
            return items
        rng = proxy.rng
        it = rng.choice(items)
        b = bytearray(it.data)
        for _ in range(rng.randint(1, self.max_bits)):
            i = rng.randrange(len(b))
            b[i] ^= 1 << rng.randrange(8)
        self.stats.events += 1
        self.stats.mutated_bytes += len(b)
        it.data = bytes(b)
        return items


class Duplicate(Fault):
    """The datagram sent again (1..``max_copies`` times), now or a few ms later."""

    name = "duplicate"

    def __init__(self, p=0.1, max_copies=2, max_delay=0.005, directions=(DOWN, UP)) -> None:
        super().__init__(p, directions)
        self.max_copies, self.max_delay = max_copies, max_delay

    def process(self, proxy, direction, items):
        if not items or not self.wants(proxy, direction):
            return items
        rng = proxy.rng
        self.stats.events += 1
        extra = []
        for it in items:
            for _ in range(rng.randint(1, self.max_copies)):
                self.injected(it.data)
                extra.append(Out(it.data, it.delay + rng.uniform(0.0, self.max_delay), it.alt))
        return items + extra


class Reorder(Fault):
    """Frames of a datagram split into one datagram each and shuffled; some held back a few ms."""

    name = "reorder"

    def __init__(self, p=0.2, max_delay=0.008, directions=(DOWN, UP)) -> None:
        super().__init__(p, directions)
        self.max_delay = max_delay

    def process(self, proxy, direction, items):
        if not items or not self.wants(proxy, direction):
            return items
        rng = proxy.rng
        out = []
        for it in items:
            frames = split_frames(it.data)
            if frames and len(frames) > 1:
                rng.shuffle(frames)
                out += [Out(f, it.delay, it.alt) for f in frames]
            else:
                out.append(it)
        for it in out:
            if rng.random() < 0.5:
                it.delay += rng.uniform(0.0, self.max_delay)
        self.stats.events += 1
        self.stats.mutated_bytes += sum(len(i.data) for i in items)
        return out


class Delay(Fault):
    """A datagram held back ``lo``..``hi`` s (later ones overtake it)."""

    name = "delay"

    def __init__(self, p=0.1, lo=0.005, hi=0.08, directions=(DOWN, UP)) -> None:
        super().__init__(p, directions)
        self.lo, self.hi = lo, hi

    def process(self, proxy, direction, items):
        if not self.wants(proxy, direction):
            return items
        d = proxy.rng.uniform(self.lo, self.hi)
        self.stats.events += 1
        for it in items:
            it.delay += d
        return items


class Burst(Fault):
    """Every ``period`` s (wall) the direction is held for ``hold`` s, then everything arrives at once."""

    name = "burst"

    def __init__(self, period=(0.5, 2.0), hold=(0.05, 0.2), directions=(DOWN, UP)) -> None:
        super().__init__(1.0, directions)
        self.period, self.hold = period, hold
        self._windows: dict[str, tuple[float, float]] = {}

    def process(self, proxy, direction, items):
        if direction not in self.directions:
            return items
        now = time.monotonic()
        rng = proxy.rng
        w = self._windows.get(direction)
        if w is None or now >= w[1]:
            start = now + rng.uniform(*self.period)
            w = self._windows[direction] = (start, start + rng.uniform(*self.hold))
        if w[0] <= now < w[1]:
            for it in items:
                it.delay = max(it.delay, w[1] - now)
            self.stats.events += 1
        return items


def _mutate_fields(rng: random.Random, msg, values=_HOSTILE_FLOATS) -> list[str]:
    """Set one or more fields of a decoded message to hostile values; the names changed."""
    t = msg.get_type()
    changed = []
    if t == "HEARTBEAT":
        name = rng.choice(("custom_mode", "type", "autopilot", "system_status", "mavlink_version"))
        setattr(msg, name, 0xFFFFFFFF if name == "custom_mode" else 255)
        return [name]
    floats = [n for n in msg.get_fieldnames() if isinstance(getattr(msg, n), float)]
    arrays = [n for n in msg.get_fieldnames() if isinstance(getattr(msg, n), (list, tuple))
              and getattr(msg, n) and isinstance(getattr(msg, n)[0], float)]
    for _ in range(rng.randint(1, 3)):
        if arrays and rng.random() < 0.3:
            n = rng.choice(arrays)
            a = list(getattr(msg, n))
            a[rng.randrange(len(a))] = rng.choice(values)
            setattr(msg, n, a)
            changed.append(n)
        elif floats:
            n = rng.choice(floats)
            setattr(msg, n, rng.choice(values))
            changed.append(n)
    return changed


class HostileFields(Fault):
    """Valid frames (good CRC, the sender's ids and sequence) with fields set to NaN/inf/±1e38.

    ``types``: which messages are re-encoded (ATTITUDE, LOCAL_POSITION_NED, HEARTBEAT by
    default; for "up" e.g. SET_ATTITUDE_TARGET).  ``mode``: "inject" adds the hostile copy
    next to the original, "replace" sends it instead of the original.  ``alt``: from the
    alternate socket (a different source address/port).  ``huge_time``: also stamp
    ``time_boot_ms`` with 2**32 - 1.  On a signed link the proxy cannot sign: the copy goes
    unsigned or signed with a wrong key (a forgery).
    """

    name = "hostile_fields"

    def __init__(self, p=0.05, types=("ATTITUDE", "LOCAL_POSITION_NED", "HEARTBEAT"), mode="inject", alt=False,
                 values=_HOSTILE_FLOATS, huge_time=False, directions=(DOWN,), name: str | None = None) -> None:
        super().__init__(p, directions)
        self.types, self.mode, self.alt, self.values, self.huge_time = set(types), mode, alt, values, huge_time
        if name:
            self.name = name
        self._parser = _parser()

    def process(self, proxy, direction, items):
        if not items or not self.wants(proxy, direction):
            return items
        rng = proxy.rng
        out, extra = [], []
        acted = False
        for it in items:
            frames = split_frames(it.data)
            out.append(it)
            if not frames:
                continue
            new_frames = []
            for f in frames:
                msgs = decode_frames(self._parser, f)
                if len(msgs) != 1 or msgs[0].get_type() not in self.types or acted:
                    new_frames.append(f)
                    continue
                m = msgs[0]
                _mutate_fields(rng, m, self.values)
                if self.huge_time and hasattr(m, "time_boot_ms"):
                    m.time_boot_ms = 0xFFFFFFFF
                hostile = proxy.repack(m, m.get_srcSystem(), m.get_srcComponent(), m.get_seq(),
                                       signed_like=bool(f[0] == 0xFD and f[2] & 1))
                acted = True
                if self.mode == "replace":
                    self.stats.mutated_bytes += len(f)
                    new_frames.append(hostile)
                else:
                    new_frames.append(f)
                    self.injected(hostile)
                    extra.append(Out(hostile, it.delay + rng.uniform(0.0, 0.002), self.alt))
            it.data = b"".join(new_frames)
        if acted:
            self.stats.events += 1
        return out + extra


class OtherSystem(Fault):
    """Copies of the real frames re-encoded as from another system id (some with hostile fields)."""

    name = "other_system"

    def __init__(self, p=0.2, directions=(DOWN, UP)) -> None:
        super().__init__(p, directions)
        self._parser = _parser()

    def process(self, proxy, direction, items):
        if not items or not self.wants(proxy, direction):
            return items
        rng = proxy.rng
        extra = []
        for it in items:
            for m in decode_frames(self._parser, it.data):
                real = m.get_srcSystem()
                sysid = rng.choice([s for s in (0, 2, 3, 42, 77, 200, 254, 255, 1) if s != real])
                if rng.random() < 0.3:
                    _mutate_fields(rng, m)
                hostile = proxy.repack(m, sysid, m.get_srcComponent(), rng.randrange(256), signed_like=False)
                self.injected(hostile)
                extra.append(Out(hostile, it.delay, rng.random() < 0.3))
        self.stats.events += 1
        return items + extra


class ForgedSigned(Fault):
    """Frames signed with a wrong key, claiming the real sender's stream (link id, system, component),
    with a huge signing timestamp (2**48 - 1 - small) or one just ahead of the real one."""

    name = "forged_signed"

    def __init__(self, p=0.05, huge=True, directions=(DOWN, UP)) -> None:
        super().__init__(p, directions)
        self.huge = huge
        self._parser = _parser()

    def process(self, proxy, direction, items):
        if not items or not self.wants(proxy, direction):
            return items
        rng = proxy.rng
        extra = []
        for it in items:
            for f in split_frames(it.data) or []:
                if not (f[0] == 0xFD and f[2] & 1):
                    continue
                msgs = decode_frames(self._parser, f)
                if len(msgs) != 1:
                    continue
                m = msgs[0]
                link_id = f[-13]
                real_ts = int.from_bytes(f[-12:-6], "little")
                ts = (2 ** 48 - 1 - rng.randrange(1000)) if self.huge else real_ts + rng.randint(1, 1000)
                if rng.random() < 0.5:
                    _mutate_fields(rng, m)
                forged = proxy.forge(m, m.get_srcSystem(), m.get_srcComponent(), m.get_seq(), link_id, ts)
                self.injected(forged)
                extra.append(Out(forged, it.delay))
                break
        if extra:
            self.stats.events += 1
        return extra + items


class Drop(Fault):
    """Datagrams lost."""

    name = "drop"

    def process(self, proxy, direction, items):
        if not items or not self.wants(proxy, direction):
            return items
        self.stats.events += 1
        self.stats.dropped_datagrams += len(items)
        return []


#: name -> factory of a fault list (the suite's and the soak's fault kinds).
FAULTS: dict[str, Callable[[float], list[Fault]]] = {
    "garbage": lambda s: [GarbageDatagrams(p=0.25 * s, max_len=1400)],
    "magic_garbage": lambda s: [GarbageDatagrams(p=0.2 * s, max_len=600, magic_rich=True)],
    "lone_magic": lambda s: [LoneMagic(p=0.05 * s)],
    "inline_garbage": lambda s: [InlineGarbage(p=0.1 * s)],
    "truncate": lambda s: [Truncate(p=0.03 * s)],
    "bit_flip": lambda s: [BitFlip(p=0.03 * s)],
    "duplicate": lambda s: [Duplicate(p=0.1 * s)],
    "reorder": lambda s: [Reorder(p=0.2 * s)],
    "delay": lambda s: [Delay(p=0.05 * s, lo=0.005, hi=0.06)],
    "burst": lambda s: [Burst(period=(0.5, 2.0), hold=(0.03, 0.12))],
    "drop": lambda s: [Drop(p=0.02 * s)],
    "other_system": lambda s: [OtherSystem(p=0.2 * s)],
    "nonfinite_fields": lambda s: [HostileFields(p=0.03 * s, values=(math.nan, math.inf, -math.inf),
                                                 name="nonfinite_fields")],
    "huge_fields": lambda s: [HostileFields(p=0.02 * s, values=(1e38, -1e38), huge_time=True, name="huge_fields")],
    "alt_source": lambda s: [HostileFields(p=0.05 * s, alt=True, values=(math.nan, math.inf, 1e38),
                                           name="alt_source")],
    "nonfinite_up": lambda s: [HostileFields(p=0.02 * s, types=("SET_ATTITUDE_TARGET", "SET_ACTUATOR_CONTROL_TARGET"),
                                             mode="replace", values=(math.nan, math.inf, -math.inf),
                                             directions=(UP,), name="nonfinite_up")],
    "forged_signed": lambda s: [ForgedSigned(p=0.03 * s)],
}


def make_faults(names: Iterable[str], scale: float = 1.0) -> list[Fault]:
    out: list[Fault] = []
    for n in names:
        out += FAULTS[n](scale)
    return out


# ----------------------------------------------------------------------------- the proxy
class MitmProxy:
    """The proxy (a background thread).  See the module docstring.

    Parameters
    ----------
    faults : list of Fault
    seed : int
        Seed of the one ``random.Random`` every fault draws from.
    vehicle_sysid, vehicle_compid : int
    """

    def __init__(self, faults: Sequence[Fault] = (), seed: int = 0, vehicle_sysid: int = 1,
                 vehicle_compid: int = 1) -> None:
        self.faults = list(faults)
        self.rng = random.Random(seed)
        self.monitor = Monitor(vehicle_sysid, vehicle_compid)
        self.vsock = self._udp()          # the sitl sends here (sitl --udp 127.0.0.1:<vehicle_port>)
        self.gsock = self._udp()          # talks to the ground station
        self.asock = self._udp()          # the alternate source address (injections)
        self.vehicle_port = self.vsock.getsockname()[1]
        self.vehicle_addr: tuple[str, int] | None = None   # the sitl's own socket, learned
        self.gcs_addr: tuple[str, int] | None = None
        self.forwarded = {DOWN: 0, UP: 0}
        self.forwarded_bytes = {DOWN: 0, UP: 0}
        self.send_errors = 0
        self.enabled = True               # False: forward untouched (faults off)
        self._heap: list = []
        self._injections: collections.deque = collections.deque()
        self._seq = 0
        self._stop = threading.Event()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._thread: threading.Thread | None = None
        self._encoders: dict = {}
        self.error: BaseException | None = None
        self.error_text = ""
        self.taps: list[Callable[[str, bytes], None]] = []

    @staticmethod
    def _udp() -> socket.socket:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", 0))
        s.setblocking(False)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
        return s

    # ------------------------------------------------------------------ encoding for faults
    def _encoder(self, sysid: int, compid: int) -> mavlink.MAVLink:
        key = (sysid, compid)
        e = self._encoders.get(key)
        if e is None:
            e = self._encoders[key] = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        return e

    def repack(self, msg, sysid: int, compid: int, seq: int, signed_like: bool = False) -> bytes:
        """``msg`` framed as MAVLink 2 from (sysid, compid) with ``seq``.  ``signed_like``: the link is
        signed, which the proxy cannot do: half unsigned, half signed with a wrong key (forged)."""
        if signed_like and self.rng.random() < 0.5:
            return self.forge(msg, sysid, compid, seq, 0, self.rng.randrange(1, 2 ** 40))
        e = self._encoder(sysid, compid)
        e.seq = seq & 0xFF
        e.signing.sign_outgoing = False
        return bytes(msg.pack(e, force_mavlink1=False))

    def forge(self, msg, sysid: int, compid: int, seq: int, link_id: int, timestamp: int) -> bytes:
        """``msg`` signed with a random (wrong) key, claiming stream (link_id, sysid, compid) at ``timestamp``."""
        e = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        e.seq = seq & 0xFF
        e.signing.secret_key = self.rng.randbytes(32)
        e.signing.sign_outgoing = True
        e.signing.link_id = link_id & 0xFF
        e.signing.timestamp = timestamp
        return bytes(msg.pack(e, force_mavlink1=False))

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> "MitmProxy":
        self._thread = threading.Thread(target=self._main, name="mitm-proxy", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        try:
            self._wake_w.send(b"x")
        except OSError:
            pass
        if self._thread is not None:
            self._thread.join(5.0)
        for s in (self.vsock, self.gsock, self.asock, self._wake_r, self._wake_w):
            s.close()

    def __enter__(self) -> "MitmProxy":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------------ counts
    def stats(self) -> dict:
        per: dict[str, dict] = {}
        for f in self.faults:
            d = per.setdefault(f.name, {"events": 0, "injected_bytes": 0, "mutated_bytes": 0,
                                        "injected_datagrams": 0, "dropped_datagrams": 0})
            for k in d:
                d[k] += getattr(f.stats, k)
        return {"faults": per,
                "injected_bytes": sum(v["injected_bytes"] for v in per.values()),
                "mutated_bytes": sum(v["mutated_bytes"] for v in per.values()),
                "forwarded": dict(self.forwarded), "forwarded_bytes": dict(self.forwarded_bytes),
                "send_errors": self.send_errors}

    # ------------------------------------------------------------------ the loop
    def inject(self, direction: str, data: bytes, alt: bool = False) -> None:
        """Send ``data`` now towards the gcs (DOWN) or the vehicle (UP), from outside the fault chain
        (thread-safe: goes through the scheduler)."""
        self._injections.append((direction, Out(data, 0.0, alt)))
        try:
            self._wake_w.send(b"i")
        except OSError:
            pass

    def _push(self, now: float, direction: str, out: Out) -> None:
        self._seq += 1
        heapq.heappush(self._heap, (now + out.delay, self._seq, direction, out.data, out.alt))

    def _send(self, direction: str, data: bytes, alt: bool) -> None:
        if direction == DOWN:
            addr, sock = self.gcs_addr, (self.asock if alt else self.gsock)
        else:
            addr, sock = self.vehicle_addr, (self.asock if alt else self.vsock)
        if addr is None:
            return
        try:
            sock.sendto(data, addr)
        except OSError:
            self.send_errors += 1

    def _received(self, direction: str, data: bytes) -> None:
        self.forwarded[direction] += 1
        self.forwarded_bytes[direction] += len(data)
        if direction == DOWN:
            self.monitor.down(data)
        else:
            self.monitor.up(data)
        for tap in self.taps:
            tap(direction, data)
        items = [Out(data)]
        if self.enabled:
            for f in self.faults:
                try:
                    items = f.process(self, direction, items)
                except Exception as exc:  # noqa: BLE001 - a harness bug: reported, the datagram goes on
                    if self.error is None:
                        import traceback

                        self.error = exc
                        self.error_text = f"in fault {f.name}: " + traceback.format_exc()
        now = time.monotonic()
        for it in items:
            self._push(now, direction, it)

    def _main(self) -> None:
        try:
            self._loop()
        except BaseException as exc:  # noqa: BLE001 - reported by the harness
            self.error = exc
            raise

    def _loop(self) -> None:
        sel = selectors.DefaultSelector()
        sel.register(self.vsock, selectors.EVENT_READ, DOWN)
        sel.register(self.gsock, selectors.EVENT_READ, UP)
        sel.register(self.asock, selectors.EVENT_READ, None)
        sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        while not self._stop.is_set():
            now = time.monotonic()
            while self._injections:
                self._push(now, *self._injections.popleft())
            while self._heap and self._heap[0][0] <= now:
                _, _, direction, data, alt = heapq.heappop(self._heap)
                self._send(direction, data, alt)
            timeout = max(0.0, self._heap[0][0] - now) if self._heap else 0.2
            for key, _ in sel.select(min(timeout, 0.2)):
                what = key.data
                sock = key.fileobj
                for _ in range(256):
                    try:
                        data, addr = sock.recvfrom(65535)  # type: ignore[union-attr]
                    except (BlockingIOError, InterruptedError):
                        break
                    except OSError:  # ICMP port unreachable from an earlier send (peer gone)
                        continue
                    if what == "wake" or what is None:
                        continue
                    if what == DOWN:
                        if self.vehicle_addr is None:
                            self.vehicle_addr = addr
                        elif addr != self.vehicle_addr:
                            continue  # not the vehicle: not ours to forward
                    else:
                        if self.gcs_addr is not None and addr != self.gcs_addr:
                            continue
                    self._received(what, data)


# ----------------------------------------------------------------------------- a second client
class StreamClobberer:
    """A MAVProxy-like second ground station talking to the vehicle directly (its own address, or
    ``target``: an endpoint of its own; or ``shared_link``: on the ground station's own link, as when
    both sit behind one MAVProxy):
    HEARTBEAT once a second and REQUEST_DATA_STREAM(target 1/1, MAV_DATA_STREAM_ALL, ``rate_hz``,
    start) at connect and every ``period_s`` of vehicle time (or of wall time, whichever comes
    first), as MAVProxy's ``set streamrate`` keeps doing.  Everything it receives is read and dropped.
    """

    def __init__(self, proxy: MitmProxy, rate_hz: int = 4, period_s: float = 2.0, sysid: int = 255,
                 compid: int = 0, target: tuple[str, int] | None = None, shared_link: bool = False) -> None:
        self.proxy = proxy
        self.target = target  # None: the vehicle's socket as the proxy learned it
        self.shared_link = shared_link  # True: injected into the ground station's own link (same address)
        self.rate_hz, self.period_s = rate_hz, period_s
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.requests = 0
        self.received_bytes = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _send(self, msg) -> None:
        data = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) & 0xFF
        if self.shared_link:
            self.proxy.inject(UP, bytes(data))
            return
        addr = self.target or self.proxy.vehicle_addr
        if addr is None:
            return
        try:
            self.sock.sendto(data, addr)
        except OSError:
            pass

    def request(self) -> None:
        self._send(self.mav.request_data_stream_encode(1, 1, mavlink.MAV_DATA_STREAM_ALL, self.rate_hz, 1))
        self.requests += 1

    def _run(self) -> None:
        last_wall = last_hb = -1e9
        last_vt = None
        while not self._stop.wait(0.01):
            try:
                while True:
                    self.received_bytes += len(self.sock.recv(65535))
            except OSError:
                pass
            if self.proxy.vehicle_addr is None:  # the SITL is not up yet
                continue
            now = time.monotonic()
            vt = self.proxy.monitor.vehicle_time_ms
            if now - last_hb >= 1.0:
                last_hb = now
                self._send(self.mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0))
            if last_vt is None or vt - last_vt >= self.period_s * 1000 or now - last_wall >= self.period_s:
                last_vt, last_wall = vt, now
                self.request()

    def start(self) -> "StreamClobberer":
        self._thread = threading.Thread(target=self._run, name="stream-clobberer", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
        self.sock.close()


