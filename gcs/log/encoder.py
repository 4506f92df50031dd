"""Records to MCAP messages: the one encoder of the log pipeline, for flown and simulated flights alike.

:class:`RecordEncoder` writes each record of :mod:`gcs.log.records` into a
:class:`~gcs.log.writer.FlightLog`, choosing what to do by the record's type:

* :class:`~gcs.log.records.FlightStart` — ``/flight`` (a flight with ``t_ns`` None is placed
  :data:`~gcs.log.records.GAP_NS` after what the file holds, and its records' times count
  from its start); its cost (:meth:`gcs.control.cost.CostSpec.to_dict`) gives every tick's
  ``/control/cost`` (:mod:`gcs.control.cost`, the one definition of the eq. 5 / 17 stage cost);
* :class:`~gcs.log.records.Tick` — ``/control/state``, ``reference``, ``error`` (reference -
  estimate, yaw wrapped), ``command``, ``command_limited``, ``horizon``, ``cost`` (on the truth
  when there is one, else the estimate; on the limited command when there is one), ``/sim/truth``
  and ``/loop/timing``;
* :class:`~gcs.log.records.TickBlock` — the same messages for each of its ticks (the stage
  cost and the error computed for the whole block at once);
* :class:`~gcs.log.records.LinkFrame`, :class:`~gcs.log.records.Garbage` — decoded and raw
  link messages (:mod:`gcs.log.linkframes`);
* :class:`~gcs.log.records.Event` — ``/events``; :class:`~gcs.log.records.FlightEnd` — the
  state (estimate, truth) and reference closing the flight record;
  :class:`~gcs.log.records.Metrics` — ``/sim/metrics`` (simulated flight: with its index,
  controller and run) or ``/flight/metrics``; :class:`~gcs.log.records.Metadata`,
  :class:`~gcs.log.records.Attachment` — MCAP metadata and attachments.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from gcs.control.cost import StageCost, cost_variables, stage_costs
from gcs.errors import LogError
from gcs.log import topics as T
from gcs.log.jsonfmt import FIXED, TickText, timing_json, tracking_error
from gcs.log.linkframes import LinkDecoder
from gcs.log.records import (
    GAP_NS,
    SIMULATED,
    Attachment,
    Event,
    FlightEnd,
    FlightStart,
    Garbage,
    LinkFrame,
    Metadata,
    Metrics,
    Tick,
    TickBlock,
)
from gcs.log.writer import FlightLog

__all__ = ["RecordEncoder"]


class RecordEncoder:
    """Writes records into a :class:`FlightLog`, after what it already holds."""

    def __init__(self, log: FlightLog) -> None:
        self.log = log
        self.links = LinkDecoder()
        self._flight: FlightStart | None = None
        self._index = 0
        self._origin = 0
        self._ts_ns = 0
        self._cost: StageCost | None = None
        self._weights: tuple[np.ndarray, np.ndarray] | None = None
        self._text = TickText()
        self._last_ref: np.ndarray | None = None
        self._ref_text = b""
        self._handlers = {FlightStart: self._start, Tick: self._tick, TickBlock: self._block, LinkFrame: self._frame,
                          Garbage: self._garbage, Event: self._event, FlightEnd: self._end, Metrics: self._metrics,
                          Metadata: self._metadata, Attachment: self._attachment}

    @property
    def undecodable(self) -> int:
        """MAVLink frames that did not decode (logged raw)."""
        return self.links.undecodable

    def write(self, record: Any) -> None:
        """Write one record.

        Raises
        ------
        LogError
            For something that is not a record to write (or when the log fails).
        """
        handler = self._handlers.get(type(record))
        if handler is None:
            raise LogError(f"{self.log.path}: not a log record to write: {record!r:.80}")
        handler(record)

    def write_all(self, records: Iterable[Any]) -> None:
        """Write records in order."""
        for record in records:
            self.write(record)

    # ------------------------------------------------------------------ the flight
    def _start(self, rec: FlightStart) -> None:
        log = self.log
        if rec.t_ns is None:
            t = self._origin = 0 if log.end_time_ns is None else log.end_time_ns + GAP_NS
        else:
            self._origin, t = 0, rec.t_ns
        self._index = log.flight_start(t, controller=rec.controller, flight=rec.flight, experiment=rec.experiment,
                                       run=rec.run, seed=rec.seed, ts_s=rec.ts_s, steps=rec.steps, source=rec.source,
                                       **(rec.extra or {}))
        self._flight = rec
        self._ts_ns = round(rec.ts_s * 1e9) if rec.ts_s else 0
        self._cost = StageCost.from_dict(rec.cost) if rec.cost is not None else None
        self._weights = None if self._cost is None else (np.array(self._cost.Q, float), np.array(self._cost.R, float))
        self._text = TickText()
        self._last_ref = None
        self._ref_text = b""

    def _tick(self, rec: Tick) -> None:
        state, ref, limited = rec.state, rec.reference, rec.command_limited
        cost = None
        if self._cost is not None:
            cost = self._cost.terms(state if rec.truth is None else rec.truth, ref,
                                    rec.command if limited is None else limited)
        text = self._text
        items = text.items(state, text.reference(ref), tracking_error(ref, state), rec.command, limited, rec.k,
                           rec.steps_to_go, rec.mode, cost, rec.truth, rec.disturbance)
        if rec.timing is not None:
            items.append((T.TIMING, timing_json(rec.k, rec.timing)))
        self.log.add(items, self._origin + rec.t_ns)

    def _new_references(self, reference: np.ndarray) -> list[bool]:
        """Which rows of a block differ from the one before (the others reuse its text)."""
        prev = reference[:1] if self._last_ref is None else self._last_ref[None, :]
        new_ref = np.any(reference != np.vstack([prev, reference[:-1]]), axis=1)
        if self._last_ref is None:
            new_ref[0] = True
        self._last_ref = reference[-1].copy()
        return new_ref.tolist()

    def _block_costs(self, b: TickBlock) -> list | None:
        """The stage terms of a block's ticks, on the truth, vectorised."""
        c = self._cost
        if c is None or self._weights is None:
            return None
        x, u = cost_variables(c.kind, b.truth, b.reference, b.command, c.mass_kg, c.gravity_m_s2,
                              c.gravity_compensated)
        return stage_costs(x, u, *self._weights).tolist()

    def _block(self, b: TickBlock) -> None:
        n = b.command.shape[0]
        if n == 0:
            return
        err = b.reference - b.estimate
        with np.errstate(invalid="ignore"):  # a non-finite estimate stays non-finite (its tick is skipped)
            err[:, 8] = (err[:, 8] + math.pi) % (2 * math.pi) - math.pi
        costs = self._block_costs(b)
        new_ref = self._new_references(b.reference)
        truth, ref, est, errs = b.truth.tolist(), b.reference.tolist(), b.estimate.tolist(), err.tolist()
        cmd, j, modes = b.command.tolist(), b.steps_to_go.tolist(), b.modes
        encode_ref, items, add = FIXED[T.REFERENCE].encode, self._text.items, self.log.add
        ref_text = self._ref_text
        ts_ns = self._ts_ns
        t = self._origin + b.k0 * ts_ns
        k = b.k0
        for i in range(n):
            if new_ref[i]:
                ref_text = encode_ref(tuple(ref[i]))
            add(items(tuple(est[i]), ref_text, tuple(errs[i]), tuple(cmd[i]), None, k, j[i], modes[i],
                      None if costs is None else tuple(costs[i]), tuple(truth[i])), t)
            t += ts_ns
            k += 1
        self._ref_text = ref_text

    def _end(self, rec: FlightEnd) -> None:
        items = []
        if rec.state is not None:
            items.append((T.STATE, FIXED[T.STATE].encode(tuple(rec.state))))
        items.append((T.REFERENCE, FIXED[T.REFERENCE].encode(tuple(rec.reference))))
        if rec.truth is not None:
            items.append((T.TRUTH, FIXED[T.TRUTH].encode(tuple(rec.truth))))
        self.log.add(items, self._origin + rec.t_ns)

    def _metrics(self, rec: Metrics) -> None:
        fl = self._flight
        if fl is not None and fl.source == SIMULATED:
            topic, doc = T.SIM_METRICS, {"flight": self._index, "controller": fl.controller, "run": fl.run}
        else:
            topic, doc = T.FLIGHT_METRICS, {"flight": self._index}
        doc.update({key: float(v) for key, v in rec.values.items()})
        self.log.write(topic, self._origin + rec.t_ns, doc)

    # ------------------------------------------------------------------ link, events, file records
    def _frame(self, rec: LinkFrame) -> None:
        self.log.add(self.links.frame(rec), self._origin + rec.t_ns)

    def _garbage(self, rec: Garbage) -> None:
        self.log.add(self.links.garbage(rec), self._origin + rec.t_ns)

    def _event(self, rec: Event) -> None:
        self.log.event(self._origin + rec.t_ns, rec.kind, rec.text, **(rec.fields or {}))

    def _metadata(self, rec: Metadata) -> None:
        self.log.metadata(rec.name, rec.data)

    def _attachment(self, rec: Attachment) -> None:
        self.log.attachment(rec.name, rec.media_type, rec.data, log_time_ns=rec.log_time_ns)
