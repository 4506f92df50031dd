"""The mission loop: one composition of parts, flown the same way on every vehicle and in ``gcs sim``.

Parts: the clock (of the :class:`~gcs.flight.context.FlightContext`), the vehicle session
(:class:`~gcs.flight.session.VehicleSession`: telemetry and estimate in, commands out), the
mission reference (:class:`gcs.mission.Mission`), the controller, the safety envelope
(optional), the flight log (the context's recorder) and the loop statistics (optional).
Each tick runs on absolute deadlines of the clock (no drift): wait, pump the telemetry,
estimate, failsafes and interrupts, reference, controller (with the session's estimated
disturbance acceleration, zero where none is estimated), envelope, send, record.
Nothing here reads wall time except the per-stage timing of :class:`~gcs.flight.stats.LoopStats`.

The exit reasons are :mod:`gcs.flight.result`'s; a failsafe ends the tick loop and the
session's :meth:`~gcs.flight.session.VehicleSession.finish` lands as the reason asks.  Any
exception while flying becomes ``internal_error``: the vehicle is landed, never abandoned.
"""

from __future__ import annotations

import time
import traceback
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Callable

import numpy as np

from gcs.config import PhaseConfig
from gcs.control import FiniteHorizonController, model_params
from gcs.control.base import Controller, horizon_mode
from gcs.flight.authority import TrackingWatch
from gcs.flight.context import FlightContext
from gcs.flight.result import FlightResult
from gcs.flight.safety import SafetyEnvelope
from gcs.flight.session import VehicleSession, finite
from gcs.flight.stats import LoopStats
from gcs.log.records import LoopTiming
from gcs.metrics import FlightRecord, controller_cost, flight_metrics
from gcs.mission import Mission
from quadrotor.state import Command, State

__all__ = ["MissionLoop", "TOUCHDOWN_WAIT_S"]

#: After the descent of a vehicle that does not land itself: how long to wait for touchdown [s].
TOUCHDOWN_WAIT_S = 5.0


@dataclass
class _Track:
    """What one flight accumulates tick by tick."""

    origin: tuple[float, float, float]
    t0_ns: int
    tracking: TrackingWatch
    states: list = field(default_factory=list)
    truths: list = field(default_factory=list)
    refs: list = field(default_factory=list)
    cmds: list = field(default_factory=list)
    js: list = field(default_factory=list)
    override: Mission | None = None
    override_k0: int = 0
    override_dz: float = 0.0
    descent: bool = False
    phase_idx: int = -1
    handled_interrupts: int = 0
    next_live_s: float = 0.0
    next_housekeeping_k: int = 0
    log_prev_ns: int = 0
    last_cmd: Command | None = None


class MissionLoop:
    """Fly ``config``'s mission with ``controller`` on ``session``.

    Parameters
    ----------
    ctx : FlightContext
    controller_name : str
    controller : Controller
        Designed; stepped ``controller.step(k, state, reference, disturbance_m_s2=d)``, ``d`` the session's
        estimated disturbance minus the reference's acceleration (:meth:`MissionLoop._drift`).
    session : VehicleSession
    envelope : SafetyEnvelope or None
        Limits, tilt guard and geofence (None: the command goes as the controller gave it).
    stats : bool
        Keep per-stage timing and deadline statistics (the simulation does not need them).
    duration_s : float or None
        How long the mission's references are flown; None = the mission's own length.
    live_period_s : float
        Period of the console's live line [s] (0 = none).
    close_at_end_time : bool
        Close the flight record (the J terminal term) with the mission's reference at the end
        time, as ``gcs sim`` always has; False: with the last reference flown, as ``gcs fly``
        always has (both kept so that the published tables do not move).
    """

    def __init__(self, ctx: FlightContext, controller_name: str, controller: Controller, session: VehicleSession, *,
                 envelope: SafetyEnvelope | None = None, stats: bool = True, duration_s: float | None = None,
                 live_period_s: float = 0.5, close_at_end_time: bool = False) -> None:
        config = ctx.config
        e = config.experiment
        self.ctx = ctx
        self.config = config
        self.controller_name = controller_name
        self.controller = controller
        self.session = session
        self.envelope = envelope
        self.ts = e.ts_s
        self.ts_ns = int(round(e.ts_s * 1e9))
        self.ticks_per_second = max(1, int(round(1.0 / e.ts_s)))
        self.mission = Mission(config.mission, zero_velocity=e.zero_velocity_reference)
        self._feed_acceleration = e.acceleration_reference  # zero velocity references: Mission gives 0
        self.duration_s = self.mission.duration_s if duration_s is None else duration_s
        self.mission_steps = int(round(self.duration_s / e.ts_s))
        self.stats = LoopStats(self.ts_ns) if stats else None
        self.live_period_s = live_period_s
        self.close_at_end_time = close_at_end_time
        self.model = model_params(config)
        self.cost = controller_cost(controller_name, config)
        self.horizon = controller if isinstance(controller, FiniteHorizonController) else None
        self._limit_flags_seen: set[str] = set()
        self._tap: Any = None
        #: A vehicle that can fail (link, mode, streams) is checked every tick; a simulated one need not be.
        self._supervised = getattr(session, "supervised", True)

    # ------------------------------------------------------------------ the flight
    def run(self, tap: Callable[[_Track], Any] | None = None) -> FlightResult:
        """Fly the mission (preflight must have passed) and land; returns the summary.

        ``tap(track)``, when given, returns an object told ``tick(estimate)`` after every tick and
        ``finish(metrics)`` at the end, sharing the flight's lists (the simulation's block log).
        """
        track = self._begin()
        self._tap = tap(track) if tap is not None else None
        wall0 = time.perf_counter()
        try:
            reason = self._fly(track)
        except Exception as exc:  # noqa: BLE001 - any failure while flying must end in a landing, never an abandoned vehicle
            reason = "internal_error"
            self.ctx.event("failsafe", f"internal error at t = {len(track.cmds) * self.ts:.2f} s "
                                       f"({type(exc).__name__}: {exc}): landing", traceback=traceback.format_exc())
        return self._end(track, reason, time.perf_counter() - wall0)

    def _begin(self) -> _Track:
        ctx, e = self.ctx, self.config.experiment
        t0 = ctx.clock.now_ns()
        # The mission is flown relative to where the vehicle stands at its start (the local
        # origin of a real autopilot need not be the takeoff point).
        origin = self.session.mission_origin(self.session.estimate(0.0, None))
        if self.envelope is not None:
            self.envelope.origin = origin
        rec = ctx.recorder
        rec.flight_start(t0, controller=self.controller_name, experiment=e.name, ts_s=e.ts_s, steps=self.mission_steps,
                         cost=self.cost.to_dict(self.model.mass_kg, self.model.gravity_m_s2)
                         if self.cost else None, origin_m=list(origin))
        ctx.event("phase", f"takeoff point (x {origin[0]:.2f}, y {origin[1]:.2f}, z {origin[2]:.2f}) m")
        ctx.event("phase", f"mission start: {len(self.config.mission)} phases, {self.mission.duration_s:g} s")
        fc = self.config.flight
        return _Track(origin=origin, t0_ns=t0, tracking=TrackingWatch(e.ts_s, fc.tracking_lost_m, fc.tracking_lost_s))

    def _fly(self, tr: _Track) -> str:
        """The tick loop; returns the exit reason."""
        clock, session, ts_ns = self.ctx.clock, self.session, self.ts_ns
        mark = getattr(clock, "mark_sent", None)
        lockstep = self.ctx.lockstep
        k = 0
        while True:
            deadline = tr.t0_ns + k * ts_ns
            clock.sleep_until_ns(deadline)
            wake = clock.now_ns()
            late = wake - deadline
            c0 = time.perf_counter_ns() if self.stats is not None else 0
            session.pump()
            c1 = time.perf_counter_ns() if self.stats is not None else 0
            state = session.estimate(self.ts, tr.last_cmd)
            truth = session.truth()
            c2 = time.perf_counter_ns() if self.stats is not None else 0
            t = k * self.ts
            reason = self._failsafe(k, t, wake, state, tr)
            if reason is not None:
                return reason
            ref = self._reference(k, t, state, tr)
            if ref is None:
                return "interrupted" if tr.handled_interrupts else "completed"
            lost = tr.tracking.update(state, ref)
            if lost is not None:
                self.ctx.event("failsafe", f"{lost} at t = {t:.2f} s: landing")
                return "out_of_authority"
            raw = self.controller.step(k, state, ref, disturbance_m_s2=self._drift(t, tr))
            cmd, reason = self._limit(t, state, raw)
            if reason is not None:
                return reason
            c3 = time.perf_counter_ns() if self.stats is not None else 0
            session.send(state, cmd)
            if mark is not None:
                mark()
            c4 = time.perf_counter_ns() if self.stats is not None else 0
            fault = session.fault()
            if fault is not None:  # the output guard blocked the command (a safe one went instead)
                return fault[0]
            self._record(k, wake, late, state, truth, ref, raw, cmd, tr, (c0, c1, c2, c3, c4))
            if k >= tr.next_housekeeping_k:  # once a second, skipped ticks or not (a GCS heartbeat among it)
                tr.next_housekeeping_k = k + self.ticks_per_second
                session.housekeeping()
            if self.live_period_s and t >= tr.next_live_s:
                tr.next_live_s = t + self.live_period_s
                self.ctx.console(f"t {t:7.2f} s  z {state.z:6.3f} m  ref {ref.z:6.3f} m  err {ref.z - state.z:+.3f} m  "
                                 f"xy ({state.x:+.2f}, {state.y:+.2f}) m  thrust {cmd.thrust_n:5.2f} N")
            k += 1
            if not lockstep and late >= ts_ns:
                skipped = int(late // ts_ns)
                k += skipped
                if self.stats is not None:
                    self.stats.skipped_ticks += skipped

    def _failsafe(self, k: int, t: float, wake: int, state: State, tr: _Track) -> str | None:
        """The checks of one tick, in order; an exit reason (said as an event) or None."""
        ctx, session, stale_s = self.ctx, self.session, self.config.flight.telemetry_stale_s
        if not self._supervised:
            return self._interrupted(k, t, state, tr)
        fault = session.fault()
        if fault is not None:
            if fault[1]:
                ctx.event("failsafe", f"{fault[1]} at t = {t:.2f} s")
            return fault[0]
        if not session.fresh(wake, stale_s):
            ctx.event("failsafe", f"telemetry stale for more than {stale_s:g} s at t = {t:.2f} s: landing")
            return "telemetry_lost"
        health = session.health(wake)
        if health is not None:
            ctx.event("failsafe", f"{health[1]} at t = {t:.2f} s: landing")
            return health[0]
        if not finite(state):
            ctx.event("failsafe", f"the state estimate is not finite at t = {t:.2f} s: landing")
            return "unsafe_command"
        if self.envelope is not None:
            breach = self.envelope.breaches(state)
            if breach:
                ctx.event("failsafe", f"{', '.join(sorted(breach))} breached at t = {t:.2f} s "
                                      f"(x {state.x:.2f}, y {state.y:.2f}, z {state.z:.2f} m): landing")
                return "geofence"
        lost = session.control_lost()
        if lost is not None:
            ctx.event("failsafe",
                      f"the vehicle left {session.control_name} at t = {t:.2f} s ({lost}): stopping setpoints")
            return "vehicle_took_over"
        return self._interrupted(k, t, state, tr)

    def _interrupted(self, k: int, t: float, state: State, tr: _Track) -> str | None:
        """Ctrl-C: the first one flies a controlled descent, the second lands at once."""
        ctx = self.ctx
        count = ctx.interrupts.count
        if count > tr.handled_interrupts:
            tr.handled_interrupts = count
            if count >= 2:
                ctx.event("failsafe", "second interrupt: landing now")
                return "immediate_land"
            tr.override, tr.override_dz = self._landing_mission(state, tr.origin[2])
            tr.override_k0 = k
            ctx.event("interrupt", f"interrupted at t = {t:.2f} s: controlled descent from z = {state.z:.2f} m "
                                   f"at {self.config.flight.landing_speed_m_s:g} m/s")
        return None

    def _reference(self, k: int, t: float, state: State, tr: _Track) -> State | None:
        """This tick's reference, or None when the flight is over (mission flown, descent done)."""
        if tr.override is None and t >= self.duration_s:
            if self.session.lands_itself:
                return None
            tr.descent = True
            tr.override, tr.override_dz = self._landing_mission(state, tr.origin[2])
            tr.override_k0 = k
            self.ctx.event("phase", f"mission over at t = {t:.2f} s: descent from z = {state.z:.2f} m "
                                    f"at {self.config.flight.landing_speed_m_s:g} m/s")
        if tr.override is not None:
            tm = (k - tr.override_k0) * self.ts
            if tm >= tr.override.duration_s and (self.session.lands_itself or self.session.landed()
                                                 or tm >= tr.override.duration_s + TOUCHDOWN_WAIT_S):
                return None
            r = tr.override.reference(min(tm, tr.override.duration_s))  # x, y from the estimate: absolute
            return r._replace(z=r.z + tr.override_dz)
        seg = self.mission.segment_at(t)
        if seg is not None and seg.index != tr.phase_idx:
            tr.phase_idx = seg.index
            self.ctx.event("phase", f"{seg.phase.kind} ({seg.phase.duration_s:g} s) at t = {t:.2f} s",
                           phase=seg.phase.kind, index=seg.index)
        r = self.mission.reference(t)
        ox, oy, oz = tr.origin
        return r if ox == oy == oz == 0.0 else r._replace(x=r.x + ox, y=r.y + oy, z=r.z + oz)

    def _drift(self, t: float, tr: _Track) -> tuple[float, float, float]:
        """The acceleration the laws compensate: the estimated disturbance minus the mission
        reference's acceleration (fed forward, :meth:`Mission.acceleration`; none in the descent)."""
        d = self.session.disturbance_m_s2()
        if not self._feed_acceleration or tr.override is not None:
            return d
        a = self.mission.acceleration(t)
        return d if a[0] == a[1] == a[2] == 0.0 else (d[0] - a[0], d[1] - a[1], d[2] - a[2])

    def _limit(self, t: float, state: State, raw: Command) -> tuple[Command, str | None]:
        """The command after the envelope, or the exit reason of a non-finite one (never sent)."""
        if self.envelope is None:
            if not finite(raw):
                self.ctx.event("failsafe", f"{self.controller_name} commanded a non-finite value at t = {t:.2f} s "
                                           f"({tuple(raw)}): not sent, landing")
                return raw, "unsafe_command"
            return raw, None
        cmd, flags = self.envelope.apply(state, raw)
        if "non-finite" in flags:
            self.ctx.event("failsafe", f"{self.controller_name} commanded a non-finite value at t = {t:.2f} s "
                                       f"({tuple(raw)}): not sent, landing")
            return cmd, "unsafe_command"
        for f in flags - self._limit_flags_seen:
            self.ctx.event("warning", f"{f} limit acting at t = {t:.2f} s")
        self._limit_flags_seen |= flags
        return cmd, None

    def _record(self, k: int, wake: int, late: int, state: State, truth: State | None, ref: State, raw: Command,
                cmd: Command, tr: _Track, c: tuple[int, int, int, int, int]) -> None:
        h = self.horizon
        j = (h.last_steps_to_go or 0) if h is not None else 0
        rec = self.ctx.recorder
        if rec.sink is not None:
            c0, c1, c2, c3, c4 = c
            rec.tick(wake, k, state, ref, raw, cmd, j,
                     horizon_mode(k, h.horizon_steps if h else None, h.after if h else None),
                     LoopTiming(late / 1e9, (c4 - c0) / 1e9, late >= self.ts_ns, (c1 - c0) / 1e9, (c2 - c1) / 1e9,
                                (c3 - c2) / 1e9, (c4 - c3) / 1e9, tr.log_prev_ns / 1e9), self.session.observer_log())
        if self.stats is not None:
            c0, c1, c2, c3, c4 = c
            c5 = time.perf_counter_ns()
            tr.log_prev_ns = c5 - c4
            self.stats.record(late, {"decode": c1 - c0, "estimate": c2 - c1, "control": c3 - c2, "send": c4 - c3,
                                     "log": tr.log_prev_ns})
        tr.last_cmd = cmd
        tr.states.append(state)
        if truth is not None:
            tr.truths.append(truth)
        tr.refs.append(ref)
        tr.cmds.append(cmd)
        tr.js.append(j)
        if self._tap is not None:
            self._tap.tick(state)

    def _landing_mission(self, s: State, to_z: float) -> tuple[Mission, float]:
        """A descent from the current position ``s`` to ``to_z`` at ``landing_speed_m_s``, and the z offset
        to add to its references (the mission lands at 0: it is flown relative to ``to_z``)."""
        height = max(s.z - to_z, 1e-3)
        duration = max(height / self.config.flight.landing_speed_m_s, self.ts)
        return Mission([PhaseConfig("takeoff", self.ts, z_m=height), PhaseConfig("land", duration)],
                       start=(s.x, s.y, height)), to_z

    # ------------------------------------------------------------------ after the loop
    def _end(self, tr: _Track, reason: str, wall_s: float) -> FlightResult:
        ctx, e, session = self.ctx, self.config.experiment, self.session
        end_state = session.estimate(0.0, None)
        end_truth = session.truth()
        t_end = ctx.clock.now_ns()
        if tr.cmds:
            ctx.recorder.flight_end(t_end, end_state, tr.refs[-1])
        if tr.descent and reason == "completed":
            ctx.event("phase", "on the ground" if session.landed() else
                      f"not on the ground {TOUCHDOWN_WAIT_S:g} s after the descent")
        try:
            session.finish(reason)
        except Exception as exc:  # noqa: BLE001 - the landing itself failed: the vehicle's own failsafes are left
            ctx.event("failsafe", f"landing failed ({type(exc).__name__}: {exc}); the vehicle's own failsafe "
                                  "must bring it down", traceback=traceback.format_exc())
            session.abandon()
        record, metrics = self._metrics(tr, end_truth if end_truth is not None else end_state)
        n_flown = len(tr.cmds)
        ctx.event("flight_end", f"{self.controller_name}: {reason} after {n_flown * e.ts_s:.2f} s", exit_reason=reason)
        loop = self.stats.summary() if self.stats is not None else {"ticks": n_flown}
        loop["wall_s"] = wall_s
        loop["realtime_ratio"] = n_flown * e.ts_s / wall_s if wall_s > 0 else 0.0
        loop.update(session.loop_summary())
        loop["flown_s"] = n_flown * e.ts_s  # with a descent flown after the mission
        rec = ctx.recorder
        return FlightResult(self.controller_name, self.config.source, reason, min(n_flown, self.mission_steps) * e.ts_s,
                            metrics, loop, ctx.events, session.summary(), record,
                            None if rec.path is None else str(rec.path), experiment=e.name)

    def _metrics(self, tr: _Track, closing: State) -> tuple[FlightRecord | None, dict]:
        if not tr.cmds:
            return None, {}
        e = self.config.experiment
        n = min(len(tr.cmds), self.mission_steps)  # a descent flown after the mission is logged, not measured
        states = tr.truths if tr.truths else tr.states
        states.append(closing)
        tr.refs.append(self._closing_reference(tr, n))
        record = FlightRecord(e.ts_s, np.array(states[:n + 1], float), np.array(tr.refs[:n + 1], float),
                              np.array(tr.cmds[:n], float), np.array(tr.js[:n], dtype=np.int64))
        try:
            metrics = flight_metrics(record, self.config, self.mission, self.cost)
        except (ValueError, FloatingPointError) as exc:
            self.ctx.event("warning", f"metrics not computed: {exc}")
            metrics = {}
        self.ctx.recorder.flight_metrics(self.ctx.now_ns(), metrics)
        if self._tap is not None:
            self._tap.finish(metrics)
        return record, metrics

    def _closing_reference(self, tr: _Track, n: int) -> State:
        """The reference after the last one flown (it closes the record when the flight ended with the
        mission; see ``close_at_end_time``)."""
        if not self.close_at_end_time or tr.override is not None:
            return tr.refs[-1]
        r = self.mission.reference(n * self.ts)
        ox, oy, oz = tr.origin
        return r if ox == oy == oz == 0.0 else r._replace(x=r.x + ox, y=r.y + oy, z=r.z + oz)
