"""Flights in a log, and their metrics recomputed from what was logged.

A log holds one or more flights: each ``/flight`` message starts one, and it runs
until the next (a log without any is one flight, described by its ``flight``
metadata).  :func:`flight_record` rebuilds the :class:`gcs.metrics.FlightRecord`
of a flight from the logged ticks — the ``/sim/truth`` states when there are any
(simulation: what ``gcs sim`` computes its metrics on), else the estimates on
``/control/state``; ``/control/reference``; the commands on
``/control/command_limited`` when there are any (what was sent), else
``/control/command``; ``/control/horizon`` for the steps to go — and
:func:`logged_metrics` feeds it to :func:`gcs.metrics.flight_metrics` with the
config attached to the log, so the figures equal the ones computed in the run.
:func:`gcs.log.review.stream.stream_metrics` does the same reading the log as a stream,
one flight in memory at a time (what ``gcs log metrics`` uses: a default ``gcs sim`` log is
over a gigabyte).
"""

from __future__ import annotations

import bisect
import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gcs.config import parse_config
from gcs.errors import LogError
from gcs.log import topics as T
from gcs.log.mcap.reader import McapLog
from gcs.metrics import FlightRecord, controller_cost, flight_metrics
from gcs.mission import Mission

__all__ = [
    "METRIC_TOPICS",
    "LoggedFlight",
    "as_int",
    "flight_arrays",
    "flight_record",
    "flight_slice",
    "log_config",
    "logged_metrics",
    "positive_float",
    "record_from_arrays",
    "split_flights",
]

#: Topics :func:`logged_metrics` needs.
METRIC_TOPICS = (T.FLIGHT, T.TRUTH, T.STATE, T.REFERENCE, T.COMMAND, T.COMMAND_LIMITED, T.HORIZON, *T.RUN_METRICS)


@dataclass
class LoggedFlight:
    """One flight of a log: its ``/flight`` announcement and its time span [start_ns, end_ns)."""

    index: int
    controller: str
    experiment: str
    run: int | None
    seed: int | None
    ts_s: float | None
    steps: int | None
    source: str
    start_ns: int
    end_ns: int | None
    info: dict = field(default_factory=dict)

    @property
    def label(self) -> str:
        run = f" run {self.run}" if self.run is not None else ""
        return f"#{self.index} {self.controller}{run}"


def split_flights(log: McapLog) -> list[LoggedFlight]:
    """The flights of a log, in order (``/flight`` must have been read)."""
    announced = log.decoded(T.FLIGHT) if T.FLIGHT in log.messages else []
    md = log.metadata_dict("flight") or {}
    if not announced:
        ts = md.get("ts_s")
        try:
            ts_s = float(ts) if ts else None
        except ValueError:
            ts_s = None
        start = log.start_ns if log.start_ns is not None else 0
        return [LoggedFlight(0, md.get("controller", "?"), md.get("experiment", ""), None, None, ts_s, None,
                             md.get("source", "flight"), start, None, dict(md))]
    out = []
    for i, (t, d) in enumerate(announced):
        if not isinstance(d, dict):
            raise LogError(f"{log.path}: a /flight message is not a JSON object")
        end = announced[i + 1][0] if i + 1 < len(announced) else None
        ts = positive_float(d.get("ts_s"))
        out.append(LoggedFlight(as_int(d.get("flight"), i), str(d.get("controller", "?")),
                                str(d.get("experiment", md.get("experiment", ""))), as_int(d.get("run")),
                                as_int(d.get("seed")), ts, as_int(d.get("steps")), str(d.get("source", "")), t, end, d))
    return out


def as_int(v: Any, default: int | None = None) -> int | None:
    """``v`` if it is an int (not a bool), else ``default``."""
    return v if isinstance(v, int) and not isinstance(v, bool) else default


def positive_float(v: Any) -> float | None:
    """``v`` as a float if it is a positive number (not a bool), else None."""
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0 else None


def flight_slice(messages: list[tuple[int, Any]], flight: LoggedFlight) -> list[tuple[int, Any]]:
    """The messages (sorted by time) within a flight's span."""
    key = _time_of
    lo = bisect.bisect_left(messages, flight.start_ns, key=key)
    hi = len(messages) if flight.end_ns is None else bisect.bisect_left(messages, flight.end_ns, key=key)
    return messages[lo:hi]


def _time_of(message: tuple[int, Any]) -> int:
    return message[0]


def _matrix(log: McapLog, topic: str, flight: LoggedFlight, fields: tuple[str, ...]) -> np.ndarray:
    msgs = flight_slice(log.messages.get(topic, []), flight)
    if not msgs:
        return np.zeros((0, len(fields)))
    loads = json.loads
    try:
        rows = [[d[f] for f in fields] for d in (loads(m[1].decode()) for m in msgs)]
        return np.array(rows, dtype=float)
    except (KeyError, TypeError, ValueError) as exc:
        raise LogError(f"{log.path}: {topic}: a message lacks or mangles a field ({exc})") from None


def flight_arrays(log: McapLog, flight: LoggedFlight, *, estimate: bool = True) -> dict[str, np.ndarray]:
    """The flight's logged series as arrays: ``state`` (truth if logged, else estimate),
    ``estimate`` (empty with ``estimate=False`` when there is truth), ``reference``, ``command``
    (limited if logged), ``steps_to_go``, and times ``t_state``, ``t_estimate``, ``t_reference``,
    ``t_command`` [s from the flight start]; ``truth`` says where ``state`` came from."""
    sf = T.STATE_FIELDS
    truth = _matrix(log, T.TRUTH, flight, sf)
    estimate = _matrix(log, T.STATE, flight, sf) if (estimate or not truth.shape[0]) else np.zeros((0, 12))
    limited = _matrix(log, T.COMMAND_LIMITED, flight, T.COMMAND_FIELDS)
    command = limited if limited.shape[0] else _matrix(log, T.COMMAND, flight, T.COMMAND_FIELDS)
    cmd_topic = T.COMMAND_LIMITED if limited.shape[0] else T.COMMAND
    state_topic = T.TRUTH if truth.shape[0] else T.STATE
    hor = flight_slice(log.messages.get(T.HORIZON, []), flight)
    try:
        j = np.array([json.loads(m[1].decode()).get("steps_to_go", 0) for m in hor], dtype=np.int64)
    except (AttributeError, TypeError, ValueError, OverflowError) as exc:
        raise LogError(f"{log.path}: {T.HORIZON}: a message lacks or mangles steps_to_go ({exc})") from None

    def times(topic: str) -> np.ndarray:
        msgs = flight_slice(log.messages.get(topic, []), flight)
        return (np.array([m[0] for m in msgs], dtype=np.int64) - flight.start_ns) / 1e9

    return {"state": truth if truth.shape[0] else estimate, "estimate": estimate,
            "reference": _matrix(log, T.REFERENCE, flight, sf), "command": command, "steps_to_go": j,
            "t_state": times(state_topic), "t_estimate": times(T.STATE), "t_reference": times(T.REFERENCE),
            "t_command": times(cmd_topic), "truth": np.array(bool(truth.shape[0]))}


def flight_record(log: McapLog, flight: LoggedFlight, ts_s: float) -> tuple[Any, bool]:
    """The :class:`gcs.metrics.FlightRecord` of a logged flight, and whether it is partial.

    K = the commands, with the K + 1 states (truth in simulation, estimates in flight) and
    references: both ``gcs sim`` and ``gcs fly`` log the state and reference after the last
    command.  In a truncated log the last tick's state closes the record (K = ticks - 1).

    Raises
    ------
    LogError
        When the flight has fewer than two ticks.
    """
    a = flight_arrays(log, flight, estimate=False)
    return record_from_arrays(a["state"], a["reference"], a["command"], a["steps_to_go"], ts_s, flight.steps,
                              f"{log.path}: flight {flight.label}")


def record_from_arrays(state: np.ndarray, ref: np.ndarray, command: np.ndarray, steps_to_go: np.ndarray,
                       ts_s: float, planned_steps: int | None, what: str) -> tuple[Any, bool]:
    """A :class:`gcs.metrics.FlightRecord` from logged series (see :func:`flight_record`), and whether it is partial."""

    s, r, u, j = state, ref, command, steps_to_go
    # A complete flight logs the state and reference after its last command (K commands, K + 1
    # states); a truncated one ends with a tick whose state then closes the record.  Ticks past
    # the planned steps (a descent the ground station flew after the mission) are not measured.
    k = min(u.shape[0], s.shape[0] - 1, r.shape[0] - 1)
    if planned_steps is not None and planned_steps > 0:
        k = min(k, int(planned_steps))
    if k < 1:
        raise LogError(f"{what} has no complete control tick to compute metrics on")
    if j.shape[0] < k:
        j = np.concatenate([j, np.zeros(k - j.shape[0], dtype=np.int64)])
    partial = planned_steps is not None and k < int(planned_steps)
    return FlightRecord(ts_s, s[:k + 1], r[:k + 1], u[:k], j[:k]), bool(partial)


def log_config(log: McapLog, override: Any = None) -> Any:
    """The config of a log: ``override`` (a Config) if given, else the attached ``config.json``.

    Raises
    ------
    LogError
        When the log has no config attachment (give one with ``--config``).
    """
    if override is not None:
        return override

    att = log.attachment("config.json")
    if att is None:
        raise LogError(f"{log.path}: no config.json attachment{' (the log is truncated)' if log.truncated else ''}; "
                       "give the experiment config with --config")
    try:
        raw = json.loads(att.data)
    except ValueError:
        raise LogError(f"{log.path}: the config.json attachment is not JSON") from None
    return parse_config(raw, f"{log.path}:config.json")


def logged_metrics(log: McapLog, config: Any = None) -> list[dict]:
    """Per-flight metrics recomputed from the log.

    Returns
    -------
    list of dict
        ``{"flight", "controller", "run", "seed", "experiment", "steps", "partial", "metrics",
        "in_run"}`` per flight; ``in_run`` is the ``/sim/metrics`` message of a simulated flight
        (what ``gcs sim`` computed) or None.
    """

    cfg = log_config(log, config)
    mission = Mission(cfg.mission, zero_velocity=cfg.experiment.zero_velocity_reference)
    in_run = {}
    for topic in T.RUN_METRICS:
        for _, d in log.decoded(topic) if topic in log.messages else []:
            if isinstance(d, dict):
                in_run[d.get("flight")] = {k: v for k, v in d.items() if k not in ("flight", "controller", "run")}
    out = []
    flights = split_flights(log)
    for fl in flights:
        ts = fl.ts_s if fl.ts_s else cfg.experiment.ts_s
        try:
            rec, partial = flight_record(log, fl, ts)
        except LogError:
            if log.truncated and fl is flights[-1] and len(flights) > 1:
                break  # the writer died as this flight began: nothing of it to measure
            raise
        partial = partial or (log.truncated and fl is flights[-1])
        try:
            cost = controller_cost(fl.controller, cfg)
        except (KeyError, ValueError):
            cost = None
        metrics = flight_metrics(rec, cfg, mission, cost)
        out.append({"flight": fl.index, "controller": fl.controller, "run": fl.run, "seed": fl.seed,
                    "experiment": fl.experiment or cfg.experiment.name, "steps": int(rec.command.shape[0]),
                    "partial": partial, "metrics": metrics, "in_run": in_run.get(fl.index)})
    return out
