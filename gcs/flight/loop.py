"""The vehicle-independent part of ``gcs fly``: the 100 Hz mission loop, failsafes, events, log, summary.

:class:`FlightLoop` flies a config's mission with one controller on one vehicle.
What differs between vehicles — the link, telemetry decoding, preflight, the output
message, how the flight ends — is in a subclass: :class:`gcs.flight.fly.Flight`
(a MAVLink autopilot) and :class:`gcs.flight.rig.RigFlight` (the 4-DOF rig).  The
loop calls these hooks:

``_pump() -> int``
    drain the link into the estimator (never blocks);
``_fresh(now_ns, stale_s) -> bool``
    telemetry newer than ``stale_s``;
``_control_lost(t_s) -> str | None``
    why the vehicle is no longer ours to steer (disarmed, another mode, cut off), or None;
``_send_command(state, cmd)``
    the limited command to the vehicle;
``_housekeeping(k)``
    once a second: heartbeats, round-trip probes;
``_finish(reason)``
    after the loop: land and disarm (or wait for the vehicle to), as ``reason`` asks;
``_landed() -> bool``
    for vehicles that do not land themselves (``lands_itself = False``): on the ground;
``_link_summary() -> dict``
    link counters for the summary.

Each tick runs on absolute deadlines of the injected clock (no drift): drain the
telemetry, predict the estimate, failsafes and interrupts, reference, controller,
safety envelope, send, record.  In lockstep the clock is :class:`VehicleClock`, the
vehicle's own time.

Failsafes and exit codes (also in the summary as ``exit_reason``):

====  =================  ==========================================================
code  exit_reason        what happened
====  =================  ==========================================================
0     completed          mission flown, landed, disarmed
3     telemetry_lost     telemetry older than ``telemetry_stale_s``: safe descent
4     geofence           geofence or ceiling breached: landing
5     interrupted        Ctrl-C / SIGTERM: controlled descent, landed, disarmed
6     link_error         no heartbeat, port cannot be opened, link failed before flight
7     preflight_refused  link budget, stale telemetry, battery, mode or arming refused
8     immediate_land     a second Ctrl-C: land at once
9     vehicle_took_over  the vehicle left our control (disarmed, another mode, the rig's
                         cut-off): setpoints stop, the vehicle is left to itself
10    unsafe_command     a non-finite or out-of-limit estimate or command was caught
                         (never sent): a safe level command, then landing
11    internal_error     an exception in the ground station while flying: landing
12    telemetry_slow     the streams the controller flies on stayed too slow (after
                         asking for them again): landing
====  =================  ==========================================================

Whatever ends the flight, the vehicle is landed and disarmed (or left to the pilot, 9),
the parameters changed for the flight are restored and the log is finished.
"""

from __future__ import annotations

import math
import signal
import threading
import time
import traceback
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from gcs.config import Config, PhaseConfig
from gcs.control import FiniteHorizonController, make_controller, model_params
from gcs.control.base import horizon_mode
from gcs.errors import GcsError
from gcs.estimate import StateEstimator
from quadrotor.clock import Clock
from gcs.flight.recorder import FlightRecorder
from gcs.log.flightlog import StageCost
from gcs.flight.safety import EnvelopeLimits, SafetyEnvelope
from gcs.flight.stats import LoopStats
from gcs.link.guard import UnsafeCommand
from gcs.link.mavlink import LinkError
from gcs.metrics import FlightRecord, controller_cost, flight_metrics
from gcs.mission import Mission
from quadrotor.state import Command, State

__all__ = ["FlightLoop", "FlightResult", "VehicleClock", "Interrupts", "EXIT_CODES", "PreflightRefused"]

EXIT_CODES = {"completed": 0, "telemetry_lost": 3, "geofence": 4, "interrupted": 5, "link_error": 6,
              "preflight_refused": 7, "immediate_land": 8, "vehicle_took_over": 9, "unsafe_command": 10,
              "internal_error": 11, "telemetry_slow": 12}

#: After the descent of a vehicle that does not land itself: how long to wait for touchdown [s].
TOUCHDOWN_WAIT_S = 5.0


class PreflightRefused(GcsError):
    """A preflight check failed; the vehicle was not armed."""

    exit_code = 7


@dataclass
class FlightResult:
    """End-of-flight summary (see :meth:`to_json`)."""

    controller: str
    config: str
    exit_reason: str
    duration_s: float
    metrics: dict
    loop: dict
    events: list = field(default_factory=list)
    link: dict = field(default_factory=dict)
    record: FlightRecord | None = None
    log_path: str | None = None

    @property
    def exit_code(self) -> int:
        return EXIT_CODES[self.exit_reason]

    def to_json(self) -> dict:
        return {"controller": self.controller, "config": self.config, "exit_reason": self.exit_reason,
                "exit_code": self.exit_code, "duration_s": self.duration_s, "metrics": self.metrics,
                "loop": self.loop, "events": self.events, "link": self.link, "log": self.log_path}


class VehicleClock:
    """Lockstep clock: the vehicle's own time (the time stamps of its telemetry).

    Parameters
    ----------
    vehicle_time_ns : callable () -> int
        The newest vehicle time stamp received [ns].
    pump : callable (wait_s)
        Receive from the link, waiting at most ``wait_s`` when nothing is there.
    max_wait_s : float
        Wall time to wait for a step's telemetry before giving up on it.
    lost_wait_s : float
        The same after a step whose telemetry never came, until telemetry comes again.

    After :meth:`mark_sent`, ``sleep_until_ns`` pumps the link until telemetry newer
    than the command has arrived (the vehicle steps once per command; an absolute time
    would never be reached after a lost frame).  Wall time enters only when that telemetry
    does not come: after ``max_wait_s`` (long enough that a simulator starved of CPU is
    waited for, so the same seed gives the same flight) the clock moves to the deadline
    anyway, and while nothing comes back each step waits only ``lost_wait_s`` — a silent
    vehicle still ages the telemetry quickly and trips the failsafe.  :attr:`timeouts`
    counts the steps given up on (a flight with none did not depend on wall time).
    """

    def __init__(self, vehicle_time_ns: Callable[[], int], pump: Callable[[float], None],
                 max_wait_s: float = 0.5, lost_wait_s: float = 0.05) -> None:
        self.vehicle_time_ns = vehicle_time_ns
        self.pump = pump
        self.max_wait_s = max_wait_s
        self.lost_wait_s = lost_wait_s
        self._virtual_ns = 0
        self._sent_ns: int | None = None
        self._lost = False
        self.timeouts = 0

    def now_ns(self) -> int:
        return max(self.vehicle_time_ns(), self._virtual_ns)

    def mark_sent(self) -> None:
        """A command went out: the next tick waits for telemetry newer than now."""
        self._sent_ns = self.vehicle_time_ns()

    def sleep_until_ns(self, deadline_ns: int) -> None:
        sent = self._sent_ns
        end = time.monotonic() + (self.lost_wait_s if self._lost else self.max_wait_s)
        while (self.vehicle_time_ns() <= sent) if sent is not None else (self.now_ns() < deadline_ns):
            remaining = end - time.monotonic()
            if remaining <= 0:
                self.timeouts += 1
                self._lost = True
                break
            self.pump(min(remaining, 0.005))
        else:
            self._lost = False
        self._virtual_ns = max(self._virtual_ns, deadline_ns)


class Interrupts:
    """SIGINT/SIGTERM -> a count (first: controlled landing, second: immediate landing)."""

    def __init__(self) -> None:
        self.count = 0
        self._old: dict = {}

    def __enter__(self) -> "Interrupts":
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum, frame) -> None:
        self.count += 1

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)


class FlightLoop:
    """The mission loop of one flight of ``controller`` on ``config`` (subclassed per vehicle).

    Parameters
    ----------
    config : Config
    controller : str
        One of :data:`gcs.control.CONTROLLERS`.
    estimator : StateEstimator
        Fed by the subclass's telemetry.
    clock : Clock or None
        The loop's clock in real time; None = lockstep (the subclass sets :attr:`clock`
        to a :class:`VehicleClock` of its vehicle).
    console : callable (str) or None
        Where the pilot's lines go.
    live_period_s : float
        Period of the live altitude/error line [s].
    interrupts : Interrupts or None
    recorder : FlightRecorder or None
        The flight log (None: no log).
    """

    #: The vehicle lands itself once told to (MAVLink LAND); False: the loop flies the descent
    #: to the ground and :meth:`_finish` disarms.
    lands_itself = True
    #: What the vehicle leaves when it stops taking our setpoints (for the failsafe message).
    control_name = "ground-station control"

    def __init__(self, config: Config, controller: str, estimator: StateEstimator, clock: Clock | None, *,
                 console: Callable[[str], None] | None = None, live_period_s: float = 0.5,
                 interrupts: Interrupts | None = None, recorder: FlightRecorder | None = None) -> None:
        self.config = config
        self.controller_name = controller
        self.flight_cfg = config.flight
        self.console = console or (lambda s: None)
        self.live_period_s = live_period_s
        self.events: list[dict] = []
        self.interrupts = interrupts or Interrupts()
        self.recorder = recorder or FlightRecorder(None)
        if self.recorder.warn is None:
            self.recorder.warn = lambda text: self.event("warning", text)
        e = config.experiment
        self.ts_ns = int(round(e.ts_s * 1e9))
        self.model = model_params(config)
        self.estimator = estimator
        self.lockstep = clock is None
        self.clock: Clock = clock  # type: ignore[assignment]  # the subclass sets the lockstep clock
        self.stats = LoopStats(self.ts_ns)
        fc = config.flight
        self.envelope = SafetyEnvelope(EnvelopeLimits(
            max_thrust_n=config.vehicle.max_thrust_n, max_angular_accel_rad_s2=config.vehicle.max_angular_accel_rad_s2,
            max_tilt_rad=math.radians(fc.max_tilt_deg), fence_half_width_m=fc.fence_half_width_m,
            ceiling_m=fc.ceiling_m, level_kp=config.pd.kp_phi, level_kd=config.pd.kd_phi))
        self.controller = make_controller(controller, config)
        self._last_cmd: Command | None = None
        self._limit_flags_seen: set[str] = set()

    # ------------------------------------------------------------------ events
    def now_ns(self) -> int:
        return self.clock.now_ns() if self.clock is not None else 0

    def event(self, kind: str, text: str, **fields) -> None:
        """Record (summary and log) and print an event."""
        t = self.now_ns()
        self.events.append({"t_ns": t, "kind": kind, "text": text, **fields})
        self.recorder.event(t, kind, text, **fields)
        self.console(f"[{kind}] {text}")

    # ------------------------------------------------------------------ the link
    # A subclass sets ``self.link`` (``drain()``, ``send(msg)``, ``wait_readable(s)``; raising
    # LinkError) and implements ``_handle(msg)``.
    link: object
    _link_down = False
    _last_rx_wall = 0.0

    def _handle(self, msg) -> None:
        raise NotImplementedError

    def _pump(self) -> int:
        """Drain the link into the telemetry (never blocks); the number of messages."""
        try:
            msgs = self.link.drain()  # type: ignore[attr-defined]
        except LinkError as exc:
            self._link_failed(exc)
            return 0
        for m in msgs:
            self._handle(m)
        if msgs:
            self._last_rx_wall = time.monotonic()
        return len(msgs)

    def _pump_wait(self, wait_s: float) -> None:
        """Pump; when nothing was there, wait up to ``wait_s`` for bytes."""
        if self._pump() == 0:
            self.link.wait_readable(wait_s)  # type: ignore[attr-defined]

    def _link_failed(self, exc: Exception) -> None:
        """A dead link shows as stale telemetry (the failsafe acts); said once."""
        if not self._link_down:
            self._link_down = True
            self.event("warning", f"link failure: {exc}")

    #: Set when the output guard blocked a command: ``(exit_reason, text)``; the loop fails safe.
    fault: tuple[str, str] | None = None
    #: () -> why the vehicle process is gone (a child simulator that exited), or None.
    vehicle_alive: Callable[[], str | None] | None = None

    def _send(self, msg) -> None:
        try:
            self.link.send(msg)  # type: ignore[attr-defined]
        except UnsafeCommand as exc:
            self._unsafe(str(exc))
        except LinkError as exc:
            self._link_failed(exc)

    def _unsafe(self, why: str) -> None:
        """A command was blocked before the wire: send the safe one instead, and fail safe (once)."""
        first = self.fault is None
        if first:
            self.fault = ("unsafe_command", why)
            self.event("failsafe", f"output guard blocked a command ({why}): safe level command, landing")
        try:
            self.link.send(self._safe_command())  # type: ignore[attr-defined]
        except (UnsafeCommand, LinkError) as exc:
            if first:
                self.event("warning", f"the safe command could not be sent either: {exc}")

    def _safe_command(self):
        """A level command below hover thrust for this vehicle (what a blocked command is replaced by)."""
        raise NotImplementedError

    def _vehicle_gone(self) -> str | None:
        if self.vehicle_alive is None:
            return None
        return self.vehicle_alive()

    # ------------------------------------------------------------------ hooks

    def _fresh(self, now_ns: int, stale_s: float) -> bool:
        raise NotImplementedError

    def _control_lost(self, t_s: float) -> str | None:
        raise NotImplementedError

    def _send_command(self, state: State, cmd: Command) -> None:
        raise NotImplementedError

    def _housekeeping(self, k: int) -> None:
        """Once a second during the mission (nothing by default)."""

    def _finish(self, reason: str) -> None:
        raise NotImplementedError

    def _landed(self) -> bool:
        return False

    def _abandon(self) -> None:
        """The last resort when landing raised: whatever gets the vehicle's own failsafe to land it."""

    def _health(self, now_ns: int) -> tuple[str, str] | None:
        """Once a tick: a failsafe ``(exit_reason, text)`` the vehicle's link calls for (slow streams), or None."""
        return None

    def _mission_origin(self, state: State) -> tuple[float, float, float]:
        """Where the mission's (0, 0, 0) is: the takeoff point (a real autopilot's local origin need not
        be where the vehicle stands)."""
        return (state.x, state.y, state.z)

    def _link_summary(self) -> dict:
        return {}

    def restore_params(self) -> None:
        """Put back what was changed on the vehicle for the flight (nothing by default)."""

    def emergency_land(self) -> None:
        """Land from wherever the flight stands (an exception escaped the flight): the usual landing."""
        self._finish("internal_error")

    # ------------------------------------------------------------------ the mission
    def _landing_mission(self, from_z: float, to_z: float) -> tuple[Mission, float]:
        """A descent from the current position to ``to_z`` at ``landing_speed_m_s``, and the z offset
        to add to its references (the mission lands at 0: it is flown relative to ``to_z``)."""
        ts = self.config.experiment.ts_s
        height = max(from_z - to_z, 1e-3)
        duration = max(height / self.flight_cfg.landing_speed_m_s, ts)
        s = self.estimator.state()
        return Mission([PhaseConfig("takeoff", ts, z_m=height), PhaseConfig("land", duration)],
                       start=(s.x, s.y, height)), to_z

    def run_mission(self) -> FlightResult:
        """Fly the mission (preflight must have passed) and land; returns the summary."""
        e = self.config.experiment
        mission = Mission(self.config.mission, zero_velocity=e.zero_velocity_reference)
        override: Mission | None = None
        override_k0 = 0
        override_dz = 0.0
        horizon = self.controller if isinstance(self.controller, FiniteHorizonController) else None
        h_steps = horizon.horizon_steps if horizon is not None else None
        h_after = horizon.after if horizon is not None else None
        states, refs, cmds, js = [], [], [], []
        stale_s = self.flight_cfg.telemetry_stale_s
        reason = "completed"
        ts_ns = self.ts_ns
        rec = self.recorder
        t0 = self.clock.now_ns()
        # The mission is flown relative to where the vehicle stands at its start (the local
        # origin of a real autopilot need not be the takeoff point).
        origin = self._mission_origin(self.estimator.state())
        self.envelope.origin = origin
        cost = controller_cost(self.controller_name, self.config)
        mission_steps = int(round(mission.duration_s / e.ts_s))
        rec.flight_start(t0, controller=self.controller_name, experiment=e.name, ts_s=e.ts_s, steps=mission_steps,
                         cost=StageCost.spec_of(cost, self.model.mass_kg, self.model.gravity_m_s2) if cost else None,
                         origin_m=list(origin))
        self.event("phase", f"takeoff point (x {origin[0]:.2f}, y {origin[1]:.2f}, z {origin[2]:.2f}) m")
        next_live = 0.0
        phase_idx = -1
        k = 0
        handled_interrupts = 0
        descent = False  # the end-of-mission descent of a vehicle that does not land itself
        self.event("phase", f"mission start: {len(self.config.mission)} phases, {mission.duration_s:g} s")
        wall0 = time.perf_counter()
        log_prev_ns = 0
        try:
            while True:
                deadline = t0 + k * ts_ns
                self.clock.sleep_until_ns(deadline)
                wake = self.clock.now_ns()
                late = wake - deadline
                if late >= ts_ns and not self.lockstep:
                    self.stats.skipped_ticks += int(late // ts_ns)
                c0 = time.perf_counter_ns()
                self._pump()
                c1 = time.perf_counter_ns()
                self.estimator.predict(e.ts_s, self._last_cmd)
                state = self.estimator.state()
                c2 = time.perf_counter_ns()
                t = k * e.ts_s
                # --- failsafes and interrupts
                gone = self._vehicle_gone() if k % 10 == 0 else None
                if gone is not None:
                    reason = "link_error"
                    self.event("failsafe", f"{gone} at t = {t:.2f} s")
                    break
                if self.fault is not None:
                    reason = self.fault[0]
                    break
                if not self._fresh(wake, stale_s):
                    reason = "telemetry_lost"
                    self.event("failsafe", f"telemetry stale for more than {stale_s:g} s at t = {t:.2f} s: landing")
                    break
                health = self._health(wake)
                if health is not None:
                    reason = health[0]
                    self.event("failsafe", f"{health[1]} at t = {t:.2f} s: landing")
                    break
                if not all(math.isfinite(v) for v in state):
                    reason = "unsafe_command"
                    self.event("failsafe", f"the state estimate is not finite at t = {t:.2f} s: landing")
                    break
                breach = self.envelope.breaches(state)
                if breach:
                    reason = "geofence"
                    self.event("failsafe", f"{', '.join(sorted(breach))} breached at t = {t:.2f} s "
                                           f"(x {state.x:.2f}, y {state.y:.2f}, z {state.z:.2f} m): landing")
                    break
                lost = self._control_lost(t)
                if lost is not None:
                    reason = "vehicle_took_over"
                    self.event("failsafe", f"the vehicle left {self.control_name} at t = {t:.2f} s ({lost}): stopping setpoints")
                    break
                if self.interrupts.count > handled_interrupts:
                    handled_interrupts = self.interrupts.count
                    if handled_interrupts >= 2:
                        reason = "immediate_land"
                        self.event("failsafe", "second interrupt: landing now")
                        break
                    reason = "interrupted"
                    override, override_dz = self._landing_mission(state.z, origin[2])
                    override_k0 = k
                    self.event("interrupt", f"interrupted at t = {t:.2f} s: controlled descent from z = {state.z:.2f} m "
                                            f"at {self.flight_cfg.landing_speed_m_s:g} m/s")
                if override is None and t >= mission.duration_s:
                    if self.lands_itself:
                        break
                    descent = True
                    override, override_dz = self._landing_mission(state.z, origin[2])
                    override_k0 = k
                    self.event("phase", f"mission over at t = {t:.2f} s: descent from z = {state.z:.2f} m "
                                        f"at {self.flight_cfg.landing_speed_m_s:g} m/s")
                if override is not None:
                    tm = (k - override_k0) * e.ts_s
                    if tm >= override.duration_s and (
                            self.lands_itself or self._landed() or tm >= override.duration_s + TOUCHDOWN_WAIT_S):
                        break
                    r = override.reference(min(tm, override.duration_s))  # x, y from the estimate: absolute
                    ref = r._replace(z=r.z + override_dz)
                else:
                    seg = mission.segment_at(t)
                    if seg is not None and seg.index != phase_idx:
                        phase_idx = seg.index
                        self.event("phase", f"{seg.phase.kind} ({seg.phase.duration_s:g} s) at t = {t:.2f} s",
                                   phase=seg.phase.kind, index=seg.index)
                    r = mission.reference(t)
                    ref = r._replace(x=r.x + origin[0], y=r.y + origin[1], z=r.z + origin[2])
                # --- control, envelope, output
                raw = self.controller.step(k, state, ref)
                cmd, flags = self.envelope.apply(state, raw)
                if "non-finite" in flags:
                    reason = "unsafe_command"
                    self.event("failsafe", f"{self.controller_name} commanded a non-finite value at t = {t:.2f} s "
                                           f"({tuple(raw)}): not sent, landing")
                    break
                for f in flags - self._limit_flags_seen:
                    self.event("warning", f"{f} limit acting at t = {t:.2f} s")
                self._limit_flags_seen |= flags
                c3 = time.perf_counter_ns()
                self._send_command(state, cmd)
                if isinstance(self.clock, VehicleClock):
                    self.clock.mark_sent()
                if self.fault is not None:
                    reason = self.fault[0]
                    break
                c4 = time.perf_counter_ns()
                j = (horizon.last_steps_to_go or 0) if horizon is not None else 0
                if rec.sink is not None:
                    rec.tick(wake, k, state, ref, raw, cmd, j, horizon_mode(k, h_steps, h_after),
                             (late / 1e9, (c4 - c0) / 1e9, late >= ts_ns, (c1 - c0) / 1e9, (c2 - c1) / 1e9,
                              (c3 - c2) / 1e9, (c4 - c3) / 1e9, log_prev_ns / 1e9))
                c5 = time.perf_counter_ns()
                log_prev_ns = c5 - c4
                self.stats.record(late, {"decode": c1 - c0, "estimate": c2 - c1, "control": c3 - c2, "send": c4 - c3,
                                         "log": log_prev_ns})
                self._last_cmd = cmd
                states.append(state)
                refs.append(ref)
                cmds.append(cmd)
                js.append(j)
                if k % 100 == 0:  # once a second: the ground station is alive, and how late is the link
                    self._housekeeping(k)
                if t >= next_live:
                    next_live = t + self.live_period_s
                    self.console(f"t {t:7.2f} s  z {state.z:6.3f} m  ref {ref.z:6.3f} m  err {ref.z - state.z:+.3f} m  "
                                 f"xy ({state.x:+.2f}, {state.y:+.2f}) m  thrust {cmd.thrust_n:5.2f} N")
                k += 1
                if not self.lockstep and late >= ts_ns:
                    k += int(late // ts_ns)
        except Exception as exc:  # noqa: BLE001 - any failure while flying must end in a landing, never an abandoned vehicle
            reason = "internal_error"
            self.event("failsafe", f"internal error at t = {k * e.ts_s:.2f} s ({type(exc).__name__}: {exc}): landing",
                       traceback=traceback.format_exc())
        wall_s = time.perf_counter() - wall0
        end_state = self.estimator.state()
        t_end = self.clock.now_ns()
        if cmds:
            rec.flight_end(t_end, end_state, refs[-1])
        if descent and reason == "completed":
            self.event("phase", "on the ground" if self._landed() else
                       f"not on the ground {TOUCHDOWN_WAIT_S:g} s after the descent")
        try:
            self._finish(reason)
        except Exception as exc:  # noqa: BLE001 - the landing itself failed: the vehicle's own failsafes are left
            self.event("failsafe", f"landing failed ({type(exc).__name__}: {exc}); the vehicle's own failsafe "
                                   "must bring it down", traceback=traceback.format_exc())
            self._abandon()
        record = None
        metrics: dict = {}
        if cmds:
            states.append(end_state)
            refs.append(refs[-1])
            n = min(len(cmds), mission_steps)  # a descent flown after the mission is logged, not measured
            record = FlightRecord(e.ts_s, np.array(states[:n + 1], float), np.array(refs[:n + 1], float),
                                  np.array(cmds[:n], float), np.array(js[:n], dtype=np.int64))
            try:
                metrics = flight_metrics(record, self.config, mission, cost)
            except (ValueError, FloatingPointError) as exc:
                self.event("warning", f"metrics not computed: {exc}")
                metrics = {}
            rec.flight_metrics(self.now_ns(), metrics)
        self.event("flight_end", f"{self.controller_name}: {reason} after {len(cmds) * e.ts_s:.2f} s",
                   exit_reason=reason)
        loop = self.stats.summary()
        loop["wall_s"] = wall_s
        loop["realtime_ratio"] = len(cmds) * e.ts_s / wall_s if wall_s > 0 else 0.0
        if isinstance(self.clock, VehicleClock):
            loop["telemetry_timeouts"] = self.clock.timeouts
        loop["flown_s"] = len(cmds) * e.ts_s  # with a descent flown after the mission
        return FlightResult(self.controller_name, self.config.source, reason,
                            min(len(cmds), mission_steps) * e.ts_s, metrics,
                            loop, self.events, self._link_summary(), record,
                            None if rec.path is None else str(rec.path))
