"""``gcs fly`` on a MAVLink autopilot: preflight, arming, the mission loop, LAND and failsafes.

Sequence::

    heartbeat -> streams requested -> parameters (GUID_OPTIONS bit 3, MOT_THST_HOVER,
    ATC_ANG_*_P) -> telemetry fresh, battery -> GUIDED_NOGPS -> setpoints streamed
    -> arm -> mission phases at 100 Hz -> LAND -> disarmed

The mission loop, the failsafes and the exit codes are :class:`gcs.flight.loop.FlightLoop`'s;
this module is the MAVLink vehicle: the link, telemetry, output adapters, the preflight
and the landing.  Every frame both ways goes to the flight log (``recorder``).
"""

from __future__ import annotations

import math
import time
from typing import Callable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

import numpy as np

from gcs.config import Config
from gcs.control import model_params
from gcs.estimate import StateEstimator
from quadrotor.clock import Clock
from gcs.flight.loop import (EXIT_CODES, FlightLoop, FlightResult, Interrupts, PreflightRefused,  # noqa: F401
                             VehicleClock)
from gcs.flight.output import OutputAdapter, OutputModel
from gcs.flight.recorder import FlightRecorder
from gcs.flight.streams import StreamMonitor
from gcs.flight.telemetry import Telemetry
from gcs.link.guard import GuardLimits, OutputGuard, UnsafeCommand
from gcs.link.mavlink import LinkError, MavlinkLink
from quadrotor.state import Command, State

__all__ = ["Flight", "FlightResult", "VehicleClock", "EXIT_CODES", "PreflightRefused"]

#: Largest body rate a setpoint may carry [rad/s] (the output guard's limit).
MAX_BODY_RATE_RAD_S = 35.0
#: The loop fails safe when a stream the controller flies on stays below this share of its requested rate.
MIN_RATE_FRACTION = 0.25
STREAM_IDS = {"ATTITUDE": mavlink.MAVLINK_MSG_ID_ATTITUDE, "LOCAL_POSITION_NED": mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED}

class Flight(FlightLoop):
    """One flight of ``controller`` on ``config``'s mission over a MAVLink ``link``.

    Parameters
    ----------
    config : Config
    controller : str
    link : MavlinkLink
    clock : Clock or None
        The loop's clock in real time (None = lockstep on :class:`VehicleClock`).
    output : str or None
        Setpoint message (default: the config's ``[flight] output``).
    console : callable (str) or None
        Where the pilot's lines go.
    live_period_s : float
        Period of the live altitude/error line.
    recorder : FlightRecorder or None
        The flight log; every MAVLink frame both ways is logged.
    """

    control_name = "guided control"

    def __init__(self, config: Config, controller: str, link: MavlinkLink, clock: Clock | None, *,
                 output: str | None = None, console: Callable[[str], None] | None = None,
                 live_period_s: float = 0.5, interrupts: Interrupts | None = None,
                 recorder: FlightRecorder | None = None) -> None:
        fc = config.flight
        estimator = StateEstimator(config.experiment.ts_s, model_params(config), (fc.position_std_m,) * 3,
                                   config.estimator.accel_noise_std_m_s2, ground_z_m=None)
        super().__init__(config, controller, estimator, clock, console=console, live_period_s=live_period_s,
                         interrupts=interrupts, recorder=recorder)
        self.link = link
        self.output_kind = output or fc.output
        self.telemetry = Telemetry(estimator, (fc.position_std_m ** 2,) * 3, (fc.velocity_std_m_s ** 2,) * 3,
                                   on_event=self._vehicle_event, target_component=link.target_component)
        self._restore: dict[str, float] = {}
        if clock is None:
            self.clock = VehicleClock(lambda: self.telemetry.status.time_boot_ms * 1_000_000, self._pump_wait)
        if self.recorder.enabled:
            rec = self.recorder
            link.on_frame = lambda direction, msg, accepted=True: rec.mavlink(self.clock.now_ns(), direction, msg,
                                                                              accepted)
        self.adapter: OutputAdapter | None = None
        self._last_rx_wall = time.monotonic()
        self.guard = OutputGuard(GuardLimits(max_body_rate_rad_s=MAX_BODY_RATE_RAD_S))
        link.guard = self.guard
        rate = fc.telemetry_rate_hz
        self.streams = StreamMonitor({"ATTITUDE": rate, "LOCAL_POSITION_NED": rate},
                                     min_rate_hz=MIN_RATE_FRACTION * rate)
        self._armed_sent = False

    # ------------------------------------------------------------------ events and I/O
    def _vehicle_event(self, kind: str, text: str) -> None:
        self.event(kind, text)

    def _handle(self, msg) -> None:
        self.telemetry.handle(msg, self.clock.now_ns())

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
            gone = self._vehicle_gone()
            if gone is not None:
                raise LinkError(gone)
            if self.adapter is not None:
                self._health(self.clock.now_ns())  # streams clobbered while landing are asked for again too
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
        period; the next one goes only when its telemetry is back (or after 0.5 s), so a
        slow serial link is never flooded with steps it cannot report.
        """
        if self.adapter is None:
            self.link.conn.select(0.01)
            return
        before = self.telemetry.status.time_boot_ms
        self._send_level(thrust_n)
        wait = 0.01
        if self.lockstep:
            # Wait for the step's telemetry (long enough for a simulator starved of CPU: the same
            # seed gives the same flight), unless the telemetry is gone (failsafe): then keep the
            # vehicle's time moving so that it can land by itself.
            wait = 0.5 if time.monotonic() - self._last_rx_wall < 0.5 else 0.005
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

    def _safe_command(self):
        """Level, yaw held, 90 % of hover thrust (0 before the adapter exists: on the ground)."""
        state = self.estimator.state()
        if self.adapter is None:
            q = (1.0, 0.0, 0.0, 0.0)
            return self.link.mav.set_attitude_target_encode(self.telemetry.status.time_boot_ms & 0xFFFFFFFF,
                                                            self.link.target_system, self.link.target_component,
                                                            7, q, 0.0, 0.0, 0.0, 0.0)
        return self.adapter.level(state, 0.9 * self.model.hover_thrust_n, self.telemetry.status.time_boot_ms)

    def _health(self, now_ns: int) -> tuple[str, str] | None:
        """The stream-rate watch: ask again for a stream that fell, fail safe when it stays too slow."""
        verdict = self.streams.update(now_ns, self.telemetry.counts)
        for name in verdict.rerequest:
            rate = self.streams.requested_hz[name]
            got = self.streams.rates_hz.get(name, 0.0)
            if self.streams.rerequests <= 3 or self.streams.rerequests % 20 == 0:
                self.event("warning", f"{name} at {got:.1f} Hz instead of {rate:g} Hz (another ground station's "
                                      f"stream request?): asking for {rate:g} Hz again")
            try:
                self.link.send_message_interval(STREAM_IDS[name], rate)
            except LinkError as exc:
                self._link_failed(exc)
        if verdict.failure is not None:
            return ("telemetry_slow", verdict.failure)
        return None

    def _abandon(self) -> None:
        """LAND, sent a few times without waiting (the vehicle's guided timeout is the fallback)."""
        for _ in range(3):
            try:
                self.link.send(self.link.mav.command_long_encode(
                    self.link.target_system, self.link.target_component, mavlink.MAV_CMD_DO_SET_MODE, 0,
                    mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 9, 0, 0, 0, 0, 0))
            except (LinkError, UnsafeCommand):
                return

    # ------------------------------------------------------------------ preflight
    def _param(self, name: str, default: float | None) -> float:
        """A parameter of the vehicle; ``default=None`` makes it required (refuse without it)."""
        self._check_interrupt()
        try:
            value = self.link.param_get(name, timeout_s=1.0, retries=1, on_message=self._handle)
        except LinkError:
            if default is None:
                raise PreflightRefused(f"parameter {name} not readable; it is needed to fly") from None
            self.event("warning", f"parameter {name} not readable; assuming {default:g}")
            return default
        if not math.isfinite(value):
            raise PreflightRefused(f"parameter {name} = {value} is not a finite number")
        return value

    def disarm_on_ground(self) -> None:
        """After a preflight refusal that came after the arm command: disarm (the vehicle is on the ground)."""
        if not self._armed_sent:
            return
        self._pump()
        # Sent whatever the vehicle last reported: a refusal may come exactly because its report of
        # the arming was lost (disarming a disarmed vehicle on the ground is harmless).
        try:
            self.link.arm(False, on_message=self._handle)
            self._wait_for("disarm", lambda: not self.telemetry.status.armed, 3.0, send=False)
        except LinkError as exc:
            self.event("warning", f"disarm after the refusal not acknowledged: {exc}")
        self.event("arming", "disarmed after the preflight refusal" if not self.telemetry.status.armed
                   else "still armed after the preflight refusal: disarm it")

    def _set_param(self, name: str, value: float, old: float) -> float:
        new = self.link.param_set(name, value, on_message=self._handle)
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
                self.link.param_set(name, value, timeout_s=1.0, retries=1, on_message=self._handle)
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
                       1.0, self._handle)

    def preflight(self, budget_ok: bool = True) -> None:
        """Everything before arming; raises :class:`PreflightRefused` or :class:`LinkError`."""
        link, fc = self.link, self.flight_cfg
        hb = link.wait_heartbeat(on_message=self._handle)
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
            res = link.set_message_interval(mid, hz, on_message=self._handle)
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
        if not 0.05 <= hover <= 0.95:
            raise PreflightRefused(f"MOT_THST_HOVER = {hover:g} is not a plausible hover throttle (0.05..0.95)")
        gains = tuple(self._param(f"ATC_ANG_{ax}_P", 4.5) for ax in ("RLL", "PIT", "YAW"))
        if not all(0.1 <= g <= 50.0 for g in gains):
            raise PreflightRefused(f"ATC_ANG_RLL/PIT/YAW_P = {gains} are not plausible angle gains (0.1..50)")
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
        res = link.set_mode("GUIDED_NOGPS", on_message=self._handle)
        if res != mavlink.MAV_RESULT_ACCEPTED:
            raise PreflightRefused(f"mode GUIDED_NOGPS refused (MAV_RESULT {res})")
        if not self._wait_for("mode", lambda: self.telemetry.status.custom_mode == 20, 3.0):
            # A mode is trusted only once the vehicle reports it: never arm in another one.
            raise PreflightRefused(f"mode GUIDED_NOGPS acknowledged but not confirmed: the vehicle reports "
                                   f"{self.telemetry.status.mode}")
        # Stream setpoints before arming (0.5 s of idle, level).
        for _ in range(int(round(0.5 / self.config.experiment.ts_s))):
            self._pump()
            self._idle_tick(0.0)
        self._check_interrupt()
        self._armed_sent = True
        res = link.arm(True, on_message=self._handle)
        if res != mavlink.MAV_RESULT_ACCEPTED:
            # The reason comes as STATUSTEXT, before or just after the acknowledgement.
            link.wait(lambda m: m.get_type() == "STATUSTEXT", 0.5, self._handle)
            texts = [t for t in self.telemetry.status.statustext if "arm" in t.lower()]
            why = texts[-1] if texts else f"MAV_RESULT {res}"
            raise PreflightRefused(f"arming refused: {why}")
        if not self._wait_for("armed", lambda: self.telemetry.status.armed, 3.0):
            raise PreflightRefused("the vehicle acknowledged arming but does not report armed")

    # ------------------------------------------------------------------ the loop's hooks
    def _fresh(self, now_ns: int, stale_s: float) -> bool:
        return self.telemetry.fresh(now_ns, stale_s)

    def _control_lost(self, t_s: float) -> str | None:
        st = self.telemetry.status
        if not st.armed:
            return "disarmed"
        if st.custom_mode not in (20, 4):
            return f"mode {st.mode}"
        return None

    def _send_command(self, state: State, cmd: Command) -> None:
        fields = self.adapter.fields(state, cmd)  # type: ignore[union-attr]
        self._send(self.adapter.encode(fields, self.telemetry.status.time_boot_ms))  # type: ignore[union-attr]

    def _housekeeping(self, k: int) -> None:
        try:
            self.link.send_heartbeat()
            self.telemetry.timesync_sent.add(self.link.send_timesync())
        except LinkError as exc:
            self._link_failed(exc)

    def _finish(self, reason: str) -> None:
        gone = self._vehicle_gone()
        if gone is not None:
            self.event("warning", f"{gone}: nothing left to land")
            return
        if reason == "vehicle_took_over":
            self._wait_for("disarm", lambda: not self.telemetry.status.armed, self.flight_cfg.land_timeout_s,
                           send=False)
        else:
            self._land(reason)

    def _link_summary(self) -> dict:
        c = self.link.counters
        samples = self.telemetry.timesync_samples_ms
        return {"received": c.received, "sent": c.sent, "bad_data": c.bad_data, "other_system": c.other_system,
                "unsigned_rejected": c.unsigned_rejected, "bad_signature": c.bad_signature,
                "other_address": c.other_address, "truncated": c.truncated, "malformed": c.malformed,
                "blocked": c.blocked, "guard_blocked": dict(self.guard.blocked),
                "telemetry_rejected": dict(self.telemetry.validator.rejected),
                "stream_rates_hz": dict(self.streams.rates_hz), "stream_rerequests": self.streams.rerequests,
                "timesync_rtt_ms": self.telemetry.timesync_rtt_ms,
                "timesync_rtt_median_ms": float(np.median(samples)) if samples else None}

    def fly(self) -> FlightResult:
        """Preflight must have passed.  Flies the mission and lands; returns the summary."""
        return self.run_mission()

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
                                         on_message=self._handle)
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
