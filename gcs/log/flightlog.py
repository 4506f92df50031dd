"""Logging real flights (``gcs fly``): compact records from the loop, formatted off its path.

The flight loop hands :class:`gcs.flight.recorder.FlightRecorder` plain tuples — the
tick's numbers, link frames as the bytes on the wire, events — and the recorder passes
them, unformatted, to a sink:

* :class:`InlineFlightSink`: a :class:`FlightItemWriter` on a
  :class:`~gcs.log.writer.FlightLog` in this process (tests, tools);
* :class:`BackgroundFlightLog`: the same writer in a separate process
  (``python -m gcs.log.worker``), fed through a non-blocking pipe, so that the JSON
  formatting, the decoding of link frames, the compression and the disk never run on
  the control loop's interpreter.  The loop pays for one ``pickle.dumps`` and one
  ``os.write`` a tick.  Should the writer fall behind so far that the pipe and a local
  buffer of :data:`MAX_BACKLOG_BYTES` fill up, records are dropped and counted — the
  loop never waits for the log.  Should this process die (even by SIGKILL), the writer
  sees its pipe close, writes what it has and finishes the file.

Items (tuples, first element the kind)::

    ("start", t_ns, fields, cost)          /flight (+ the cost spec of /control/cost)
    ("tick", t_ns, k, state, reference, command, sent, steps_to_go, mode, timing)
    ("frame", t_ns, protocol, direction, data, decoded)   protocol "mavlink" | "rig"
    ("garbage", t_ns, protocol, direction, data)
    ("event", t_ns, kind, text, fields)
    ("end", t_ns, state, reference)        the state and reference closing the flight record
    ("metrics", t_ns, metrics)             /flight/metrics
    ("metadata", name, mapping) / ("attachment", name, media_type, bytes)

``timing`` is :data:`TIMING_FIELDS` in order.  MAVLink frames are decoded by the writer
with pymavlink (decoded on ``/mavlink/<dir>/<TYPE>``, raw on ``/mavlink/raw``); rig frames
with :class:`quadrotor.rig_protocol.RigDecoder` (``/rig/<dir>/<NAME>``, ``/rig/raw``).
"""

from __future__ import annotations

import base64
import dataclasses
import errno
import fcntl
import math
import os
import pickle
import struct
import subprocess
from typing import Any, Mapping, Sequence

from gcs.errors import LogError
from gcs.log import topics as T
from gcs.log.writer import FlightLog, _dumps, _Template, check_writable

__all__ = ["FlightItemWriter", "InlineFlightSink", "BackgroundFlightLog", "StageCost", "TIMING_FIELDS",
           "MAX_BACKLOG_BYTES"]

#: Fields of ``/loop/timing`` after ``k``, in the order of a tick's ``timing`` tuple.
TIMING_FIELDS = ("jitter_s", "tick_s", "deadline_missed", "decode_s", "estimate_s", "control_s", "send_s",
                 "log_prev_s")
#: Records kept here while the writer process cannot take them, before they are dropped [bytes].
MAX_BACKLOG_BYTES = 8 << 20

_TWO_PI = 2.0 * math.pi
_TIMING = _Template(("k",) + TIMING_FIELDS)


class StageCost:
    """Stage terms ``(1/2 x'Qx, 1/2 u'Ru, sum)`` of a controller's J at one tick, in plain Python.

    The same x and u as :func:`gcs.metrics.flight_metrics` and
    :func:`gcs.log.simlog.stage_costs` use: eq. 5 for LOC (x = [e_z, e_vz], u = thrust
    cos(phi)cos(theta)/m - g), eq. 17 for NLSOC (x = [e_z, e_vz, e_psi, e_psidot],
    u = [thrust - hover thrust (literal: thrust), tau_psi]), e = state - reference.

    Parameters
    ----------
    spec : Mapping
        ``kind`` ("loc" | "nlsoc"), ``Q``, ``R`` (lists of rows), ``gravity_compensated``,
        ``mass_kg``, ``gravity_m_s2`` (see :meth:`spec_of`).
    """

    def __init__(self, spec: Mapping[str, Any]) -> None:
        from gcs.model import MIN_TILT_COS, SUBSYSTEMS

        self.kind = spec["kind"]
        self.idx = SUBSYSTEMS["z" if self.kind == "loc" else "z_psi"]
        self.Q = [[float(v) for v in row] for row in spec["Q"]]
        self.R = [[float(v) for v in row] for row in spec["R"]]
        self.mass = float(spec["mass_kg"])
        self.g = float(spec["gravity_m_s2"])
        self.compensated = bool(spec.get("gravity_compensated", True))
        self.min_cos = MIN_TILT_COS

    @staticmethod
    def spec_of(cost: Any, mass_kg: float, gravity_m_s2: float) -> dict:
        """The picklable spec of a :class:`gcs.metrics.CostSpec`."""
        return {"kind": cost.kind, "Q": [list(map(float, r)) for r in cost.Q],
                "R": [list(map(float, r)) for r in cost.R], "gravity_compensated": bool(cost.gravity_compensated),
                "mass_kg": float(mass_kg), "gravity_m_s2": float(gravity_m_s2)}

    @staticmethod
    def _quad(v: Sequence[float], m: list[list[float]]) -> float:
        n = len(v)
        return 0.5 * sum(v[i] * m[i][j] * v[j] for i in range(n) for j in range(n))

    def terms(self, state: Sequence[float], ref: Sequence[float], command: Sequence[float]) -> tuple[float, float, float]:
        cc = max(math.cos(state[6]) * math.cos(state[7]), self.min_cos)
        x = [state[i] - ref[i] for i in self.idx]
        if self.kind == "loc":
            u = [command[0] * cc / self.mass - self.g]
        else:
            x[2] = (x[2] + math.pi) % _TWO_PI - math.pi
            u = [command[0] - (self.mass * self.g / cc if self.compensated else 0.0), command[3]]
        xs, us = self._quad(x, self.Q), self._quad(u, self.R)
        return xs, us, xs + us


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


class FlightItemWriter:
    """Writes the items of one flight (see the module docstring) into a :class:`FlightLog`."""

    def __init__(self, log: FlightLog) -> None:
        self.log = log
        self.cost: StageCost | None = None
        self._mav = None
        self._rig: dict[str, Any] = {}
        self._rig_templates: dict = {}
        self.undecodable = 0

    # ------------------------------------------------------------------ frames
    def _mavlink_parser(self):
        if self._mav is None:
            os.environ.setdefault("MAVLINK20", "1")
            from pymavlink.dialects.v20 import ardupilotmega as mavlink

            self._mav = mavlink.MAVLink(None)
            self._mav.robust_parsing = True
        return self._mav

    def _rig_decoder(self, direction: str):
        """One decoder per direction: the received stream is replayed through it as it came."""
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
                                                              _Template(names) if numeric else None)
        topic, names, tmpl = cached
        if tmpl is not None:
            try:
                return topic, tmpl.encode(tuple(getattr(msg, n) for n in names))
            except (TypeError, ValueError):
                pass
        return topic, _dumps({n: _plain(getattr(msg, n)) for n in names}).encode()

    def frame(self, t: int, protocol: str, direction: str, data: bytes, decoded: bool) -> None:
        log = self.log
        if protocol == "mavlink":
            msg = None
            if decoded:
                try:
                    msg = self._mavlink_parser().decode(bytearray(data))
                except Exception:  # pymavlink raises its own MAVError and struct/index errors on odd frames
                    self.undecodable += 1
            if msg is not None and msg.get_type() != "BAD_DATA":
                log.mavlink(t, direction, msg)
            else:
                log.mavlink_raw(t, direction, data, "" if decoded else "DROPPED")
            return
        msgs = self._rig_decoder(direction).feed(data) if decoded else []
        name = msgs[0].NAME if len(msgs) == 1 else ""
        items = []
        for m in msgs:
            items.append(self._rig_json(direction, m))
        items.append((T.RIG_RAW, _dumps({"dir": direction, "type": name,
                                         "data_b64": base64.b64encode(data).decode("ascii")}).encode()))
        log._add(items, t, None)

    def garbage(self, t: int, protocol: str, direction: str, data: bytes) -> None:
        topic = T.MAVLINK_RAW if protocol == "mavlink" else T.RIG_RAW
        kind = "BAD_DATA" if protocol == "mavlink" else "GARBAGE"
        self.log._add([(topic, _dumps({"dir": direction, "type": kind,
                                       "data_b64": base64.b64encode(data).decode("ascii")}).encode())], t, None)

    # ------------------------------------------------------------------ the flight
    def apply(self, item: tuple) -> None:
        """Write one item."""
        kind = item[0]
        log = self.log
        if kind == "tick":
            _, t, k, state, ref, command, sent, j, mode, timing = item
            cost = self.cost.terms(state, ref, sent) if self.cost is not None else None
            log.control_tick(t, state=state, reference=ref, command=command, command_limited=sent, k=k,
                             steps_to_go=j, mode=mode, cost=cost)
            log.write_json(T.TIMING, t, _TIMING.encode((k,) + tuple(timing)).replace(
                b'"deadline_missed":0', b'"deadline_missed":false').replace(
                b'"deadline_missed":1', b'"deadline_missed":true'))
        elif kind == "frame":
            self.frame(*item[1:])
        elif kind == "garbage":
            self.garbage(*item[1:])
        elif kind == "event":
            _, t, ev, text, fields = item
            log.event(t, ev, text, **fields)
        elif kind == "start":
            _, t, fields, cost = item
            self.cost = StageCost(cost) if cost is not None else None
            log.flight_start(t, **fields)
        elif kind == "end":
            _, t, state, ref = item
            log.write_values(T.STATE, t, state)
            log.write_values(T.REFERENCE, t, ref)
        elif kind == "metrics":
            _, t, metrics = item
            doc: dict[str, Any] = {"flight": 0}
            doc.update({key: float(v) for key, v in metrics.items()})
            log.write(T.FLIGHT_METRICS, t, doc)
        elif kind == "metadata":
            log.metadata(item[1], item[2])
        elif kind == "attachment":
            log.attachment(item[1], item[2], item[3])
        else:
            raise LogError(f"{log.path}: unknown flight log item {kind!r}")


class InlineFlightSink:
    """Items written at once into a :class:`FlightLog` of this process."""

    def __init__(self, log: FlightLog) -> None:
        self.log = log
        self.path = log.path
        self.writer = FlightItemWriter(log)
        self.dropped = 0

    def put_many(self, items: list) -> None:
        for item in items:
            self.writer.apply(item)

    def close(self) -> dict:
        self.log.close()
        return {"messages": self.log.message_count, "dropped": 0}


# --------------------------------------------------------------------------- the writer process

def _frame(obj: Any) -> bytes:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    return struct.pack("<Q", len(data)) + data


class BackgroundFlightLog:
    """A flight log written by ``python -m gcs.log.worker`` (see the module docstring).

    Parameters
    ----------
    path : path-like
    expected_bytes : int
        For the free-space check, run here before the process starts.
    **log_kwargs
        Passed to :class:`FlightLog` in the writer process.

    Raises
    ------
    LogError
        The path is not writable, the disk is nearly full, or the process cannot start.
    """

    def __init__(self, path: str | os.PathLike, *, expected_bytes: int = 0, **log_kwargs: Any) -> None:
        from gcs.log.simlog import spawn_writer

        self.path = check_writable(path, expected_bytes)
        self._proc = spawn_writer(self.path)
        self._fd = self._proc.stdin.fileno()  # type: ignore[union-attr]
        self._backlog = bytearray()
        self.dropped = 0
        self.closed = False
        self.stats: dict[str, int] = {}
        self._broken = False
        self._write_blocking(_frame(("open", str(self.path), dict(log_kwargs, flight=True))))
        flags = fcntl.fcntl(self._fd, fcntl.F_GETFL)
        fcntl.fcntl(self._fd, fcntl.F_SETFL, flags | os.O_NONBLOCK)

    def _write_blocking(self, data: bytes) -> None:
        try:
            self._proc.stdin.write(data)  # type: ignore[union-attr]
            self._proc.stdin.flush()  # type: ignore[union-attr]
        except (BrokenPipeError, OSError) as exc:
            self._broken = True
            raise LogError(f"{self.path}: the log writer process is not reading: {exc}") from None

    def _pump(self) -> None:
        """Write as much of the backlog as the pipe takes now (never blocks)."""
        while self._backlog:
            try:
                n = os.write(self._fd, self._backlog)
            except BlockingIOError:
                return
            except OSError as exc:
                if exc.errno == errno.EAGAIN:
                    return
                self._broken = True
                raise LogError(f"{self.path}: the log writer process stopped: {exc.strerror or exc}") from None
            del self._backlog[:n]

    def put_many(self, items: list) -> None:
        """Queue items for the writer; drops them (counted) when the writer is far behind."""
        if self.closed or self._broken:
            raise LogError(f"{self.path}: the log is closed" if self.closed else
                           f"{self.path}: the log writer process stopped")
        data = _frame(items)
        if len(self._backlog) + len(data) > MAX_BACKLOG_BYTES:
            self.dropped += len(items)
            self._pump()
            return
        self._backlog += data
        self._pump()

    def close(self, timeout_s: float = 30.0) -> dict:
        """Hand over what is left, wait for the writer to finish the file; ``{"messages", "bytes", "dropped"}``.

        Raises
        ------
        LogError
            When the writer failed.
        """
        if self.closed:
            return self.stats
        self.closed = True
        from gcs.log.simlog import _recv

        stdin = self._proc.stdin
        error = None
        try:
            flags = fcntl.fcntl(self._fd, fcntl.F_GETFL)
            fcntl.fcntl(self._fd, fcntl.F_SETFL, flags & ~os.O_NONBLOCK)
            if self._broken:
                raise BrokenPipeError("broken")
            stdin.write(bytes(self._backlog) + _frame([("close",)]))  # type: ignore[union-attr]
            stdin.flush()  # type: ignore[union-attr]
        except (BrokenPipeError, OSError, ValueError):
            error = "the log writer process stopped early"
        self._backlog.clear()
        try:
            stdin.close()  # type: ignore[union-attr]
        except OSError:
            pass
        try:
            result = _recv(self._proc.stdout)
            self._proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
            result = None
        if result is not None and result[0] == "done":
            self.stats = dict(result[1], dropped=self.dropped)
            if error is None:
                return self.stats
        if result is not None and result[0] == "error":
            error = result[1]
        raise LogError(f"{self.path}: the log writer failed: {error or f'exit code {self._proc.returncode}'}")
