"""``FlightLog``: the MCAP file of a ``gcs fly`` / ``gcs sim`` run, written message by message.

A :class:`~gcs.log.mcap.writer.McapWriter` whose channels carry JSON messages with the
``jsonschema`` schemas of :mod:`gcs.log.topics` (Foxglove Studio reads them), each topic
registered once, lazily, plus one method per kind of message (formatted by
:mod:`gcs.log.jsonfmt`).  The log pipeline (:mod:`gcs.log.encoder`) writes its records
into one; tests and tools may write one directly.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

from gcs import __version__
from gcs.log import topics as T
from gcs.log.jsonfmt import FIXED, TickText, dumps, mavlink_items, raw_frame_json, tracking_error
from gcs.log.mcap.writer import MIN_FREE_BYTES, McapWriter, best_compression, check_writable

__all__ = ["MIN_FREE_BYTES", "PROFILE", "FlightLog", "best_compression", "check_writable"]

#: MCAP header profile of these logs.
PROFILE = "gcs"


class FlightLog(McapWriter):
    """An MCAP flight log being written.  Use as a context manager (the file is always finished).

    Parameters
    ----------
    path : path-like
        File to write (its directory is created).
    **options
        Of :class:`~gcs.log.mcap.writer.McapWriter`: ``compression``, ``chunk_size_bytes``,
        ``flush_interval_s``, ``fsync``, ``background_flush``, ``check``, ``expected_bytes``.

    Examples
    --------
    A flight loop::

        with FlightLog("logs/x.mcap") as log:
            log.metadata("flight", {...}); log.attachment("config.json", "application/json", text)
            log.flight_start(t0_ns, controller="loc", experiment="outdoor-altitude", ts_s=0.01)
            for k ...:
                log.control_tick(t_ns, k=k, state=est, reference=ref, command=cmd,
                                 command_limited=sent, steps_to_go=j, mode="horizon")
                log.event(t_ns, "mode", "GUIDED_NOGPS")
    """

    def __init__(self, path: str | os.PathLike, **options: Any) -> None:
        super().__init__(path, schema_of=T.schema_json, profile=PROFILE, library=f"gcs/{__version__} mcap-python",
                         **options)
        self.flight_count = 0
        self._ticks = TickText()

    def __enter__(self) -> FlightLog:
        return self

    def write(self, topic: str, log_time_ns: int, obj: Mapping[str, Any], *,
              publish_time_ns: int | None = None) -> None:
        """Write one message: ``obj`` (a JSON-able mapping) on ``topic`` at ``log_time_ns`` [ns].

        bytes become base64 strings, numpy values plain numbers.
        """
        self.add(((topic, dumps(obj)),), log_time_ns, publish_time_ns)

    def write_json(self, topic: str, log_time_ns: int, text: str | bytes, *,
                   publish_time_ns: int | None = None) -> None:
        """Write an already serialised JSON object."""
        self.add(((topic, text.encode() if isinstance(text, str) else bytes(text)),), log_time_ns, publish_time_ns)

    def write_values(self, topic: str, log_time_ns: int, values: Sequence[float], *,
                     publish_time_ns: int | None = None) -> None:
        """Fast path for the fixed-field topics (:data:`gcs.log.topics.FIXED_FIELDS`): the values in field order.

        ``values`` may be a :class:`quadrotor.state.State` / ``Command`` (any tuple), a list or an array.
        """
        tmpl = FIXED.get(topic)
        if tmpl is None:
            raise ValueError(f"{topic} has no fixed fields; use write()")
        self.add(((topic, tmpl.encode(values)),), log_time_ns, publish_time_ns)

    def control_tick(self, log_time_ns: int, *, state: Sequence[float], reference: Sequence[float],
                     command: Sequence[float], command_limited: Sequence[float] | None = None,
                     k: int | None = None, steps_to_go: int = 0, mode: str = "horizon",
                     cost: Sequence[float] | None = None, truth: Sequence[float] | None = None,
                     error: bool = True, disturbance: Sequence[float] | None = None) -> None:
        """Everything of one control tick, under one lock.

        Writes ``/control/state``, ``/control/reference``, ``/control/error`` (reference - state,
        yaw wrapped; unless ``error=False``), ``/control/command``, and when given
        ``/control/command_limited``, ``/control/horizon`` (``k`` given), ``/control/cost``
        (state_cost, input_cost, stage_cost), ``/sim/truth`` and ``/control/disturbance``.
        """
        text = self._ticks
        err = tracking_error(reference, state) if error else None
        self.add(text.items(state, text.reference(reference), err, command, command_limited, k, steps_to_go, mode,
                            cost, truth, disturbance), log_time_ns)

    def horizon_json(self, k: int, steps_to_go: int, mode: str) -> bytes:
        """The ``/control/horizon`` message."""
        return self._ticks.horizon(k, steps_to_go, mode)

    def event(self, log_time_ns: int, kind: str, text: str, **fields: Any) -> None:
        """An ``/events`` message: ``{"kind", "text", **fields}`` (mode change, arming, failsafe, warning, phase)."""
        obj = {"kind": kind, "text": text}
        obj.update(fields)
        self.add(((T.EVENTS, dumps(obj)),), log_time_ns)

    def flight_start(self, log_time_ns: int, *, controller: str, flight: int | None = None, experiment: str = "",
                     run: int = 0, seed: int | None = None, ts_s: float | None = None, steps: int | None = None,
                     source: str = "flight", **fields: Any) -> int:
        """A ``/flight`` message: every later message up to the next one belongs to this flight.

        Returns the flight index (by default the number of flights started before).
        """
        if flight is None:
            flight = self.flight_count
        obj = {"flight": flight, "controller": controller, "experiment": experiment, "run": run, "seed": seed,
               "ts_s": ts_s, "steps": steps, "source": source}
        obj.update(fields)
        self.add(((T.FLIGHT, dumps(obj)),), log_time_ns)
        self.flight_count += 1
        return flight

    def loop_timing(self, log_time_ns: int, **fields: Any) -> None:
        """A ``/loop/timing`` message (``k``, ``jitter_s``, ``tick_s``, ``deadline_missed``, per-stage ``*_s``)."""
        self.add(((T.TIMING, dumps(fields)),), log_time_ns)

    def mavlink(self, log_time_ns: int, direction: str, msg: Any, *, raw: bool = True) -> None:
        """A pymavlink message: decoded fields on ``/mavlink/<direction>/<TYPE>`` and its frame on ``/mavlink/raw``.

        ``msg`` needs ``get_type()``, ``to_dict()`` and, for ``raw``, ``get_msgbuf()``.
        """
        self.add(mavlink_items(direction, msg, raw), log_time_ns)

    def mavlink_raw(self, log_time_ns: int, direction: str, frame: bytes, msg_type: str = "") -> None:
        """A raw frame on ``/mavlink/raw`` (e.g. one that did not decode)."""
        if direction not in ("in", "out"):
            raise ValueError(f"direction must be 'in' or 'out', got {direction!r}")
        self.add(((T.MAVLINK_RAW, raw_frame_json(direction, msg_type, frame)),), log_time_ns)
