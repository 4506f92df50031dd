"""What ``gcs sim`` logs: every control tick of every flight, one file, in blocks of ticks.

:func:`gcs.sim.simulate` feeds a :class:`SimRecorder` the lists it keeps anyway (states,
references, commands, steps to go) plus the estimates; the recorder hands them to a sink
(:mod:`gcs.log.sink`) in :class:`~gcs.log.records.TickBlock` records of :data:`BLOCK_TICKS`
ticks, with the flight's other records (:mod:`gcs.log.records`), on the flight's own time
line (the writer places the flight after what the file holds, :data:`~gcs.log.records.GAP_NS`
apart):

* a :class:`~gcs.log.records.FlightStart` (``/flight``) and an ``/events`` ``flight_start``;
* per tick k (at ``k * ts``): the messages of a tick (``/control/state`` = the estimate,
  ``reference``, ``error``, ``command``, ``horizon``, ``cost`` of LOC and NLSOC on the truth)
  and ``/sim/truth``;
* ``/events`` ``phase`` at each mission phase change and ``horizon_end`` when the horizon
  runs out within the flight;
* after the last command (k = K): ``/control/reference`` and ``/sim/truth`` once more,
  ``/sim/metrics`` and an ``/events`` ``flight_end``.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gcs.control.base import horizon_mode
from gcs.log.records import SIMULATED, Event, FlightEnd, FlightStart, Metrics, TickBlock
from gcs.log.sink import InlineSink
from gcs.log.writer import FlightLog

__all__ = ["BLOCK_TICKS", "BYTES_PER_TICK", "SimRecorder", "horizon_modes"]

#: Ticks handed to the log at a time.
BLOCK_TICKS = 1000
#: Generous size of one logged simulation tick, compressed [bytes] (for the free-space check).
BYTES_PER_TICK = 700


def horizon_modes(k0: int, n: int, horizon_steps: int | None, after: str | None) -> list[str]:
    """Mode of ticks k0 .. k0 + n - 1 (:func:`gcs.control.base.horizon_mode` of each)."""

    if horizon_steps is None:
        return ["pd"] * n
    inside = max(0, min(n, horizon_steps - k0))
    return ["horizon"] * inside + [horizon_mode(horizon_steps, horizon_steps, after)] * (n - inside)


def _rows(rows: list, k0: int, k1: int, width: int) -> np.ndarray:
    """``rows[k0:k1]`` (tuples of ``width`` floats) as an array, faster than ``np.array``."""
    n = k1 - k0
    flat = np.fromiter(itertools.chain.from_iterable(rows[k0:k1]), dtype=float, count=n * width)
    return flat.reshape(n, width)


def _timed_events(mission: Any, ts_s: float, horizon_steps: int | None, after: str | None) -> dict[int, list]:
    """``{k: [(kind, text, fields)]}`` of the phase changes and the end of the horizon."""
    events: dict[int, list] = {}
    for s in mission.segments:
        i, kind = int(s.index), s.phase.kind
        events.setdefault(round(float(s.t_start_s) / ts_s), []).append(
            ("phase", f"phase {i}: {kind}", {"phase": kind, "index": i}))
    if horizon_steps is not None:
        events.setdefault(horizon_steps, []).append(
            ("horizon_end", f"horizon over after {horizon_steps} steps: {after}", {"after_horizon": after}))
    return events


class SimRecorder:
    """What :func:`gcs.sim.simulate` calls: shares the simulation's lists and hands them to the log in blocks.

    Parameters
    ----------
    log : FlightLog (written in this process) or a sink of :mod:`gcs.log.sink`
    config : gcs.config.Config
    controller : gcs.control.Controller
        The controller flown (for its horizon schedule).
    name : str
        Its name as given to ``simulate``.
    cost : gcs.control.cost.CostSpec or None
        Its cost J (``/control/cost``).
    states, refs, cmds, j_log : list
        The simulation's own lists (states has one more entry than the others), appended by it.
    """

    def __init__(self, log: Any, config: Any, controller: Any, name: str, *, run: int, seed: int, mission: Any,
                 steps: int, cost: Any, states: list, refs: list, cmds: list, j_log: list) -> None:
        self.sink = InlineSink(log) if isinstance(log, FlightLog) else log
        self.states, self.refs, self.cmds, self.j_log = states, refs, cmds, j_log
        self.estimates: list = []
        self.sent = 0
        e, v = config.experiment, config.vehicle
        self.name, self.run = name, run
        self.ts_ns = round(e.ts_s * 1e9)
        self.horizon = (getattr(controller, "horizon_steps", None), getattr(controller, "after", None))
        self.events = _timed_events(mission, e.ts_s, *self.horizon)
        self.index = self.sink.flight_count
        spec = cost.to_dict(v.mass_kg, v.gravity_m_s2) if cost is not None else None
        self.sink.put_many([
            FlightStart(None, name, e.name, e.ts_s, steps, SIMULATED, self.index, run, seed, spec),
            Event(0, "flight_start", f"{name} run {run} (seed {seed})",
                  {"flight": self.index, "controller": name, "run": run})])

    def tick(self, estimate: Sequence[float]) -> None:
        """After each tick (the simulation has appended to its lists)."""
        self.estimates.append(estimate)
        if len(self.estimates) >= BLOCK_TICKS:
            self._send(self.sent + len(self.estimates))

    def _send(self, k1: int) -> None:
        k0 = self.sent
        if k1 <= k0:
            return
        n = k1 - k0
        records = [Event(k * self.ts_ns, kind, text, fields) for k in range(k0, k1) if k in self.events
                   for kind, text, fields in self.events[k]]
        records.append(TickBlock(k0, _rows(self.states, k0, k1, 12), _rows(self.estimates, 0, n, 12),
                                 _rows(self.refs, k0, k1, 12), _rows(self.cmds, k0, k1, 4),
                                 np.array(self.j_log[k0:k1], dtype=np.int64), horizon_modes(k0, n, *self.horizon)))
        self.sink.put_many(records)
        self.estimates.clear()  # sent: the simulation keeps only what its metrics need
        self.sent = k1

    def finish(self, metrics: Mapping[str, float]) -> None:
        """After the flight: the remaining ticks, the final state and reference, the metrics."""
        k = len(self.cmds)
        self._send(k)
        t_end = k * self.ts_ns
        self.sink.put_many([
            FlightEnd(t_end, tuple(np.asarray(self.refs[k], float).tolist()),
                      truth=tuple(np.asarray(self.states[k], float).tolist())),
            Metrics(t_end, {key: float(v) for key, v in metrics.items()}),
            Event(t_end, "flight_end", f"{self.name} run {self.run}: {k} steps", {"flight": self.index})])
