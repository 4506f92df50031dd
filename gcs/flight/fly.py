"""``gcs fly``: preflight, arming, the 100 Hz mission loop, landing and failsafes.

Sequence::

    heartbeat -> streams requested -> parameters (GUID_OPTIONS bit 3, MOT_THST_HOVER,
    ATC_ANG_*_P) -> telemetry fresh, battery -> GUIDED_NOGPS -> setpoints streamed
    -> arm -> mission phases at 100 Hz -> LAND -> disarmed

Each tick (absolute deadlines on the injected clock, so no drift): drain all
telemetry, predict and correct the estimate, reference from the mission,
controller step, safety envelope, output adapter, send.  In lockstep the same
loop runs on :class:`VehicleClock`, whose time is the vehicle's own.

Failsafes and exit codes (also in the summary as ``exit_reason``):

====  =================  ==========================================================
code  exit_reason        what happened
====  =================  ==========================================================
0     completed          mission flown, landed, disarmed
3     telemetry_lost     telemetry older than ``telemetry_stale_s``: LAND, level setpoints
4     geofence           geofence or ceiling breached: LAND
5     interrupted        Ctrl-C / SIGTERM: controlled descent, LAND, disarmed
6     link_error         no heartbeat, port cannot be opened, link failed before flight
7     preflight_refused  link budget, stale telemetry, battery, mode or arming refused
8     immediate_land     a second Ctrl-C: LAND at once
9     vehicle_took_over  the vehicle disarmed or left GUIDED(_NOGPS) (pilot, onboard
                         failsafe): setpoints stop, the vehicle is left to its mode
====  =================  ==========================================================
"""

from __future__ import annotations

import math
import signal
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.config import Config, PhaseConfig
from gcs.control import FiniteHorizonController, make_controller, model_params
from gcs.errors import GcsError
from gcs.estimate import StateEstimator
from gcs.flight.clock import Clock
from gcs.flight.output import OutputAdapter, OutputModel
from gcs.flight.safety import EnvelopeLimits, SafetyEnvelope
from gcs.flight.stats import LoopStats
from gcs.flight.telemetry import Telemetry
from gcs.link.mavlink import LinkError, MavlinkLink
from gcs.metrics import FlightRecord, controller_cost, flight_metrics
from gcs.mission import Mission
from gcs.model import Command, State

__all__ = ["Flight", "FlightResult", "VehicleClock", "EXIT_CODES", "PreflightRefused"]

EXIT_CODES = {"completed": 0, "telemetry_lost": 3, "geofence": 4, "interrupted": 5, "link_error": 6,
              "preflight_refused": 7, "immediate_land": 8, "vehicle_took_over": 9}


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

    @property
    def exit_code(self) -> int:
        return EXIT_CODES[self.exit_reason]

    def to_json(self) -> dict:
        return {"controller": self.controller, "config": self.config, "exit_reason": self.exit_reason,
                "exit_code": self.exit_code, "duration_s": self.duration_s, "metrics": self.metrics,
                "loop": self.loop, "events": self.events, "link": self.link}


class VehicleClock:
    """Lockstep clock: the vehicle's time (``time_boot_ms`` of its telemetry).

    ``sleep_until_ns`` pumps the link until telemetry stamped at or after the
    deadline has arrived; if none comes within ``max_wait_s`` of wall time the
    clock moves to the deadline anyway, so a silent vehicle still ages the
    telemetry and trips the failsafe.
    """

    def __init__(self, telemetry: Telemetry, pump: Callable[[float], None], max_wait_s: float = 0.05) -> None:
        self.telemetry = telemetry
        self.pump = pump
        self.max_wait_s = max_wait_s
        self._virtual_ns = 0
        self.timeouts = 0

    def now_ns(self) -> int:
        return max(self.telemetry.status.time_boot_ms * 1_000_000, self._virtual_ns)

    def mark_sent(self) -> None:
        """A command went out: the next tick waits for telemetry newer than now."""
        self._sent_ms = self.telemetry.status.time_boot_ms

    def sleep_until_ns(self, deadline_ns: int) -> None:
        # The vehicle steps once per command: wait for the telemetry of that step (newer than
        # when the command left), not for an absolute time a lost frame would never reach.
        sent = getattr(self, "_sent_ms", None)
        end = time.monotonic() + self.max_wait_s
        while (self.telemetry.status.time_boot_ms <= sent) if sent is not None else (self.now_ns() < deadline_ns):
            remaining = end - time.monotonic()
            if remaining <= 0:
                self.timeouts += 1
                break
            self.pump(min(remaining, 0.005))
        self._virtual_ns = max(self._virtual_ns, deadline_ns)


class _Interrupts:
    """SIGINT/SIGTERM -> flags (first: controlled landing, second: immediate LAND)."""

    def __init__(self) -> None:
        self.count = 0
        self._old: dict = {}

    def __enter__(self) -> "_Interrupts":
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum, frame) -> None:
        self.count += 1

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)


class Flight:
    """One flight of ``controller`` on ``config``'s mission over ``link``.

    Parameters
    ----------
    config : Config
    controller : str
    link : MavlinkLink
    clock : Clock or None
        The loop's clock in real time (None = lockstep on :class:`VehicleClock`).
    console : callable (str) or None
        Where the pilot's lines go.
    live_period_s : float
        Period of the live altitude/error line.
    """

    def __init__(self, config: Config, controller: str, link: MavlinkLink, clock: Clock | None, *,
                 output: str | None = None, console: Callable[[str], None] | None = None,
                 live_period_s: float = 0.5, interrupts: _Interrupts | None = None) -> None:
        self.config = config
        self.controller_name = controller
        self.link = link
        self.flight_cfg = config.flight
        self.output_kind = output or config.flight.output
        self.console = console or (lambda s: None)
        self.live_period_s = live_period_s
        self.events: list[dict] = []
        self.interrupts = interrupts or _Interrupts()
        e = config.experiment
        self.ts_ns = int(round(e.ts_s * 1e9))
        self.model = model_params(config)
        fc = config.flight
        self.estimator = StateEstimator(e.ts_s, self.model, (fc.position_std_m,) * 3, config.estimator.accel_noise_std_m_s2,
                                        ground_z_m=None)
        self.telemetry = Telemetry(self.estimator, (fc.position_std_m ** 2,) * 3, (fc.velocity_std_m_s ** 2,) * 3,
                                   on_event=self._vehicle_event, target_component=link.target_component)
        self._restore: dict[str, float] = {}
        self._link_down = False
        self.lockstep = clock is None
        self.clock: Clock = clock if clock is not None else VehicleClock(self.telemetry, self._pump_wait)
        self.stats = LoopStats(self.ts_ns)
        self.envelope = SafetyEnvelope(EnvelopeLimits(
            max_thrust_n=config.vehicle.max_thrust_n, max_angular_accel_rad_s2=config.vehicle.max_angular_accel_rad_s2,
            max_tilt_rad=math.radians(fc.max_tilt_deg), fence_half_width_m=fc.fence_half_width_m,
            ceiling_m=fc.ceiling_m, level_kp=config.pd.kp_phi, level_kd=config.pd.kd_phi))
        self.controller = make_controller(controller, config)
        self.adapter: OutputAdapter | None = None
        self._last_cmd: Command | None = None
        self._last_rx_wall = time.monotonic()
        self._limit_flags_seen: set[str] = set()

    # ------------------------------------------------------------------ events and I/O
    def event(self, kind: str, text: str) -> None:
        """Record and print an event."""
        self.events.append({"t_ns": self.clock.now_ns(), "kind": kind, "text": text})
        self.console(f"[{kind}] {text}")

    def _vehicle_event(self, kind: str, text: str) -> None:
        self.event(kind, text)

    def _pump(self) -> int:
        """Drain the link into the telemetry; returns the number of messages."""
        now = self.clock.now_ns() if not self.lockstep else 0
        try:
            msgs = self.link.drain()
        except LinkError as exc:
            self._link_failed(exc)
            return 0
        for m in msgs:
            self.telemetry.handle(m, now if not self.lockstep else self.clock.now_ns())
        if msgs:
            self._last_rx_wall = time.monotonic()
        return len(msgs)

    def _link_failed(self, exc: Exception) -> None:
        """A dead link shows as stale telemetry (the failsafe acts); said once."""
        if not self._link_down:
            self._link_down = True
            self.event("warning", f"link failure: {exc}")

    def _send(self, msg) -> None:
        try:
            self.link.send(msg)
        except LinkError as exc:
            self._link_failed(exc)

    def _pump_wait(self, wait_s: float) -> None:
        if self._pump() == 0:
            self.link.conn.select(wait_s)

    def _wait_for(self, what: str, predicate: Callable[[], bool], timeout_s: float, *, thrust_n: float = 0.0,
                  send: bool = True) -> bool:
        """Pump (and stream level setpoints at ``thrust_n``, which also drive a lockstep vehicle)
        until ``predicate``; ``send=False`` only listens (heartbeats go on)."""
        end = time.monotonic() + timeout_s
        next_hb = time.monotonic()
        while time.monotonic() < end:
            self._pump()
            if predicate():
                return True
            if self.interrupts.count and not self.telemetry.status.armed and what not in ("disarm",):
                return False
            if send:
                self._idle_tick(thrust_n)
            else:
                if time.monotonic() >= next_hb:
                    self.link.send_heartbeat()
                    next_hb += 1.0
                if self.lockstep and self.adapter is not None:
                    # A lockstep simulator's time moves only with targets: a THROTTLE_IGNORE target
                    # is refused by the autopilot but moves the clock (lockstep only).
                    q = (1.0, 0.0, 0.0, 0.0)
                    self._send(self.link.mav.set_attitude_target_encode(
                        self.telemetry.status.time_boot_ms, self.link.target_system, self.link.target_component,
                        64 | 7, q, 0.0, 0.0, 0.0, 0.0))
                self.link.conn.select(0.005 if self.lockstep else 0.01)
        return predicate()

    def _idle_tick(self, thrust_n: float) -> None:
        """One level setpoint and one control period of waiting.

        In real time: 10 ms of wall time.  In lockstep the setpoint moves the vehicle one
        period; the next one goes only when its telemetry is back (or after 50 ms), so a
        slow serial link is never flooded with steps it cannot report.
        """
        if self.adapter is None:
            self.link.conn.select(0.01)
            return
        before = self.telemetry.status.time_boot_ms
        self._send_level(thrust_n)
        wait = 0.01
        if self.lockstep:
            # Wait for the step's telemetry, unless the telemetry is gone (failsafe): then keep
            # the vehicle's time moving so that it can land by itself.
            wait = 0.05 if time.monotonic() - self._last_rx_wall < 0.5 else 0.005
        end = time.monotonic() + wait
        while True:
            remaining = end - time.monotonic()
            if remaining <= 0 or (self.lockstep and self.telemetry.status.time_boot_ms > before):
                return
            if self._pump() == 0:
                self.link.conn.select(min(remaining, 0.005))

    def _send_level(self, thrust_n: float) -> None:
        state = self.estimator.state()
        self._send(self.adapter.level(state, thrust_n, self.telemetry.status.time_boot_ms))  # type: ignore[union-attr]

    # ------------------------------------------------------------------ preflight
    def _param(self, name: str, default: float | None) -> float:
        """A parameter of the vehicle; ``default=None`` makes it required (refuse without it)."""
        self._check_interrupt()
        try:
            return self.link.param_get(name, timeout_s=1.0, retries=1, on_message=self._handle_now)
        except LinkError:
            if default is None:
                raise PreflightRefused(f"parameter {name} not readable; it is needed to fly") from None
            self.event("warning", f"parameter {name} not readable; assuming {default:g}")
            return default

    def _set_param(self, name: str, value: float, old: float) -> float:
        new = self.link.param_set(name, value, on_message=self._handle_now)
        if new == value:
            self._restore.setdefault(name, old)
        return new

    def restore_params(self) -> None:
        """Put back the parameters changed for the flight (once the vehicle is disarmed)."""
        for name, value in list(self._restore.items()):
            if self.telemetry.status.armed:
                self.event("warning", f"vehicle still armed: {name} left at its flight value")
                continue
            try:
                self.link.param_set(name, value, timeout_s=1.0, retries=1, on_message=self._handle_now)
                self.event("param", f"{name} restored to {value:g}")
                del self._restore[name]
            except LinkError as exc:
                self.event("warning", f"{name} not restored: {exc}")

    def _check_interrupt(self) -> None:
        if self.interrupts.count:
            raise PreflightRefused("interrupted before arming")

    def _timesync(self) -> None:
        self.telemetry.timesync_sent.add(self.link.send_timesync())
        self.link.wait(lambda m: m.get_type() == "TIMESYNC" and self.telemetry.timesync_rtt_ms is not None,
                       1.0, self._handle_now)

    def _handle_now(self, msg) -> None:
        self.telemetry.handle(msg, self.clock.now_ns())

    def preflight(self, budget_ok: bool = True) -> None:
        """Everything before arming; raises :class:`PreflightRefused` or :class:`LinkError`."""
        link, fc = self.link, self.flight_cfg
        hb = link.wait_heartbeat(on_message=self._handle_now)
        self.event("link", f"connected to system {link.target_system} on {link.url} "
                           f"(autopilot {hb.autopilot}, type {hb.type})")
        self._check_interrupt()
        st = self.telemetry.status
        if st.armed:
            raise PreflightRefused(f"the vehicle is already armed (mode {st.mode}); gcs fly starts from a "
                                   "disarmed vehicle on the ground")
        self._timesync()
        rtt = self.telemetry.timesync_rtt_ms
        if rtt is not None:
            self.event("link", f"round trip {rtt:.1f} ms (TIMESYNC)")
            if rtt / 1000.0 > fc.telemetry_stale_s:
                raise PreflightRefused(f"link round trip {rtt:.0f} ms exceeds the telemetry stale timeout "
                                       f"({fc.telemetry_stale_s * 1000:.0f} ms): telemetry would arrive too late "
                                       "to control (lower the stream rates or raise the baud rate)")
        else:
            self.event("warning", "no TIMESYNC reply: link latency unknown")
        if not budget_ok:
            raise PreflightRefused("link budget exceeded (see above); use --force-budget to fly anyway")
        rates = {mavlink.MAVLINK_MSG_ID_ATTITUDE: fc.telemetry_rate_hz,
                 mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: fc.telemetry_rate_hz,
                 mavlink.MAVLINK_MSG_ID_SYS_STATUS: 2.0}
        for mid, hz in rates.items():
            res = link.set_message_interval(mid, hz, on_message=self._handle_now)
            if res != mavlink.MAV_RESULT_ACCEPTED:
                self.event("warning", f"stream {mid} at {hz:g} Hz not accepted (MAV_RESULT {res})")
        guid = self._param("GUID_OPTIONS", 0.0)
        if not int(guid) & 8:
            new = self._set_param("GUID_OPTIONS", float(int(guid) | 8), guid)
            if not int(new) & 8:
                raise PreflightRefused("the vehicle did not accept GUID_OPTIONS bit 3 (thrust as thrust)")
            self.event("param", f"GUID_OPTIONS {int(guid)} -> {int(new)} (thrust field is thrust)")
        # Our controllers divide the thrust by cos(roll) cos(pitch) themselves: ArduPilot's angle
        # boost would do it a second time.
        boost = self._param("ATC_ANGLE_BOOST", None)
        if boost:
            new = self._set_param("ATC_ANGLE_BOOST", 0.0, boost)
            if new:
                raise PreflightRefused("the vehicle did not accept ATC_ANGLE_BOOST = 0 (thrust tilt compensation "
                                       "is done by the controller)")
            self.event("param", "ATC_ANGLE_BOOST 1 -> 0 (the controller compensates tilt)")
        hover = self._param("MOT_THST_HOVER", None)
        gains = tuple(self._param(f"ATC_ANG_{ax}_P", 4.5) for ax in ("RLL", "PIT", "YAW"))
        self.adapter = OutputAdapter(OutputModel(
            kind=self.output_kind, mass_kg=self.model.mass_kg, gravity_m_s2=self.model.gravity_m_s2,
            hover_throttle=hover, inertia_kg_m2=fc.inertia_kg_m2, max_torque_nm=fc.max_torque_nm,
            rate_gain_1_s=fc.rate_gain_1_s, angle_gain_1_s=gains, ts_s=self.config.experiment.ts_s),
            link.mav, link.target_system, link.target_component)
        self.event("output", f"{self.output_kind}: hover throttle {hover:.3f}, angle gains {gains}")
        if not self._wait_for("telemetry", lambda: self.telemetry.fresh(self.clock.now_ns(), fc.telemetry_stale_s)
                              and self.estimator.initialised, 5.0):
            raise PreflightRefused("no fresh ATTITUDE and LOCAL_POSITION_NED telemetry within 5 s")
        if fc.min_battery_v > 0:
            self._wait_for("battery", lambda: self.telemetry.status.battery_voltage_v is not None, 2.0)
        volt = self.telemetry.status.battery_voltage_v
        if fc.min_battery_v > 0:
            if volt is None:
                self.event("warning", "no battery voltage reported; battery not checked")
            elif volt < fc.min_battery_v:
                raise PreflightRefused(f"battery {volt:.2f} V below {fc.min_battery_v:g} V")
        self._check_interrupt()
        res = link.set_mode("GUIDED_NOGPS", on_message=self._handle_now)
        if res != mavlink.MAV_RESULT_ACCEPTED:
            raise PreflightRefused(f"mode GUIDED_NOGPS refused (MAV_RESULT {res})")
        self._wait_for("mode", lambda: self.telemetry.status.custom_mode == 20, 3.0)
        # Stream setpoints before arming (0.5 s of idle, level).
        for _ in range(int(round(0.5 / self.config.experiment.ts_s))):
            self._pump()
            self._idle_tick(0.0)
        self._check_interrupt()
        res = link.arm(True, on_message=self._handle_now)
        if res != mavlink.MAV_RESULT_ACCEPTED:
            # The reason comes as STATUSTEXT, before or just after the acknowledgement.
            link.wait(lambda m: m.get_type() == "STATUSTEXT", 0.5, self._handle_now)
            texts = [t for t in self.telemetry.status.statustext if "arm" in t.lower()]
            why = texts[-1] if texts else f"MAV_RESULT {res}"
            raise PreflightRefused(f"arming refused: {why}")
        if not self._wait_for("armed", lambda: self.telemetry.status.armed, 3.0):
            raise PreflightRefused("the vehicle acknowledged arming but does not report armed")

    # ------------------------------------------------------------------ flight
    def _landing_mission(self, from_z: float) -> Mission:
        duration = max(from_z / self.flight_cfg.landing_speed_m_s, self.config.experiment.ts_s)
        s = self.estimator.state()
        return Mission([PhaseConfig("takeoff", self.config.experiment.ts_s, z_m=max(from_z, 1e-3)),
                        PhaseConfig("land", duration)], start=(s.x, s.y, max(from_z, 1e-3)))

    def fly(self) -> FlightResult:
        """Preflight must have passed.  Flies the mission and lands; returns the summary."""
        e = self.config.experiment
        mission = Mission(self.config.mission, zero_velocity=e.zero_velocity_reference)
        override: Mission | None = None
        override_k0 = 0
        horizon = self.controller if isinstance(self.controller, FiniteHorizonController) else None
        states, refs, cmds, js = [], [], [], []
        stale_s = self.flight_cfg.telemetry_stale_s
        reason = "completed"
        ts_ns = self.ts_ns
        t0 = self.clock.now_ns()
        # The mission is flown relative to where the vehicle stands at its start (the local
        # origin of a real autopilot need not be the takeoff point).
        start = self.estimator.state()
        origin = (start.x, start.y, start.z)
        self.envelope.origin = origin
        self.event("phase", f"takeoff point (x {origin[0]:.2f}, y {origin[1]:.2f}, z {origin[2]:.2f}) m")
        next_live = 0.0
        phase_idx = -1
        k = 0
        handled_interrupts = 0
        self.event("phase", f"mission start: {len(self.config.mission)} phases, {mission.duration_s:g} s")
        wall0 = time.perf_counter()
        while True:
            deadline = t0 + k * ts_ns
            self.clock.sleep_until_ns(deadline)
            wake = self.clock.now_ns()
            late = wake - deadline
            if late >= ts_ns and not self.lockstep:
                skip = late // ts_ns
                self.stats.skipped_ticks += int(skip)
            c0 = time.perf_counter_ns()
            self._pump()
            c1 = time.perf_counter_ns()
            self.estimator.predict(e.ts_s, self._last_cmd)
            state = self.estimator.state()
            c2 = time.perf_counter_ns()
            t = k * e.ts_s
            # --- failsafes and interrupts
            if not self.telemetry.fresh(wake, stale_s):
                reason = "telemetry_lost"
                self.event("failsafe", f"telemetry stale for more than {stale_s:g} s at t = {t:.2f} s: LAND")
                break
            breach = self.envelope.breaches(state)
            if breach:
                reason = "geofence"
                self.event("failsafe", f"{', '.join(sorted(breach))} breached at t = {t:.2f} s "
                                       f"(x {state.x:.2f}, y {state.y:.2f}, z {state.z:.2f} m): LAND")
                break
            st = self.telemetry.status
            if not st.armed or st.custom_mode not in (20, 4):
                reason = "vehicle_took_over"
                self.event("failsafe", f"the vehicle left guided control at t = {t:.2f} s "
                                       f"({'disarmed' if not st.armed else 'mode ' + st.mode}): stopping setpoints")
                break
            if self.interrupts.count > handled_interrupts:
                handled_interrupts = self.interrupts.count
                if handled_interrupts >= 2:
                    reason = "immediate_land"
                    self.event("failsafe", "second interrupt: LAND now")
                    break
                reason = "interrupted"
                override = self._landing_mission(state.z)
                override_k0 = k
                self.event("interrupt", f"interrupted at t = {t:.2f} s: controlled descent from z = {state.z:.2f} m "
                                        f"at {self.flight_cfg.landing_speed_m_s:g} m/s")
            if override is not None:
                tm = (k - override_k0) * e.ts_s
                if tm >= override.duration_s:
                    break
                ref = override.reference(tm)  # built from the estimate: already absolute
            else:
                if t >= mission.duration_s:
                    break
                seg = mission.segment_at(t)
                if seg is not None and seg.index != phase_idx:
                    phase_idx = seg.index
                    self.event("phase", f"{seg.phase.kind} ({seg.phase.duration_s:g} s) at t = {t:.2f} s")
                r = mission.reference(t)
                ref = r._replace(x=r.x + origin[0], y=r.y + origin[1], z=r.z + origin[2])
            # --- control, envelope, output
            raw = self.controller.step(k, state, ref)
            cmd, flags = self.envelope.apply(state, raw)
            for f in flags - self._limit_flags_seen:
                self.event("warning", f"{f} limit acting at t = {t:.2f} s")
            self._limit_flags_seen |= flags
            c3 = time.perf_counter_ns()
            fields = self.adapter.fields(state, cmd)  # type: ignore[union-attr]
            self._send(self.adapter.encode(fields, self.telemetry.status.time_boot_ms))  # type: ignore[union-attr]
            if isinstance(self.clock, VehicleClock):
                self.clock.mark_sent()
            c4 = time.perf_counter_ns()
            self.stats.record(late, {"decode": c1 - c0, "estimate": c2 - c1, "control": c3 - c2, "send": c4 - c3})
            self._last_cmd = cmd
            states.append(state)
            refs.append(ref)
            cmds.append(cmd)
            js.append((horizon.last_steps_to_go or 0) if horizon is not None else 0)
            if k % 100 == 0:  # once a second: the ground station is alive, and how late is the link
                try:
                    self.link.send_heartbeat()
                    self.telemetry.timesync_sent.add(self.link.send_timesync())
                except LinkError as exc:
                    self._link_failed(exc)
            if t >= next_live:
                next_live = t + self.live_period_s
                self.console(f"t {t:7.2f} s  z {state.z:6.3f} m  ref {ref.z:6.3f} m  err {ref.z - state.z:+.3f} m  "
                             f"xy ({state.x:+.2f}, {state.y:+.2f}) m  thrust {cmd.thrust_n:5.2f} N")
            k += 1
            if not self.lockstep and late >= ts_ns:
                k += int(late // ts_ns)
        wall_s = time.perf_counter() - wall0
        end_state = self.estimator.state()
        if reason == "vehicle_took_over":
            self._wait_for("disarm", lambda: not self.telemetry.status.armed, self.flight_cfg.land_timeout_s,
                           send=False)
        else:
            self._land(reason)
        record = None
        metrics: dict = {}
        if cmds:
            states.append(end_state)
            refs.append(refs[-1])
            record = FlightRecord(e.ts_s, np.array(states, float), np.array(refs, float), np.array(cmds, float),
                                  np.array(js, dtype=np.int64))
            metrics = flight_metrics(record, self.config, mission, controller_cost(self.controller_name, self.config))
        c = self.link.counters
        loop = self.stats.summary()
        loop["wall_s"] = wall_s
        loop["realtime_ratio"] = len(cmds) * e.ts_s / wall_s if wall_s > 0 else 0.0
        if isinstance(self.clock, VehicleClock):
            loop["telemetry_timeouts"] = self.clock.timeouts
        return FlightResult(self.controller_name, self.config.source, reason, len(cmds) * e.ts_s, metrics,
                            loop, self.events,
                            {"received": c.received, "sent": c.sent, "bad_data": c.bad_data,
                             "other_system": c.other_system, "unsigned_rejected": c.unsigned_rejected,
                             "timesync_rtt_ms": self.telemetry.timesync_rtt_ms,
                             "timesync_rtt_median_ms": (float(np.median(self.telemetry.timesync_samples_ms))
                                                        if self.telemetry.timesync_samples_ms else None)},
                            record)

    def _land(self, reason: str) -> None:
        """LAND mode, level setpoints while waiting, until disarmed (or the timeout).

        With the telemetry gone the acknowledgement cannot come back: LAND is sent once
        without waiting long, and level setpoints keep the vehicle upright (they also keep
        a lockstep simulator's time moving) while it lands on its own.
        """
        quick = reason == "telemetry_lost"
        try:
            res = self.link.command_long(mavlink.MAV_CMD_DO_SET_MODE,
                                         [mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 9],
                                         timeout_s=0.3 if quick else 3.0, retries=0 if quick else 2,
                                         on_message=self._handle_now)
            if res != mavlink.MAV_RESULT_ACCEPTED:
                self.event("warning", f"LAND refused (MAV_RESULT {res})")
        except LinkError as exc:
            self.event("warning", f"LAND not acknowledged: {exc}")
        self.event("phase", "landing (LAND mode)")
        # LAND is sent again twice a second until the vehicle reports it (or while nothing is
        # heard): a lost frame must not leave the vehicle in guided mode.  Should LAND never be
        # taken, 90 % of hover thrust, level, still brings it down gently.
        next_land = [time.monotonic() + 0.5]

        def done() -> bool:
            st = self.telemetry.status
            if st.armed and st.custom_mode != 9 and time.monotonic() >= next_land[0]:
                next_land[0] = time.monotonic() + 0.5
                self._send(self.link.mav.command_long_encode(
                    self.link.target_system, self.link.target_component, mavlink.MAV_CMD_DO_SET_MODE, 0,
                    mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 9, 0, 0, 0, 0, 0))
            return not st.armed or self.interrupts.count >= 3

        landed = self._wait_for("disarm", done, self.flight_cfg.land_timeout_s, thrust_n=0.9 * self.model.hover_thrust_n)
        landed = landed and not self.telemetry.status.armed
        if landed:
            self.event("landed", "landed and disarmed")
        else:
            self.event("warning", f"not disarmed {self.flight_cfg.land_timeout_s:g} s after LAND")
