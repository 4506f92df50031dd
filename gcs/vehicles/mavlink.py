"""A MAVLink autopilot as a vehicle session: the generic off-board flight, the firmware's ways in a profile.

Sequence::

    heartbeat -> TIMESYNC -> streams requested -> the profile's parameters -> telemetry fresh,
    battery -> the profile's flight mode, confirmed by HEARTBEAT -> setpoints streamed -> arm
    -> mission (the loop) -> the profile's landing -> disarmed -> parameters restored

Every frame both ways goes to the flight log.  Telemetry is validated before it reaches the
estimator (:mod:`gcs.flight.validate`), every outgoing message passes the output guard
(:mod:`gcs.link.guard`), the streams the controller flies on are watched
(:mod:`gcs.vehicles.streams`).  All waiting is on the flight's clock (:func:`gcs.flight.clock.wait_until`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.config import Config
from gcs.control import model_params
from gcs.errors import PreflightRefused
from gcs.estimate import DisturbanceObserver, StateEstimator
from gcs.flight.clock import PacedVehicleClock, VehicleClock, wait_until
from gcs.flight.context import FlightContext
from gcs.link.guard import GuardLimits, OutputGuard, UnsafeCommand
from gcs.link.mavlink import LinkError, MavlinkLink
from gcs.vehicles.ardupilot import ArduPilotProfile
from gcs.flight.authority import AuthorityWatch
from gcs.vehicles.firmware import Firmware
from gcs.vehicles.linkio import LinkIO
from gcs.vehicles.output import OutputAdapter, build_adapter
from gcs.vehicles.mavlink_preflight import MavlinkPreflight
from gcs.vehicles.params import ParamJournal, VehicleParams
from gcs.vehicles.profile import velocity_var_m2_s2
from gcs.vehicles.streams import StreamMonitor
from gcs.vehicles.telemetry import Telemetry
from quadrotor.state import Command, State

__all__ = ["MavlinkSession", "MAX_BODY_RATE_RAD_S", "MIN_RATE_FRACTION"]

#: Largest body rate a setpoint may carry [rad/s] (the output guard's limit).
MAX_BODY_RATE_RAD_S = 35.0
#: The loop fails safe when a stream the controller flies on stays below this share of its requested rate.
MIN_RATE_FRACTION = 0.25
#: How long after its setpoint-loss time a vehicle has surely taken over [s]: PX4 SITL on a loaded
#: 2-core machine showed Land 1.05 s after our setpoints stopped, with COM_OF_LOSS_T = 0.5 s.
FAILSAFE_REACTION_S = 0.6
#: Height above the mission's start [m] from which the vehicle counts as airborne (the output's rate-error
#: integral learns only then).
AIRBORNE_M = 0.05
STREAM_IDS = {"ATTITUDE": mavlink.MAVLINK_MSG_ID_ATTITUDE,
              "LOCAL_POSITION_NED": mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED}


class MavlinkSession:
    """One MAVLink vehicle flown off-board.

    Parameters
    ----------
    config : Config
    link : MavlinkLink
    profile : ArduPilotProfile, Px4Profile or None
        The firmware family's conventions (None: chosen from the HEARTBEAT's ``autopilot`` by
        :func:`~gcs.vehicles.autopilots.profile_for`; ArduPilot's until then).
    event_metadata : gcs.vehicles.px4_events.EventMetadata or None
        PX4's event metadata (arming refusals in words), for a PX4 profile chosen from HEARTBEAT.
    output : str or None
        Setpoint message (default: the config's ``[flight] output``).
    vehicle_alive : callable () -> str or None
        Why the vehicle's process is gone (a child simulator that exited), or None.
    speedup : float or None
        The vehicle runs by itself this many times faster than the wall (a firmware SITL): the
        flight runs on its clock (:class:`~gcs.flight.clock.PacedVehicleClock`).  None: the
        flight's clock is given (real time), or lockstep.
    ready_timeout_s : float
        Vehicle seconds to wait for it to become ready (fresh telemetry, EKF) and to accept arming.
    boot_speedup : float or None
        A firmware SITL we started runs at this speed-up until it is ready, then at ``speedup``
        (its SIM_SPEEDUP parameter).
    """

    lands_itself = True

    def __init__(self, config: Config, link: MavlinkLink, *, profile: ArduPilotProfile | None = None,
                 output: str | None = None, vehicle_alive: Callable[[], str | None] | None = None,
                 speedup: float | None = None, ready_timeout_s: float = 60.0,
                 boot_speedup: float | None = None, event_metadata=None) -> None:
        fc = config.flight
        self.config = config
        self.link = link
        self.profile_given = profile is not None
        self.event_metadata = event_metadata
        self.profile = profile or ArduPilotProfile()
        self.control_name = self.profile.control_name
        self.output_kind = output or fc.output
        self.vehicle_alive = vehicle_alive
        self.speedup = speedup
        self.boot_speedup = boot_speedup
        self.ready_timeout_s = ready_timeout_s
        #: What the autopilot says it is (the preflight asks for AUTOPILOT_VERSION).
        self.firmware = Firmware(mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA)
        self.model = model_params(config)
        self.period_s = config.experiment.ts_s
        self.estimator = StateEstimator(config.experiment.ts_s, self.model, (fc.position_std_m,) * 3,
                                        config.estimator.accel_noise_std_m_s2, ground_z_m=None)
        self.telemetry = Telemetry(self.estimator, (fc.position_std_m ** 2,) * 3, (fc.velocity_std_m_s ** 2,) * 3,
                                   on_event=self.event, target_component=link.target_component,
                                   mode_name=self.profile.mode_name)
        self.guard = OutputGuard(GuardLimits(max_body_rate_rad_s=MAX_BODY_RATE_RAD_S))
        link.guard = self.guard
        rate = fc.telemetry_rate_hz
        self.streams = StreamMonitor({"ATTITUDE": rate, "LOCAL_POSITION_NED": rate},
                                     min_rate_hz=MIN_RATE_FRACTION * rate)
        self.adapter: OutputAdapter | None = None
        self.authority: AuthorityWatch | None = None
        self.params: VehicleParams | None = None
        self.ctx: FlightContext | None = None
        self.io = LinkIO(link, self.handle, self.event, self._safe_command, on_batch=self._backlog)
        self.armed_sent = False
        #: The preflight found the vehicle ready (its streams flowing): from then on they are watched.
        self.ready = False
        self._gone_checked = 0
        #: The vehicle's time [ms] (its telemetry's ``time_boot_ms``) at our last setpoint (None before the first).
        self._last_setpoint_ms: int | None = None
        self._ground_z: float | None = None

    # ------------------------------------------------------------------ wiring and I/O
    def attach(self, ctx: FlightContext) -> None:
        self.ctx = ctx
        if ctx.clock is None:
            vehicle_ns = self.telemetry.vehicle_time_ns
            ctx.clock = (VehicleClock(vehicle_ns, self.io.pump_wait) if self.speedup is None
                         else PacedVehicleClock(vehicle_ns, self.io.pump_wait, self.boot_speedup or self.speedup))
            self.telemetry.on_vehicle_clock = True
        if ctx.recorder.enabled:
            rec = ctx.recorder
            self.link.on_frame = lambda direction, msg, accepted=True: rec.mavlink(ctx.now_ns(), direction, msg,
                                                                                   accepted)
        # A child simulator is new each flight: nothing of an earlier one to recover.
        journal = None if self.vehicle_alive is not None else ParamJournal(f"{self.link.url}#{self.link.target_system}")
        self.params = VehicleParams(self.link, self.handle, self.event, self.check_interrupt, journal)

    def use_profile(self, profile) -> None:
        """Fly with ``profile`` (the autopilot family found in HEARTBEAT): modes named its way from now on."""
        self.profile = profile
        self.control_name = profile.control_name
        self.telemetry.status.mode_name = profile.mode_name
        events = getattr(profile, "events", None)
        self.telemetry.describe_event = events.describe if events is not None else None

    def event(self, kind: str, text: str) -> None:
        self.ctx.event(kind, text)  # type: ignore[union-attr]

    def handle(self, msg) -> None:
        self.telemetry.handle(msg, self.ctx.now_ns())  # type: ignore[union-attr]

    def pump(self) -> int:
        """Drain the link into the telemetry (never blocks); the number of messages."""
        return self.io.pump()

    def _backlog(self, msgs: list) -> None:
        """A drained batch, before the telemetry takes it: one that holds more than the observer's reading
        gap of positions is a backlog (the loop or the link stalled), which the disturbance observer must
        not take for motion within one step (:meth:`gcs.estimate.DisturbanceObserver.restart`)."""
        obs = self.estimator.disturbance
        if obs is None:
            return
        limit = max(3, round(obs.reading_gap_s * self.config.flight.telemetry_rate_hz))
        if sum(1 for m in msgs if m.get_type() == "LOCAL_POSITION_NED") > limit:
            obs.restart()

    def send_message(self, msg) -> None:
        """Send ``msg`` through the output guard (a blocked one: the safe command, and fail safe)."""
        self.io.send(msg)

    def _safe_command(self):
        """Level, yaw held, 90 % of hover thrust (zero thrust before the adapter exists: on the ground)."""
        if self.adapter is None:
            return self._target(7, (1.0, 0.0, 0.0, 0.0), 0.0)
        return self.adapter.level(self.estimator.state(), 0.9 * self.model.hover_thrust_n,
                                  self.telemetry.status.time_boot_ms)

    def _target(self, type_mask: int, q, thrust: float):
        link = self.link
        return link.mav.set_attitude_target_encode(self.telemetry.status.time_boot_ms & 0xFFFFFFFF, link.target_system,
                                                   link.target_component, type_mask, q, 0.0, 0.0, 0.0, thrust)

    def check_interrupt(self) -> None:
        if self.ctx.interrupts.count:  # type: ignore[union-attr]
            raise PreflightRefused("interrupted before arming")

    # ------------------------------------------------------------------ waiting on the flight's clock
    def wait(self, predicate: Callable[[], bool], timeout_s: float, *, thrust_n: float | None = 0.0,
              until_interrupt: bool = True) -> bool:
        """Until ``predicate`` or ``timeout_s`` of the flight's clock: level setpoints at ``thrust_n`` every
        period (None: only listen — and in lockstep a THROTTLE_IGNORE target that the autopilot refuses but
        that moves the simulator's time); a HEARTBEAT every half second either way."""
        ctx = self.ctx
        next_hb = [ctx.now_ns()]

        def pump() -> None:
            self.pump()
            if ctx.now_ns() >= next_hb[0]:
                # Twice a second of the flight's clock whatever is sent: an autopilot's GCS failsafe
                # (ArduCopter FS_GCS_*, on its own clock) must see us while we wait.
                next_hb[0] = ctx.now_ns() + 500_000_000
                self.io.quietly(self.link.send_heartbeat)
            why = self._vehicle_gone(force=True)
            if why is not None:
                raise LinkError(why)
            if self.adapter is not None and self.ready:
                self._watch_streams(ctx.now_ns())  # streams clobbered while landing are asked for again too

        def step() -> bool:
            if thrust_n is not None and self.adapter is not None:
                self.send_message(self.adapter.level(self.estimator.state(), thrust_n,
                                                     self.telemetry.status.time_boot_ms))
                return True
            if ctx.lockstep and self.adapter is not None:
                self.send_message(self._target(64 | 7, (1.0, 0.0, 0.0, 0.0), 0.0))
                return True
            return False

        def stop() -> bool:
            return until_interrupt and ctx.interrupts.count > 0 and not self.telemetry.status.armed

        return wait_until(ctx.clock, predicate, timeout_s, period_s=self.period_s, pump=pump, step=step, stop=stop)

    def _vehicle_gone(self, force: bool = False) -> str | None:
        if self.vehicle_alive is None:
            return None
        self._gone_checked += 1
        if not force and self._gone_checked % 10:
            return None  # a syscall: ten times a second is soon enough
        return self.vehicle_alive()

    def _watch_streams(self, now_ns: int) -> str | None:
        """Ask again for a stream that fell; the failure text when it stays too slow."""
        verdict = self.streams.update(now_ns, self.telemetry.counts)
        for name in verdict.rerequest:
            rate = self.streams.requested_hz[name]
            got = self.streams.rates_hz.get(name, 0.0)
            if self.streams.rerequests <= 3 or self.streams.rerequests % 20 == 0:
                self.event("warning", f"{name} at {got:.1f} Hz instead of {rate:g} Hz (another ground station's "
                                       f"stream request?): asking for {rate:g} Hz again")
            self.io.quietly(lambda name=name, rate=rate: self.link.send_message_interval(STREAM_IDS[name], rate))
        return verdict.failure

    # ------------------------------------------------------------------ preflight
    def preflight(self) -> None:
        """Everything before arming, then arm; raises :class:`PreflightRefused` or :class:`LinkError`."""
        MavlinkPreflight(self).run()

    def configure_output(self, out) -> None:
        """The output adapter, once the profile has read what it needs (``out``: its
        :class:`~gcs.vehicles.ardupilot.OutputParams`), and the disturbance observer.

        The output's own parameters are set here when the profile was not told the output
        (``out.output``); ``actuator`` on a firmware that does not take it is refused.  The
        observer runs per ``[estimator] disturbance``: "on", or "auto" on a firmware that is
        not the built-in SITL (whose thrust and drag are the model's).
        """
        if out.output != self.output_kind:
            out = self.profile.configure_output(self.params, self.output_kind, self.firmware, out)
        link = self.link
        self.adapter = build_adapter(self.output_kind, self.model, self.config.flight, out, self.period_s, link.mav,
                                     link.target_system, link.target_component)
        self.authority = AuthorityWatch(self.period_s)
        est = self.config.estimator
        observe = est.disturbance == "on" or (est.disturbance == "auto" and not self.firmware.builtin_sitl)
        tau = est.disturbance_time_constant_s
        v = self.config.vehicle
        drag = out.drag_1_s if out.drag_1_s is not None else v.drag_n_per_m_s / v.mass_kg
        self.estimator.disturbance = (DisturbanceObserver(tau, velocity_bias_time_constant_s=tau, drag_1_s=drag)
                                      if observe else None)
        fc = self.config.flight
        self.telemetry.velocity_var = velocity_var_m2_s2((fc.velocity_std_m_s ** 2,) * 3, out)
        self.event("output", f"{self.output_kind}: hover throttle {out.hover_throttle:.3f}, "
                             f"angle gains ({', '.join(f'{g:.4g}' for g in out.angle_gain_1_s)}), rate demand gains "
                             f"{self.config.flight.rate_gain_1_s}; "
                             + (f"disturbance observer on (tau {tau:g} s)" if observe
                                else "no disturbance observer"))

    def disturbance_m_s2(self) -> tuple[float, float, float]:
        """The acceleration eq. 1 misses, as the estimator's observer has it (zeros without one)."""
        return self.estimator.disturbance_m_s2()

    def observer_log(self) -> tuple[float, float, float, float, float, float] | None:
        obs = self.estimator.disturbance
        return None if obs is None else (*self.estimator.disturbance_m_s2(), *obs.velocity_bias)

    def disarm_on_ground(self) -> None:
        """After a preflight refusal that came after the arm command: disarm (the vehicle is on the ground).

        Sent whatever the vehicle last reported: a refusal may come exactly because its report of
        the arming was lost (disarming a disarmed vehicle on the ground is harmless).
        """
        if not self.armed_sent:
            return
        self.pump()
        try:
            self.link.arm(False, on_message=self.handle)
            self.wait(lambda: not self.telemetry.status.armed, 3.0, thrust_n=None, until_interrupt=False)
        except LinkError as exc:
            self.event("warning", f"disarm after the refusal not acknowledged: {exc}")
        self.event("arming", "disarmed after the preflight refusal" if not self.telemetry.status.armed
                    else "still armed after the preflight refusal: disarm it")

    # ------------------------------------------------------------------ the loop's side
    def estimate(self, dt_s: float, last_command: Command | None) -> State:
        if dt_s > 0:
            self.estimator.predict(dt_s, last_command)
        return self.estimator.state()

    def truth(self) -> State | None:
        return None

    def fresh(self, now_ns: int, stale_s: float) -> bool:
        return self.telemetry.fresh(now_ns, stale_s)

    def fault(self) -> tuple[str, str] | None:
        gone = self._vehicle_gone()
        if gone is not None:
            return ("link_error", gone)
        return self.io.fault

    def health(self, now_ns: int) -> tuple[str, str] | None:
        past = self.authority.failure() if self.authority is not None else None
        if past is not None:
            return "out_of_authority", past
        failure = self._watch_streams(now_ns)
        return None if failure is None else ("telemetry_slow", failure)

    def control_lost(self) -> str | None:
        lost = self.profile.control_lost(self.telemetry.status)
        return lost if lost is not None else self._setpoint_gap()

    def _setpoint_gap(self) -> str | None:
        """Our setpoints stopped for longer than the vehicle's limit and its reaction time
        (:data:`FAILSAFE_REACTION_S`; this ground station stalled): its failsafe has the vehicle even
        if no HEARTBEAT has said so yet (a stall can overflow the socket), and PX4 would hand it back
        to our next setpoint. We do not take it back.  (A shorter gap, a loaded machine's hiccup, is
        left to the HEARTBEATs: PX4 may not have noticed it.)"""
        loss_s, last = self.profile.setpoint_loss_s, self._last_setpoint_ms
        if loss_s is None or last is None:
            return None
        gap_s = (self.telemetry.status.time_boot_ms - last) * 1e-3  # on the vehicle's clock, as its timer runs
        if gap_s <= loss_s + FAILSAFE_REACTION_S:
            return None
        return (f"no setpoint from us for {gap_s:.2f} s, beyond {self.profile.setpoint_loss_param} = {loss_s:g} s: "
                f"{self.profile.name}'s failsafe has it")

    def mission_origin(self, state: State) -> tuple[float, float, float]:
        self._ground_z = state.z
        return (state.x, state.y, state.z)

    def send(self, state: State, command: Command) -> None:
        airborne = self._ground_z is None or state.z > self._ground_z + AIRBORNE_M
        fields = self.adapter.fields(state, command, airborne)  # type: ignore[union-attr]
        integral = self.adapter.integral  # type: ignore[union-attr]
        self.authority.update(fields, airborne, None if integral is None else integral.delta_rad,  # type: ignore[union-attr]
                              None if integral is None else integral.max_rad)
        boot_ms = self.telemetry.status.time_boot_ms
        self.send_message(self.adapter.encode(fields, boot_ms))  # type: ignore[union-attr]
        self._last_setpoint_ms = boot_ms

    def housekeeping(self) -> None:
        self.io.quietly(self.link.send_heartbeat)
        self.io.quietly(lambda: self.telemetry.timesync_sent.add(self.link.send_timesync()))

    def landed(self) -> bool:
        return not self.telemetry.status.armed

    # ------------------------------------------------------------------ the end
    def finish(self, reason: str) -> None:
        gone = self._vehicle_gone(force=True)
        if gone is not None:
            self.event("warning", f"{gone}: nothing left to land")
            return
        if reason == "vehicle_took_over":
            st, hover = self.telemetry.status, self.profile.hover_modes
            self.wait(lambda: not st.armed or st.custom_mode in hover, self.config.flight.land_timeout_s,
                      thrust_n=None, until_interrupt=False)
            if st.armed and st.custom_mode in hover:
                # A failsafe of the autopilot's own left it hovering (PX4 Hold): nobody flies it; land it.
                self.event("failsafe", f"the vehicle hovers in {st.mode} by itself: landing it")
                self._land(reason)
            elif not st.armed:
                self.event("landed", "landed and disarmed")
        else:
            self._land(reason)

    def _land(self, reason: str) -> None:
        """The profile's LAND, level setpoints while waiting, until disarmed (or the timeout).

        With the telemetry gone the acknowledgement cannot come back: LAND is sent once
        without waiting long, and level setpoints keep the vehicle upright (they also keep
        a lockstep simulator's time moving) while it lands on its own.  LAND is sent again
        twice a second until the vehicle reports it: a lost frame must not leave it in the
        flight mode.  Should LAND never be taken, 90 % of hover thrust, level, still brings
        it down gently.
        """
        p, st, ctx = self.profile, self.telemetry.status, self.ctx
        quick = reason == "telemetry_lost"
        try:
            res = p.request_mode(self.link, p.land_mode, on_message=self.handle, timeout_s=0.3 if quick else 3.0,
                                 retries=0 if quick else 2)
            if res != mavlink.MAV_RESULT_ACCEPTED:
                self.event("warning", f"LAND refused (MAV_RESULT {res})")
        except LinkError as exc:
            self.event("warning", f"LAND not acknowledged: {exc}")
        self.event("phase", "landing (LAND mode)")
        next_land = [ctx.now_ns() + 500_000_000]

        def done() -> bool:
            if st.armed and st.custom_mode != p.land_mode and ctx.now_ns() >= next_land[0]:
                next_land[0] = ctx.now_ns() + 500_000_000
                self.send_message(p.set_mode_message(self.link, p.land_mode))
            return not st.armed or ctx.interrupts.count >= 3

        timeout = self.config.flight.land_timeout_s
        landed = self.wait(done, timeout, thrust_n=0.9 * self.model.hover_thrust_n, until_interrupt=False)
        if landed and not st.armed:
            self.event("landed", "landed and disarmed")
        else:
            self.event("warning", f"not disarmed {timeout:g} s after LAND")

    def abandon(self) -> None:
        """LAND, sent a few times without waiting (the vehicle's guided timeout is the fallback)."""
        for _ in range(3):
            try:
                self.link.send(self.profile.set_mode_message(self.link, self.profile.land_mode))
            except (LinkError, UnsafeCommand):
                return

    def restore(self) -> None:
        if self.params is not None:
            self.params.restore(lambda: self.telemetry.status.armed)

    def summary(self) -> dict:
        c = self.link.counters
        samples = self.telemetry.timesync_samples_ms
        return {"received": c.received, "sent": c.sent, "bad_data": c.bad_data, "other_system": c.other_system,
                "unsigned_rejected": c.unsigned_rejected, "bad_signature": c.bad_signature,
                "other_address": c.other_address, "truncated": c.truncated, "malformed": c.malformed,
                "blocked": c.blocked, "guard_blocked": dict(self.guard.blocked),
                "telemetry_rejected": dict(self.telemetry.validator.rejected),
                "stream_rates_hz": dict(self.streams.rates_hz), "stream_rerequests": self.streams.rerequests,
                "timesync_rtt_ms": self.telemetry.timesync_rtt_ms,
                "timesync_rtt_median_ms": float(np.median(samples)) if samples else None,
                "vehicle_clock_rate": self.telemetry.time_map.mean_rate,
                "vehicle_clock_rate_recent": self.telemetry.time_map.rate}

    def loop_summary(self) -> dict:
        clock = self.ctx.clock if self.ctx is not None else None
        return {"telemetry_timeouts": clock.timeouts} if isinstance(clock, VehicleClock | PacedVehicleClock) else {}
