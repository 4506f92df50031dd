"""The typed records of the log pipeline: what producers hand over, what the writer turns into messages.

A producer (:class:`gcs.log.recorder.FlightRecorder` for ``gcs fly``,
:class:`gcs.log.simrecorder.SimRecorder` for ``gcs sim``) builds these plain, immutable
records — numbers and bytes, nothing formatted — and hands lists of them to a sink
(:mod:`gcs.log.sink`); :class:`gcs.log.encoder.RecordEncoder` turns each into its MCAP
messages (topics in :mod:`gcs.log.topics`), dispatching on the record's type.

Times are integer nanoseconds on the file's time line, except within a flight whose
:class:`FlightStart` has ``t_ns=None``: the writer places such a flight after what the file
already holds (:data:`GAP_NS` later) and the times of its records count from its start
(``gcs sim`` lays its flights one after the other so).

Records are :class:`typing.NamedTuple` classes (slots, cheap to build; the framing of
:mod:`gcs.log.framing` sends them as plain tuples, cheap to pickle).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

__all__ = [
    "FLOWN",
    "GAP_NS",
    "RECORDS",
    "SIMULATED",
    "TIMING_FIELDS",
    "Attachment",
    "CloseLog",
    "Event",
    "FlightEnd",
    "FlightStart",
    "Garbage",
    "LinkFrame",
    "LogDone",
    "LogFailed",
    "LoopTiming",
    "Metadata",
    "Metrics",
    "OpenLog",
    "Tick",
    "TickBlock",
]

#: Time between two placed flights on a file's time line [ns].
GAP_NS = 1_000_000_000
#: ``FlightStart.source`` of a flown and of a simulated flight (the ``source`` field of ``/flight``).
FLOWN, SIMULATED = "flight", "sim"


class LoopTiming(NamedTuple):
    """One control tick's timing [s] (``/loop/timing``, after ``k``)."""

    jitter_s: float          #: tick start minus its deadline
    tick_s: float            #: compute time of the tick
    deadline_missed: bool
    decode_s: float          #: reading and decoding what the vehicle sent
    estimate_s: float        #: the estimator
    control_s: float         #: the controller and the safety envelope
    send_s: float            #: the command to the vehicle
    log_prev_s: float        #: logging the previous tick


#: Fields of ``/loop/timing`` after ``k``, in order.
TIMING_FIELDS = LoopTiming._fields


class FlightStart(NamedTuple):
    """The start of a flight (``/flight``): every later record up to the next one belongs to it.

    ``t_ns`` None: the writer places the flight after what the file holds and its records'
    times count from its start.  ``flight`` None: the next index of the file.  ``cost``: the
    controller's cost J as plain data (:meth:`gcs.control.cost.CostSpec.to_dict`; None for PD),
    from which every tick's ``/control/cost`` is computed.  ``extra``: more ``/flight`` fields.
    """

    t_ns: int | None
    controller: str
    experiment: str = ""
    ts_s: float | None = None
    steps: int | None = None
    source: str = FLOWN
    flight: int | None = None
    run: int = 0
    seed: int | None = None
    cost: Mapping[str, Any] | None = None
    extra: Mapping[str, Any] | None = None


class Tick(NamedTuple):
    """One control tick: the estimate, reference, command before and after the safety envelope
    (``command_limited`` None: no envelope), the horizon step and mode, the loop timing, in
    simulation the true state, and with a disturbance observer its estimate (``/control/*``,
    ``/loop/timing``, ``/sim/truth``; ``disturbance`` in :data:`gcs.log.topics.DISTURBANCE_FIELDS` order)."""

    t_ns: int
    k: int
    state: Sequence[float]
    reference: Sequence[float]
    command: Sequence[float]
    command_limited: Sequence[float] | None
    steps_to_go: int
    mode: str
    timing: LoopTiming | None = None
    truth: Sequence[float] | None = None
    disturbance: Sequence[float] | None = None


class TickBlock(NamedTuple):
    """Ticks ``k0 .. k0 + n - 1`` of a simulated flight, at ``k * ts`` from its start: the true
    state, estimate, reference (n, 12), command (n, 4), steps to go (n,) and modes (n)."""

    k0: int
    truth: Any
    estimate: Any
    reference: Any
    command: Any
    steps_to_go: Any
    modes: Sequence[str]


class LinkFrame(NamedTuple):
    """A link frame as on the wire, ``protocol`` "mavlink" or "rig", ``direction`` "in" or "out";
    ``decoded`` False: a frame the link dropped (another system), logged raw only."""

    t_ns: int
    protocol: str
    direction: str
    data: bytes
    decoded: bool = True


class Garbage(NamedTuple):
    """Received bytes that held no valid frame (MAVLink BAD_DATA, rig bytes between frames)."""

    t_ns: int
    protocol: str
    direction: str
    data: bytes


class Event(NamedTuple):
    """An ``/events`` message: kind, text and more fields (link, mode, arming, phase, failsafe, warning...)."""

    t_ns: int
    kind: str
    text: str
    fields: Mapping[str, Any] | None = None


class FlightEnd(NamedTuple):
    """The state (estimate and/or truth) and reference after the last command: they close the flight record."""

    t_ns: int
    reference: Sequence[float]
    state: Sequence[float] | None = None
    truth: Sequence[float] | None = None


class Metrics(NamedTuple):
    """The metrics computed in the run (``/flight/metrics`` of a flown flight, ``/sim/metrics`` of a simulated one)."""

    t_ns: int
    values: Mapping[str, float]


class Metadata(NamedTuple):
    """An MCAP metadata record (values as str)."""

    name: str
    data: Mapping[str, str]


class Attachment(NamedTuple):
    """An MCAP attachment (config, gains); ``log_time_ns`` None: the last message's time."""

    name: str
    media_type: str
    data: bytes
    log_time_ns: int | None = None


# --------------------------------------------------------------------------- the writer process's protocol

class OpenLog(NamedTuple):
    """First record to the writer process: the file, the options of :class:`gcs.log.writer.FlightLog`,
    the niceness to take (a writer beside a real-time loop steps back)."""

    path: str
    options: Mapping[str, Any]
    nice: int = 0


class CloseLog(NamedTuple):
    """Last record to the writer process: finish the file (the end of its input does the same)."""


class LogDone(NamedTuple):
    """The writer process's answer: the file is finished; ``{"messages", "bytes", "flights", "undecodable"}``."""

    stats: Mapping[str, int]


class LogFailed(NamedTuple):
    """The writer process's answer: what failed (the file was finished as far as it could be)."""

    error: str


#: Every record type, in the order of their codes on the wire (:mod:`gcs.log.framing`).
RECORDS: tuple[type, ...] = (FlightStart, Tick, TickBlock, LinkFrame, Garbage, Event, FlightEnd, Metrics, Metadata,
                             Attachment, OpenLog, CloseLog, LogDone, LogFailed)
