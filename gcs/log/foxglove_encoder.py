"""The log's records to its messages, Foxglove's well-known ones included: the encoder of the log pipeline.

:class:`FoxgloveEncoder` is :class:`gcs.log.encoder.RecordEncoder` (every message of our own channels,
unchanged) plus the ``/foxglove/*`` channels of :mod:`gcs.log.foxglove`, written from the same records
in the writer process (the control loop pays nothing for them):

* :class:`~gcs.log.records.Attachment` ``config.json`` — the mission, from which each flight's planned
  reference path is drawn;
* :class:`~gcs.log.records.FlightStart` — ``/foxglove/reference_path`` at the flight's start (the
  mission's references every :data:`~gcs.log.foxglove.PATH_STEP_S`, shifted by the flight's
  ``origin_m`` as the loop shifts them);
* :class:`~gcs.log.records.Tick`, :class:`~gcs.log.records.TickBlock`,
  :class:`~gcs.log.records.FlightEnd` — ``/foxglove/tf``, ``/foxglove/vehicle_pose`` (the truth when
  there is one, else the estimate), ``/foxglove/reference_pose``; in a simulation
  ``/foxglove/location`` every :data:`~gcs.log.foxglove.SIM_FIX_PERIOD_S`;
* :class:`~gcs.log.records.LinkFrame` — ``/foxglove/location`` of a GLOBAL_POSITION_INT,
  ``/foxglove/log`` of a STATUSTEXT received;
* :class:`~gcs.log.records.Event` — ``/foxglove/log`` (but the ``statustext`` events: the STATUSTEXT
  frames are there already, with their severity).

Samples with a non-finite pose are left out and counted (:attr:`FoxgloveEncoder.skipped`).
``live`` (``gcs fly --live [HOST:]PORT``): every message written is also served on the Foxglove
WebSocket protocol (:mod:`gcs.log.foxglove_live`) until :meth:`FoxgloveEncoder.close`.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from gcs.log import foxglove as F
from gcs.log import topics as T
from gcs.log.encoder import RecordEncoder
from gcs.log.records import SIMULATED, Attachment, Event, FlightEnd, FlightStart, LinkFrame, Tick, TickBlock

__all__ = ["FoxgloveEncoder", "planned_path"]

_GLOBAL_POSITION = T.mavlink_topic("in", "GLOBAL_POSITION_INT")
_STATUSTEXT = T.mavlink_topic("in", "STATUSTEXT")


def planned_path(config_json: bytes, origin_m: Any = None) -> list[tuple[float, ...]] | None:
    """The mission's reference states (paper frame) every :data:`~gcs.log.foxglove.PATH_STEP_S` over its
    length (at most :data:`~gcs.log.foxglove.MAX_PATH_POSES`), shifted by ``origin_m`` (x, y, z) [m];
    None when ``config_json`` is not a valid config."""
    from gcs.config import parse_config
    from gcs.mission import Mission

    try:
        config = parse_config(json.loads(config_json), "config.json")
        mission = Mission(config.mission, zero_velocity=config.experiment.zero_velocity_reference)
        ox, oy, oz = (float(v) for v in (origin_m if origin_m is not None else (0.0, 0.0, 0.0)))
    except (ValueError, TypeError, KeyError, AttributeError):  # ConfigError is a ValueError
        return None
    n = min(F.MAX_PATH_POSES, max(2, math.ceil(mission.duration_s / F.PATH_STEP_S) + 1))
    out = []
    for t in np.linspace(0.0, mission.duration_s, n).tolist():
        r = tuple(mission.reference(t))
        out.append((r[0] + ox, r[1] + oy, r[2] + oz, *r[3:]))
    return out


class FoxgloveEncoder(RecordEncoder):
    """:class:`~gcs.log.encoder.RecordEncoder` with the ``/foxglove/*`` channels (see the module docstring)."""

    def __init__(self, log: Any, live: str | None = None) -> None:
        super().__init__(log)
        self.live = None
        if live:
            from gcs.log.foxglove_live import start_for

            self.live = start_for(log, live)
        self._config_json: bytes | None = None
        self._path: tuple[str, list | None] | None = None  # (origin, path) of the last flight: a simulation repeats it
        self._simulated = False
        self._fix_every = 0
        #: Samples left out of the Foxglove channels (a non-finite pose; a GLOBAL_POSITION_INT without a fix).
        self.skipped = 0

    def close(self) -> None:
        """Stop the live server, if any (the log is the caller's to close)."""
        live, self.live = self.live, None
        if live is not None:
            live.close()

    # ------------------------------------------------------------------ file records, the flight
    def _attachment(self, rec: Attachment) -> None:
        super()._attachment(rec)
        if rec.name == "config.json":
            self._config_json, self._path = bytes(rec.data), None

    def _start(self, rec: FlightStart) -> None:
        super()._start(rec)
        t = self._origin + (rec.t_ns or 0)
        self._simulated = rec.source == SIMULATED
        self._fix_every = max(1, round(F.SIM_FIX_PERIOD_S / rec.ts_s)) if self._simulated and rec.ts_s else 0
        if self._config_json is None:
            return
        origin = (rec.extra or {}).get("origin_m")
        key = repr(origin)
        if self._path is None or self._path[0] != key:
            self._path = (key, planned_path(self._config_json, origin))
        path = self._path[1]
        if path:
            self.log.add(((T.FOXGLOVE_REFERENCE_PATH, F.poses_in_frame(t, path)),), t)

    def _poses(self, t: int, vehicle: Any, reference: Any, k: int | None) -> list[tuple[str, bytes]]:
        """The Foxglove messages of one state sample at log time ``t``."""
        items = []
        if vehicle is not None:
            if F.finite_pose(vehicle):
                tf, pose = F.pose_texts(t, vehicle)
                items += [(T.FOXGLOVE_TF, tf), (T.FOXGLOVE_VEHICLE_POSE, pose)]
                if self._fix_every and k is not None and k % self._fix_every == 0:
                    fix = F.sim_fix(t, vehicle)
                    if fix is not None:
                        items.append((T.FOXGLOVE_LOCATION, fix))
            else:
                self.skipped += 1
        if reference is not None:
            if F.finite_pose(reference):
                items.append((T.FOXGLOVE_REFERENCE_POSE, F.pose_json(t, reference)))
            else:
                self.skipped += 1
        return items

    def _tick(self, rec: Tick) -> None:
        super()._tick(rec)
        t = self._origin + rec.t_ns
        items = self._poses(t, rec.state if rec.truth is None else rec.truth, rec.reference, rec.k)
        if items:
            self.log.add(items, t)

    def _block(self, b: TickBlock) -> None:
        super()._block(b)
        n = b.command.shape[0]
        if n == 0:
            return
        truth, ref = np.asarray(b.truth, float), np.asarray(b.reference, float)
        vehicle = np.column_stack([truth[:, [1, 0, 2]], F.enu_flu_quaternions(truth[:, 6:9])])
        target = np.column_stack([ref[:, [1, 0, 2]], F.enu_flu_quaternions(ref[:, 6:9])])
        ok_v, ok_r = np.isfinite(vehicle).all(axis=1).tolist(), np.isfinite(target).all(axis=1).tolist()
        self.skipped += ok_v.count(False) + ok_r.count(False)
        vehicle_rows, target_rows = vehicle.tolist(), target.tolist()
        fix_every, add, ts_ns = self._fix_every, self.log.add, self._ts_ns
        t = self._origin + b.k0 * ts_ns
        for i in range(n):
            items = []
            sec, nsec = F.stamp(t)
            if ok_v[i]:
                values = (sec, nsec, *vehicle_rows[i])
                items += [(T.FOXGLOVE_TF, F.TF_TEMPLATE % values), (T.FOXGLOVE_VEHICLE_POSE, F.POSE_TEMPLATE % values)]
                if fix_every and (b.k0 + i) % fix_every == 0:
                    fix = F.sim_fix(t, truth[i].tolist())
                    if fix is not None:
                        items.append((T.FOXGLOVE_LOCATION, fix))
            if ok_r[i]:
                items.append((T.FOXGLOVE_REFERENCE_POSE, F.POSE_TEMPLATE % (sec, nsec, *target_rows[i])))
            if items:
                add(items, t)
            t += ts_ns

    def _end(self, rec: FlightEnd) -> None:
        super()._end(rec)
        t = self._origin + rec.t_ns
        items = self._poses(t, rec.state if rec.truth is None else rec.truth, rec.reference, None)
        if items:
            self.log.add(items, t)

    # ------------------------------------------------------------------ link, events
    def _frame(self, rec: LinkFrame) -> None:
        items = self.links.frame(rec)
        t = self._origin + rec.t_ns
        if rec.direction == "in" and rec.protocol == "mavlink":
            for topic, data in items:
                if topic == _GLOBAL_POSITION:
                    fix = F.location_fix(t, json.loads(data))
                    if fix is None:
                        self.skipped += 1
                    else:
                        items.append((T.FOXGLOVE_LOCATION, fix))
                    break
                if topic == _STATUSTEXT:
                    line = F.statustext_line(t, json.loads(data))
                    if line is not None:
                        items.append((T.FOXGLOVE_LOG, line))
                    break
        self.log.add(items, t)

    def _event(self, rec: Event) -> None:
        super()._event(rec)
        if rec.kind != "statustext":
            t = self._origin + rec.t_ns
            self.log.add(((T.FOXGLOVE_LOG, F.log_line(t, F.event_level(rec.kind), rec.text, f"gcs.{rec.kind}")),), t)
