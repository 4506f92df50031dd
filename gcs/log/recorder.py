"""What ``gcs fly`` logs, and how a failing log is kept from stopping a flight.

:class:`FlightRecorder` sits between the flight loop and a sink of :mod:`gcs.log.sink`
(normally :class:`~gcs.log.sink.BackgroundSink`, a writer process).  The loop's calls only
build records (:mod:`gcs.log.records`) — the per-tick ones (:class:`~gcs.log.records.Tick`,
:class:`~gcs.log.records.LinkFrame`, :class:`~gcs.log.records.Garbage`) straight in their wire
form (:mod:`gcs.log.framing`: a plain tuple, what the writer process rebuilds them from, at a
fraction of the cost of a NamedTuple on the control loop's path); :meth:`FlightRecorder.commit`
hands the collected ones to the sink in one go.  Every call is guarded: a log that fails in flight (the
disk filled up, the writer died) becomes one ``warning`` event and the flight goes on without
a log — the vehicle matters more than the file.  Without a log (``--no-log``) every call
returns at once.

Times: the loop passes its own clock's nanoseconds; the recorder adds ``offset_ns`` (in real
time the offset that puts the monotonic clock on the UTC time line, so Foxglove shows
wall-clock times; in lockstep 0: the vehicle's own time since boot, like ``gcs sim``'s time
line), and never lets the file's time line step back.

What is logged (topics in :mod:`gcs.log`): per tick the estimate, reference, error, command
before and after the safety envelope, horizon step and mode, the stage cost terms (LOC,
NLSOC) and the loop timing (:class:`~gcs.log.records.LoopTiming`); every link frame both ways
(decoded and raw); events; after the loop the state and reference that close the flight
record and the in-flight metrics (``/flight/metrics``).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from gcs.errors import LogError
from gcs.log.framing import code_of, to_wire
from gcs.log.records import (
    FLOWN,
    Attachment,
    Event,
    FlightEnd,
    FlightStart,
    Garbage,
    LinkFrame,
    LoopTiming,
    Metadata,
    Metrics,
    Tick,
)

__all__ = ["BYTES_PER_FLIGHT_TICK", "TICKS_PER_COMMIT", "FlightRecorder", "LoopTiming", "utc_offset_ns"]

#: Generous size of one logged flight tick with its link frames, compressed [bytes] (free-space check).
BYTES_PER_FLIGHT_TICK = 1500
#: Ticks collected before they go to the writer in one write (0.1 s at 100 Hz): each write wakes
#: the writer process, which on a small machine takes the CPU from the loop for a while.
TICKS_PER_COMMIT = 10
#: Records collected outside the mission loop (preflight) before they are committed.
MAX_COLLECTED = 256

# The wire codes of the per-tick records: ``(code, *fields)`` in the order of their fields.
_FRAME, _GARBAGE, _TICK = code_of(LinkFrame), code_of(Garbage), code_of(Tick)
_TIMING_SIZE = len(LoopTiming._fields)


def utc_offset_ns(clock_now_ns: int) -> int:
    """The offset that maps a monotonic clock reading taken now onto UTC nanoseconds."""
    return time.time_ns() - int(clock_now_ns)


class FlightRecorder:
    """Guarded logging of one ``gcs fly`` flight.

    Parameters
    ----------
    sink : BackgroundSink, InlineSink or None
        Where the records go (:mod:`gcs.log.sink`); None records nothing.
    offset_ns : int
        Added to every loop-clock time [ns].
    warn : callable (str) or None
        Told once when the log fails (the flight sets it to its event list and console).
    """

    def __init__(self, sink: Any = None, *, offset_ns: int = 0, warn: Callable[[str], None] | None = None) -> None:
        self.sink = sink
        self.offset_ns = int(offset_ns)
        self.warn = warn
        self.failed: str | None = None
        self.stats: dict = {}
        self._items: list = []
        self._ticks = 0
        self._last_t = 0
        self.path = None if sink is None else sink.path

    @property
    def enabled(self) -> bool:
        return self.sink is not None

    def _t(self, t_ns: int) -> int:
        t = int(t_ns) + self.offset_ns
        if t < self._last_t:
            t = self._last_t
        self._last_t = t
        return t

    def _fail(self, exc: BaseException) -> None:
        sink, self.sink = self.sink, None
        self._items = []
        self.failed = str(exc)
        if sink is not None:
            with contextlib.suppress(LogError):
                sink.close()
        if self.warn is not None:
            self.warn(f"flight log failed, flying on without it: {exc}")

    def commit(self) -> None:
        """Hand the collected records to the sink (once a tick, and before anything slow)."""
        if self.sink is None or not self._items:
            return
        items, self._items = self._items, []
        try:
            self.sink.put_wire(items)
        except LogError as exc:
            self._fail(exc)

    def _put(self, record: Any) -> None:
        if self.sink is None:
            return
        self._items.append(to_wire(record))
        self.commit()

    # ------------------------------------------------------------------ header and frames
    def header(self, metadata: Mapping[str, Any], attachments: Sequence[tuple[str, str, bytes]]) -> None:
        """The ``flight`` metadata and the attachments (config, gains)."""
        if self.sink is None:
            return
        self._items.append(to_wire(Metadata("flight", {str(k): str(v) for k, v in metadata.items()})))
        for name, media, data in attachments:
            self._items.append(to_wire(Attachment(name, media, bytes(data))))
        self.commit()

    def frame(self, t_ns: int, protocol: str, direction: str, data: bytes, decoded: bool = True) -> None:
        """A link frame as on the wire (``protocol`` "mavlink" or "rig"); ``decoded=False``: a frame the
        link dropped (another system), logged raw only.  Collected until the next :meth:`commit`."""
        if self.sink is None or not data:
            return
        self._items.append((_FRAME, self._t(t_ns), protocol, direction, bytes(data), decoded))
        if len(self._items) > MAX_COLLECTED:  # outside the mission loop (preflight): do not hoard
            self.commit()

    def garbage(self, t_ns: int, protocol: str, direction: str, data: bytes) -> None:
        """Received bytes that held no valid frame (MAVLink BAD_DATA, rig bytes between frames)."""
        if self.sink is None or not data:
            return
        self._items.append((_GARBAGE, self._t(t_ns), protocol, direction, bytes(data)))

    def mavlink(self, t_ns: int, direction: str, msg: Any, decoded: bool = True) -> None:
        """A pymavlink message received or sent (its bytes; BAD_DATA as garbage): :meth:`frame` of its bytes."""
        if self.sink is None:
            return
        if msg.get_type() == "BAD_DATA":
            self.garbage(t_ns, "mavlink", direction, bytes(getattr(msg, "data", b"") or b""))
            return
        buf = msg.get_msgbuf()
        if buf:  # frame()'s work, inlined: a few frames a tick
            items = self._items
            items.append((_FRAME, self._t(t_ns), "mavlink", direction, bytes(buf), decoded))
            if len(items) > MAX_COLLECTED:
                self.commit()

    # ------------------------------------------------------------------ the flight
    def event(self, t_ns: int, kind: str, text: str, **fields: Any) -> None:
        self._put(Event(self._t(t_ns), kind, text, fields))

    def flight_start(self, t_ns: int, *, controller: str, experiment: str, ts_s: float, steps: int,
                     cost: Mapping[str, Any] | None, **fields: Any) -> None:
        """``/flight``; ``cost`` is the controller's J as :meth:`gcs.control.cost.CostSpec.to_dict` gives it;
        ``fields`` go to ``/flight`` too (``run``, ``seed``, ``flight``, ``source`` as such)."""
        self._put(FlightStart(self._t(t_ns), controller, experiment, ts_s, steps, fields.pop("source", FLOWN),
                              fields.pop("flight", 0), fields.pop("run", 0), fields.pop("seed", None), cost, fields))

    def tick(self, t_ns: int, k: int, state: Sequence[float], ref: Sequence[float], command: Sequence[float],
             sent: Sequence[float], steps_to_go: int, mode: str, timing: LoopTiming | tuple,
             disturbance: Sequence[float] | None = None) -> None:
        """One control tick; committed with its frames every :data:`TICKS_PER_COMMIT` ticks.

        ``timing``: a :class:`~gcs.log.records.LoopTiming` (or, for now, the same 8 numbers as a tuple);
        ``disturbance``: the observer's estimate (:data:`gcs.log.topics.DISTURBANCE_FIELDS`), None without one.
        """
        if self.sink is None:
            return
        if len(timing) != _TIMING_SIZE:  # a bug, but not one to stop a flight for
            self._fail(LogError(f"timing: {_TIMING_SIZE} values ({', '.join(LoopTiming._fields)}) expected, "
                                f"got {len(timing)}"))
            return
        self._items.append((_TICK, self._t(t_ns), k, tuple(state), tuple(ref), tuple(command), tuple(sent),
                            steps_to_go, mode, tuple(timing), None,
                            None if disturbance is None else tuple(disturbance)))
        self._ticks += 1
        if self._ticks >= TICKS_PER_COMMIT:
            self._ticks = 0
            self.commit()

    def flight_end(self, t_ns: int, state: Sequence[float], ref: Sequence[float]) -> None:
        """The state and reference after the last command (they close the flight record)."""
        self._put(FlightEnd(self._t(t_ns), tuple(ref), tuple(state)))

    def flight_metrics(self, t_ns: int, metrics: Mapping[str, float]) -> None:
        """``/flight/metrics``: the metrics computed in flight (what ``gcs log metrics`` must reproduce)."""
        self._put(Metrics(self._t(t_ns), {k: float(v) for k, v in metrics.items()}))

    def close(self) -> None:
        """Finish the file (idempotent; a failure is reported, not raised)."""
        self.commit()
        sink, self.sink = self.sink, None
        if sink is None:
            return
        try:
            self.stats = sink.close() or {}
        except LogError as exc:
            self.failed = str(exc)
            if self.warn is not None:
                self.warn(f"finishing the flight log failed: {exc}")
