"""The 4-DOF rig (x, z, roll, pitch) as a vehicle session: ``gcs fly --rig 4dof``, the paper's indoor experiment.

The same mission loop, controllers, safety envelope, log and exit codes as a MAVLink
autopilot (:class:`gcs.flight.loop.MissionLoop`); what differs is the vehicle:

* the link is the rig's serial protocol (:mod:`gcs.link.rig`, docs/rig-protocol.md);
* telemetry: TELEMETRY at 200 Hz gives the attitude and Euler-angle rates, the ultrasonic
  altitude (4 cm steps) and x along the rail; y and yaw are locked (measured as 0).  The
  Kalman filters of :class:`gcs.estimate.StateEstimator` give the velocities, with the
  quantisation in the altitude noise as in ``gcs sim``;
* output: CONTROL frames carry the controller's thrust [N] and angular accelerations
  [rad/s²] as they are (the rig's firmware mixes them to its motors);
* preflight: HEARTBEAT -> STATUS (protocol version, round trip), a latched cut-off cleared
  with DISARM, fresh telemetry, landed, ARM (control frames must follow within the rig's
  0.5 s watchdog: the mission loop starts at once);
* the rig has no landing mode: after the mission (and after Ctrl-C) the loop flies a
  descent at ``landing_speed_m_s`` down to the takeoff altitude, then this module waits for
  touchdown (LANDED) and sends DISARM.  If the telemetry is lost the ground station stops
  sending control and the rig's own link watchdog descends and disarms (real time); in
  lockstep, where the rig's time only moves with control frames, level frames at 90 % of
  hover thrust bring it down.  A cut-off or a watchdog descent the rig started itself is
  ``vehicle_took_over``: setpoints stop and a latched cut-off is cleared with DISARM once
  the motors are off.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from gcs.config import Config
from gcs.control import model_params
from gcs.errors import PreflightRefused
from gcs.estimate import StateEstimator
from gcs.flight.clock import VehicleClock, wait_until
from gcs.flight.context import FlightContext
from gcs.flight.safety import SafetyEnvelope
from gcs.link.guard import GuardLimits, OutputGuard
from gcs.link.mavlink import LinkError
from gcs.link.rig import RigLink
from gcs.vehicles.linkio import LinkIO
from gcs.vehicles.rig_telemetry import RigTelemetry, cutoff_causes
from quadrotor import rig_protocol as rp
from quadrotor.rig_protocol import AckResult, RigFlags, RigState
from quadrotor.state import Command, State

__all__ = ["RigSession", "RIG_X_STD_M"]

#: Noise assumed for the rig's x reading [m] (its rail encoder); also given to the locked y.
RIG_X_STD_M = 0.005


class RigSession:
    """The 4-DOF rig over ``link``.

    Parameters
    ----------
    config : Config
    link : RigLink
    envelope : SafetyEnvelope
        Its levelling PD flies the frames sent outside the mission (descents, the safe command).
    vehicle_alive : callable () -> str or None
        Why the rig's process is gone (the emulator child exited), or None.
    """

    lands_itself = False
    control_name = "ground-station control"

    def __init__(self, config: Config, link: RigLink, envelope: SafetyEnvelope, *,
                 vehicle_alive: Callable[[], str | None] | None = None) -> None:
        sp = config.sim.sensors
        alt_std = math.sqrt(sp.altitude_noise_std_m ** 2 + sp.altitude_resolution_m ** 2 / 12.0)
        self.config = config
        self.model = model_params(config)
        self.period_s = config.experiment.ts_s
        self.estimator = StateEstimator(config.experiment.ts_s, self.model, (RIG_X_STD_M, RIG_X_STD_M, alt_std),
                                        config.estimator.accel_noise_std_m_s2, ground_z_m=0.0)
        self.link = link
        self.envelope = envelope
        self.vehicle_alive = vehicle_alive
        self.tel = RigTelemetry(self.estimator, self._event)
        self.validator = self.tel.validator
        self.guard = OutputGuard(GuardLimits(max_thrust_n=config.vehicle.max_thrust_n,
                                             max_angular_accel_rad_s2=config.vehicle.max_angular_accel_rad_s2))
        link.guard = self.guard
        self.ctx: FlightContext | None = None
        self._seq = 0
        self.io = LinkIO(link, self._handle, self._event, self._safe_command)
        self._armed_sent = False
        self._gone_checked = 0

    def attach(self, ctx: FlightContext) -> None:
        self.ctx = ctx
        if ctx.clock is None:
            ctx.clock = VehicleClock(lambda: self.tel.time_ns, self.io.pump_wait)
        if ctx.recorder.enabled:
            rec = ctx.recorder
            self.link.on_bytes = lambda direction, data: rec.frame(ctx.now_ns(), "rig", direction, data)

    def _event(self, kind: str, text: str) -> None:
        self.ctx.event(kind, text)  # type: ignore[union-attr]

    # ------------------------------------------------------------------ telemetry
    def _handle(self, msg: rp.Message) -> None:
        self.tel.handle(msg, self.ctx.now_ns())  # type: ignore[union-attr]

    # ------------------------------------------------------------------ I/O
    def pump(self) -> int:
        """Drain the serial line into the estimate (never blocks); the number of messages."""
        return self.io.pump()

    def _send(self, msg) -> None:
        self.io.send(msg)

    def _heartbeat(self) -> None:
        self._send(rp.Heartbeat(self.tel.heartbeat_stamp()))

    def _command(self, msg_type: type, what: str, timeout_s: float = 1.0, retries: int = 2) -> AckResult:
        """ARM or DISARM, waiting for the ACK (answered at once, without moving the rig's time)."""
        for _ in range(retries + 1):
            seq = self.link.next_seq8()
            self._send(msg_type(seq))
            ack = self.link.wait(
                lambda m, seq=seq: isinstance(m, rp.Ack) and m.acked_type == msg_type.TYPE and m.seq == seq,
                timeout_s, self._handle)
            if ack is not None:
                return AckResult(ack.result)
        raise LinkError(f"no ACK for {what} after {retries + 1} tries")

    def _control_frame(self, thrust_n: float, roll: float, pitch: float, yaw: float) -> None:
        self._seq = self._seq % 65535 + 1
        self._send(rp.Control(self._seq, thrust_n, roll, pitch, yaw))

    def _safe_command(self) -> rp.Control:
        """Level at 90 % of hover thrust (all zero angular acceleration if the estimate is unusable)."""
        self._seq = self._seq % 65535 + 1
        thrust = 0.9 * self.model.hover_thrust_n if self.tel.flags & RigFlags.ARMED else 0.0
        cmd = self.envelope.level(self.estimator.state(), thrust)
        if not all(math.isfinite(v) for v in cmd):
            return rp.Control(self._seq, thrust, 0.0, 0.0, 0.0)
        return rp.Control(self._seq, cmd.thrust_n, cmd.roll_accel_rad_s2, cmd.pitch_accel_rad_s2, 0.0)

    def _level(self, thrust_n: float) -> None:
        """A level control frame at ``thrust_n`` (attitude PD of the safety envelope)."""
        cmd = self.envelope.level(self.estimator.state(), thrust_n)
        self._control_frame(cmd.thrust_n, cmd.roll_accel_rad_s2, cmd.pitch_accel_rad_s2, 0.0)

    def _check_interrupt(self) -> None:
        if self.ctx.interrupts.count:  # type: ignore[union-attr]
            raise PreflightRefused("interrupted before arming")

    def _wait(self, predicate: Callable[[], bool], timeout_s: float, *, frame: Callable[[], None] | None) -> bool:
        """Until ``predicate`` or ``timeout_s`` of the flight's clock, ``frame()`` (a control frame) every
        period; heartbeats once a second.  Without frames nothing moves a lockstep rig's time."""
        ctx = self.ctx
        next_hb = [ctx.now_ns() + 1_000_000_000]

        def step() -> bool:
            if ctx.now_ns() >= next_hb[0]:
                next_hb[0] += 1_000_000_000
                self._heartbeat()
            if frame is None:
                return False
            frame()
            return True

        return wait_until(ctx.clock, predicate, timeout_s, period_s=self.period_s, pump=self.pump, step=step,
                          stop=lambda: ctx.interrupts.count >= 3)

    # ------------------------------------------------------------------ preflight
    def preflight(self) -> None:
        """Everything before arming, then ARM; raises :class:`PreflightRefused` or :class:`LinkError`."""
        fc = self.config.flight
        status = self._greet()
        self._event("link", f"rig on {self.link.url}: protocol {status.protocol_version}, firmware "
                            f"{status.fw_major}.{status.fw_minor}.{status.fw_patch}, "
                            f"state {RigState(status.state).name}")
        if status.protocol_version != rp.PROTOCOL_VERSION:
            raise PreflightRefused(f"the rig speaks protocol version {status.protocol_version}, this ground station "
                                   f"{rp.PROTOCOL_VERSION}")
        # A round trip answered to the heartbeat just sent (the first STATUS may be the greeting).
        self._heartbeat()
        self.link.wait(lambda m: isinstance(m, rp.Status) and self.tel.rtt_ms is not None, 1.0, self._handle)
        if self.tel.rtt_ms is not None:
            self._event("link", f"round trip {self.tel.rtt_ms:.1f} ms (HEARTBEAT -> STATUS)")
            if self.tel.rtt_ms / 1000.0 > fc.telemetry_stale_s:
                raise PreflightRefused(f"link round trip {self.tel.rtt_ms:.0f} ms exceeds the telemetry stale timeout "
                                       f"({fc.telemetry_stale_s * 1000:.0f} ms)")
        if self.tel.state_rig == RigState.CUTOFF:
            self._event("warning", f"a cut-off is latched ({cutoff_causes(self.tel.flags)}); clearing it with DISARM")
            self._command(rp.Disarm, "DISARM")
        elif self.tel.state_rig in (RigState.ARMED, RigState.DESCENT):
            raise PreflightRefused(f"the rig is already {RigState(self.tel.state_rig).name.lower()}; "
                                   "gcs fly starts from a disarmed rig on the ground")
        self._settle(fc.telemetry_stale_s)
        if not self.tel.flags & RigFlags.LANDED:
            raise PreflightRefused(f"the rig is not resting on the ground (altitude {self.estimator.state().z:.2f} m)")
        self._check_interrupt()
        self._armed_sent = True
        res = self._command(rp.Arm, "ARM")
        if res != AckResult.ACCEPTED:
            raise PreflightRefused(f"arming refused: {res.name}")
        # Armed from now on (the next TELEMETRY says so too; in lockstep it comes with the first step).
        self.tel.set_flags(self.tel.flags | RigFlags.ARMED)

    def _greet(self) -> rp.Status:
        """HEARTBEATs until the rig answers with STATUS (the link's own 5 s of request and answer)."""
        for _ in range(10):
            self._check_interrupt()
            self._heartbeat()
            status = self.link.wait(lambda m: isinstance(m, rp.Status), 0.5, self._handle)
            if status is not None:
                return status
        raise LinkError(f"no STATUS from the rig on {self.link.url} within 5 s (is it powered, the baud rate "
                        f"{self.link.baud}?)")

    def _settle(self, stale_s: float) -> None:
        """Fresh telemetry and 0.5 s of it into the estimate (its velocities settle) before arming.

        In lockstep the rig sends telemetry only when a control frame moves its time: zero-thrust
        frames (ignored while disarmed) do that, one step at a time (same seed, same flight)."""
        first_ns: list[int | None] = [None]

        def settled() -> bool:
            self._check_interrupt()
            if not (self.estimator.initialised and self.fresh(self.ctx.now_ns(), stale_s)):
                return False
            first_ns[0] = self.tel.time_ns if first_ns[0] is None else first_ns[0]
            return self.tel.time_ns - first_ns[0] >= 500_000_000

        frame = (lambda: self._control_frame(0.0, 0.0, 0.0, 0.0)) if self.ctx.lockstep else None
        if not self._wait(settled, 5.0, frame=frame):
            raise PreflightRefused("no fresh TELEMETRY from the rig within 5 s")

    def disarm_on_ground(self) -> None:
        """After a preflight refusal that came after ARM: DISARM (the rig is on the ground)."""
        if self._armed_sent and self.tel.flags & RigFlags.ARMED:
            self._disarm_landed("arming", "disarmed after the preflight refusal")

    # ------------------------------------------------------------------ the loop's side
    def estimate(self, dt_s: float, last_command: Command | None) -> State:
        if dt_s > 0:
            self.estimator.predict(dt_s, last_command)
        return self.estimator.state()

    def truth(self) -> State | None:
        return None

    def disturbance_m_s2(self) -> tuple[float, float, float]:
        """None estimated: the rig flies the paper's laws as they are."""
        return (0.0, 0.0, 0.0)

    def observer_log(self) -> None:
        return None

    def fresh(self, now_ns: int, stale_s: float) -> bool:
        return self.tel.fresh(now_ns, stale_s)

    def fault(self) -> tuple[str, str] | None:
        if self.vehicle_alive is not None:
            self._gone_checked += 1
            gone = self.vehicle_alive() if self._gone_checked % 10 == 1 else None
            if gone is not None:
                return ("link_error", gone)
        return self.io.fault

    def health(self, now_ns: int) -> tuple[str, str] | None:
        return None

    def control_lost(self) -> str | None:
        f = self.tel.flags
        if f & RigFlags.CUTOFF:
            return f"safety cut-off: {cutoff_causes(f) or 'unknown cause'}"
        if f & RigFlags.WATCHDOG:
            return "the rig's link watchdog is landing it"
        if not f & RigFlags.ARMED:
            return "disarmed"
        return None

    def mission_origin(self, state: State) -> tuple[float, float, float]:
        # The ultrasonic reads the height above the ground: the mission's altitudes are absolute.
        return (state.x, 0.0, 0.0)

    def send(self, state: State, command: Command) -> None:
        self._control_frame(command.thrust_n, command.roll_accel_rad_s2, command.pitch_accel_rad_s2,
                            command.yaw_accel_rad_s2)

    def housekeeping(self) -> None:
        self._heartbeat()

    def landed(self) -> bool:
        return bool(self.tel.flags & RigFlags.LANDED)

    # ------------------------------------------------------------------ the end
    def _disarm_landed(self, kind: str = "landed", text: str = "landed and disarmed") -> None:
        """DISARM (motors off) and, once acknowledged, the event ``kind``/``text``."""
        try:
            if self._command(rp.Disarm, "DISARM") == AckResult.ACCEPTED:
                self._event(kind, text)
        except LinkError as exc:
            self._event("warning", f"DISARM not acknowledged: {exc}")

    def finish(self, reason: str) -> None:
        fc = self.config.flight
        if self.vehicle_alive is not None and self.vehicle_alive() is not None:
            self._event("warning", f"{self.vehicle_alive()}: nothing left to land")
            return
        if reason == "vehicle_took_over":
            self._wait(lambda: not self.tel.flags & RigFlags.ARMED, fc.land_timeout_s, frame=None)
            if self.tel.flags & RigFlags.CUTOFF:
                self._disarm_landed("phase", "cut-off cleared with DISARM (motors were off)")
            elif not self.tel.flags & RigFlags.ARMED:
                self._event("landed", "disarmed by the rig")
            return
        if reason == "telemetry_lost":
            self._lost_telemetry_landing()
            return
        if not self.landed():
            # Geofence, a second Ctrl-C, or a descent that did not reach the ground: level, below hover.
            self._event("phase", "level descent at 90 % of hover thrust")
            descend = 0.9 * self.model.hover_thrust_n
            if not self._wait(self.landed, fc.land_timeout_s, frame=lambda: self._level(descend)):
                self._event("warning", f"not on the ground {fc.land_timeout_s:g} s after the descent began; "
                                       "DISARM anyway (motors off)")
        self._disarm_landed()

    def _lost_telemetry_landing(self) -> None:
        fc, ctx = self.config.flight, self.ctx
        if not ctx.lockstep:
            # The rig's watchdog levels it, descends and disarms on the ground by itself.
            self._event("phase", "telemetry lost: control stopped, the rig's link watchdog lands it")
            ok = self._wait(lambda: self.fresh(ctx.now_ns(), fc.telemetry_stale_s) and self.landed(),
                            fc.land_timeout_s, frame=None)
            if ok and self.tel.flags & RigFlags.ARMED:
                self._disarm_landed()
            elif ok:
                self._event("landed", "landed and disarmed by the rig's watchdog")
            else:
                self._event("warning", f"no telemetry within {fc.land_timeout_s:g} s: touchdown not seen")
            return
        # In lockstep the rig's time moves only with control frames (its watchdog never trips):
        # level frames below hover for land_timeout_s of rig time bring it down, then DISARM.
        self._event("phase", "telemetry lost: level descent at 90 % of hover thrust")
        descend = 0.9 * self.model.hover_thrust_n
        for _ in range(int(round(fc.land_timeout_s / self.period_s))):
            self.pump()
            fresh = self.fresh(ctx.now_ns(), fc.telemetry_stale_s)
            if self.landed() and fresh:
                break
            if fresh:
                self._level(descend)
            else:  # no attitude to level on: hold the angular rates (no angular acceleration)
                self._control_frame(descend, 0.0, 0.0, 0.0)
            self.io.pump_wait(0.002)
        self._disarm_landed()

    def abandon(self) -> None:
        """Nothing to send: without control frames the rig's own link watchdog levels, descends and disarms."""

    def restore(self) -> None:
        """The rig keeps no parameters for a flight."""

    def summary(self) -> dict:
        c = self.link.counters
        st = self.tel.status
        out = {"received": c.frames, "sent": self.link.sent, "bad_data": c.errors,
               "received_bytes": self.link.received_bytes, "sent_bytes": self.link.sent_bytes,
               "decoder": c.as_dict(), "rtt_ms": self.tel.rtt_ms, "blocked": dict(self.guard.blocked),
               "telemetry_rejected": dict(self.validator.rejected)}
        if st is not None:
            out["rig_rx"] = {"frames": st.rx_frames, "checksum_errors": st.rx_checksum_errors,
                             "length_errors": st.rx_length_errors, "truncated_frames": st.rx_truncated_frames,
                             "discarded_bytes": st.rx_discarded_bytes, "cutoffs": st.cutoffs,
                             "watchdog_trips": st.watchdog_trips}
        return out

    def loop_summary(self) -> dict:
        clock = self.ctx.clock if self.ctx is not None else None
        return {"telemetry_timeouts": clock.timeouts} if isinstance(clock, VehicleClock) else {}
