"""``gcs fly --rig 4dof``: the paper's indoor experiment on the 4-DOF rig (x, z, roll, pitch).

The same mission loop, controllers, safety envelope, log and exit codes as the MAVLink
path (:class:`gcs.flight.loop.FlightLoop`); what differs is the vehicle:

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
import time
from typing import Callable

from gcs.config import Config
from gcs.control import model_params
from gcs.estimate import StateEstimator
from quadrotor.clock import Clock
from gcs.flight.loop import FlightLoop, FlightResult, Interrupts, PreflightRefused, VehicleClock
from gcs.flight.recorder import FlightRecorder
from gcs.flight.validate import TelemetryValidator
from gcs.link.guard import GuardLimits, OutputGuard
from gcs.link.mavlink import LinkError
from gcs.link.rig import RigLink
from quadrotor.state import Command, State
from quadrotor import rig_protocol as rp
from quadrotor.rig_protocol import AckResult, RigFlags, RigState

__all__ = ["RigFlight", "RIG_X_STD_M"]

#: Noise assumed for the rig's x reading [m] (its rail encoder); also given to the locked y.
RIG_X_STD_M = 0.005
#: |x| along the rail beyond which a TELEMETRY reading is implausible [m].
RIG_MAX_X_M = 50.0
_US_WRAP = 1 << 32


class RigFlight(FlightLoop):
    """One flight of ``controller`` on ``config``'s mission on the 4-DOF rig over ``link``.

    Parameters
    ----------
    config : Config
    controller : str
    link : RigLink
    clock : Clock or None
        The loop's clock in real time (None = lockstep: the rig's telemetry time).
    console, live_period_s, interrupts, recorder
        As :class:`gcs.flight.loop.FlightLoop`.
    """

    lands_itself = False
    control_name = "ground-station control"

    def __init__(self, config: Config, controller: str, link: RigLink, clock: Clock | None, *,
                 console: Callable[[str], None] | None = None, live_period_s: float = 0.5,
                 interrupts: Interrupts | None = None, recorder: FlightRecorder | None = None) -> None:
        sp = config.sim.sensors
        alt_std = math.sqrt(sp.altitude_noise_std_m ** 2 + sp.altitude_resolution_m ** 2 / 12.0)
        estimator = StateEstimator(config.experiment.ts_s, model_params(config), (RIG_X_STD_M, RIG_X_STD_M, alt_std),
                                   config.estimator.accel_noise_std_m_s2, ground_z_m=0.0)
        super().__init__(config, controller, estimator, clock, console=console, live_period_s=live_period_s,
                         interrupts=interrupts, recorder=recorder)
        self.link = link
        self.flags = RigFlags(0)
        self.state_rig: RigState | None = None
        self.status: rp.Status | None = None
        self._time_us_last: int | None = None
        self._time_ns = 0
        self._last_rx_ns: int | None = None
        self._last_rx_wall = time.monotonic()
        self._seq = 0
        self.rtt_ms: float | None = None
        self._hb_sent: dict[int, int] = {}
        if clock is None:
            self.clock = VehicleClock(lambda: self._time_ns, self._pump_wait)
        self.validator = TelemetryValidator(on_first=lambda why: self.event(
            "warning", f"telemetry rejected: {why} (further ones are counted)"))
        self.guard = OutputGuard(GuardLimits(max_thrust_n=config.vehicle.max_thrust_n,
                                             max_angular_accel_rad_s2=config.vehicle.max_angular_accel_rad_s2))
        link.guard = self.guard
        self._armed_sent = False
        if self.recorder.enabled:
            rec = self.recorder
            link.on_bytes = lambda direction, data: rec.frame(self.now_ns(), "rig", direction, data)

    # ------------------------------------------------------------------ telemetry
    def _rig_time(self, time_us: int) -> None:
        """Unwrap the rig's 32-bit microsecond clock into :attr:`_time_ns`."""
        last = self._time_us_last
        if last is not None:
            step = (time_us - last) % _US_WRAP
            if step < _US_WRAP // 2:
                self._time_ns += step * 1000
        else:
            self._time_ns = time_us * 1000
        self._time_us_last = time_us

    def _valid(self, msg: rp.Telemetry) -> bool:
        """Finite, physically plausible, and not older than the last TELEMETRY (see :mod:`gcs.flight.validate`)."""
        v = self.validator
        if not v.attitude(msg.roll_rad, msg.pitch_rad, msg.yaw_rad, msg.roll_rate_rad_s, msg.pitch_rate_rad_s,
                          msg.yaw_rate_rad_s, None, message="TELEMETRY"):
            return False
        if not math.isfinite(msg.x_m) or abs(msg.x_m) > RIG_MAX_X_M:
            return v.reject("TELEMETRY", "x out of range")
        step = (msg.time_us - self._time_us_last) % _US_WRAP if self._time_us_last is not None else 0
        if self._time_us_last is not None and (step == 0 or step >= _US_WRAP // 2):
            return v.reject("TELEMETRY", "time stamp did not advance")
        return True

    def _handle(self, msg: rp.Message) -> None:
        if isinstance(msg, rp.Telemetry):
            if not self._valid(msg):
                return
            self._rig_time(msg.time_us)
            self._last_rx_ns = self.now_ns()  # arrival on the loop's clock (in lockstep: >= the rig's time)
            self.estimator.correct_position((msg.x_m, 0.0, msg.altitude_m))
            self.estimator.set_attitude(msg.roll_rad, msg.pitch_rad, 0.0, msg.roll_rate_rad_s, msg.pitch_rate_rad_s, 0.0)
            self._flags(RigFlags(msg.flags))
        elif isinstance(msg, rp.Status):
            self.status = msg
            if self.state_rig is not None and msg.state != self.state_rig:
                self.event("mode", f"rig {RigState(msg.state).name}")
            self.state_rig = RigState(msg.state)
            sent = self._hb_sent.pop(msg.heartbeat_echo_us, None)
            if sent is not None:
                self.rtt_ms = (time.monotonic_ns() - sent) / 1e6
            self._flags(RigFlags(msg.flags))
        elif isinstance(msg, rp.Ack):
            kind = rp.MESSAGE_TYPES.get(msg.acked_type)
            name = kind.NAME if kind is not None else f"unknown type 0x{msg.acked_type:02x}"
            result = AckResult(msg.result).name if msg.result in AckResult._value2member_map_ else str(msg.result)
            self.event("ack", f"{name} seq {msg.seq}: {result}")

    def _flags(self, flags: RigFlags) -> None:
        changed = flags ^ self.flags
        self.flags = flags
        if changed & RigFlags.ARMED:
            self.event("arming", "armed" if flags & RigFlags.ARMED else "disarmed")
        if changed & RigFlags.CUTOFF and flags & RigFlags.CUTOFF:
            causes = [f.name for f in RigFlags if f & rp.CUTOFF_CAUSES and f & flags]
            self.event("failsafe", f"rig safety cut-off ({', '.join(causes) or 'unknown cause'}): motors off")
        if changed & RigFlags.WATCHDOG and flags & RigFlags.WATCHDOG:
            self.event("failsafe", "rig link watchdog: no control frames, the rig descends by itself")
        if changed & RigFlags.LANDED:
            self.event("landing", "on the ground" if flags & RigFlags.LANDED else "lifted off")

    def _heartbeat(self) -> None:
        t_us = (time.monotonic_ns() // 1000) & 0xFFFFFFFF
        self._hb_sent[t_us] = time.monotonic_ns()
        if len(self._hb_sent) > 16:
            self._hb_sent.pop(next(iter(self._hb_sent)))
        self._send(rp.Heartbeat(t_us))

    # ------------------------------------------------------------------ commands
    def _command(self, msg_type: type, what: str, timeout_s: float = 1.0, retries: int = 2) -> AckResult:
        """ARM or DISARM, waiting for the ACK (answered at once, without moving the rig's time)."""
        for _ in range(retries + 1):
            seq = self.link.next_seq8()
            self._send(msg_type(seq))
            ack = self.link.wait(lambda m: isinstance(m, rp.Ack) and m.acked_type == msg_type.TYPE and m.seq == seq,
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
        thrust = 0.9 * self.model.hover_thrust_n if self.flags & RigFlags.ARMED else 0.0
        cmd = self.envelope.level(self.estimator.state(), thrust)
        if not all(math.isfinite(v) for v in cmd):
            return rp.Control(self._seq, thrust, 0.0, 0.0, 0.0)
        return rp.Control(self._seq, cmd.thrust_n, cmd.roll_accel_rad_s2, cmd.pitch_accel_rad_s2, 0.0)

    def disarm_on_ground(self) -> None:
        """After a preflight refusal that came after ARM: DISARM (the rig is on the ground)."""
        if self._armed_sent and self.flags & RigFlags.ARMED:
            self._disarm_landed("arming", "disarmed after the preflight refusal")

    def _level(self, thrust_n: float) -> None:
        """A level control frame at ``thrust_n`` (attitude PD of the safety envelope)."""
        s = self.estimator.state()
        cmd = self.envelope.level(s, thrust_n)
        self._control_frame(cmd.thrust_n, cmd.roll_accel_rad_s2, cmd.pitch_accel_rad_s2, 0.0)

    def _step_idle(self, thrust_n: float, *, level: bool = False) -> None:
        """One control frame outside the mission loop (level at ``thrust_n``, or all zero) and one
        control period: in lockstep until the step's telemetry is back (at most 0.5 s of wall time),
        in real time 10 ms."""
        before = self._time_ns
        if level:
            self._level(thrust_n)
        else:
            self._control_frame(thrust_n, 0.0, 0.0, 0.0)
        wait_end = time.monotonic() + (0.5 if self.lockstep else 0.01)
        while time.monotonic() < wait_end and not (self.lockstep and self._time_ns > before):
            self._pump_wait(0.005)

    def _check_interrupt(self) -> None:
        if self.interrupts.count:
            raise PreflightRefused("interrupted before arming")

    # ------------------------------------------------------------------ preflight
    def preflight(self) -> None:
        """Everything before arming; raises :class:`PreflightRefused` or :class:`LinkError`."""
        fc = self.flight_cfg
        status = None
        end = time.monotonic() + 5.0
        while status is None and time.monotonic() < end:
            self._check_interrupt()
            self._heartbeat()
            status = self.link.wait(lambda m: isinstance(m, rp.Status), 0.5, self._handle)
        if status is None:
            raise LinkError(f"no STATUS from the rig on {self.link.url} within 5 s (is it powered, the baud rate "
                            f"{self.link.baud}?)")
        self.event("link", f"rig on {self.link.url}: protocol {status.protocol_version}, firmware "
                           f"{status.fw_major}.{status.fw_minor}.{status.fw_patch}, state {RigState(status.state).name}")
        if status.protocol_version != rp.PROTOCOL_VERSION:
            raise PreflightRefused(f"the rig speaks protocol version {status.protocol_version}, this ground station "
                                   f"{rp.PROTOCOL_VERSION}")
        # A round trip answered to the heartbeat just sent (the first STATUS may be the greeting).
        self._heartbeat()
        self.link.wait(lambda m: isinstance(m, rp.Status) and self.rtt_ms is not None, 1.0, self._handle)
        if self.rtt_ms is not None:
            self.event("link", f"round trip {self.rtt_ms:.1f} ms (HEARTBEAT -> STATUS)")
            if self.rtt_ms / 1000.0 > fc.telemetry_stale_s:
                raise PreflightRefused(f"link round trip {self.rtt_ms:.0f} ms exceeds the telemetry stale timeout "
                                       f"({fc.telemetry_stale_s * 1000:.0f} ms)")
        if self.state_rig == RigState.CUTOFF:
            causes = [f.name for f in RigFlags if f & rp.CUTOFF_CAUSES and f & self.flags]
            self.event("warning", f"a cut-off is latched ({', '.join(causes)}); clearing it with DISARM")
            self._command(rp.Disarm, "DISARM")
        elif self.state_rig in (RigState.ARMED, RigState.DESCENT):
            raise PreflightRefused(f"the rig is already {RigState(self.state_rig).name.lower()}; gcs fly starts from "
                                   "a disarmed rig on the ground")
        # Fresh telemetry and 0.5 s of it into the estimate (its velocities settle) before arming.
        # In lockstep the rig sends telemetry only when a control frame moves its time: zero-thrust
        # frames (ignored while disarmed) do that.
        end = time.monotonic() + 5.0
        first_ns = None
        while time.monotonic() < end:
            self._check_interrupt()
            if self.lockstep:
                self._step_idle(0.0)  # one step, and its telemetry (not wall time: same seed, same flight)
            else:
                self._pump_wait(0.02)
            if self.estimator.initialised and self._fresh(self.now_ns(), fc.telemetry_stale_s):
                first_ns = self._time_ns if first_ns is None else first_ns
                if self._time_ns - first_ns >= 500_000_000:
                    break
        else:
            raise PreflightRefused("no fresh TELEMETRY from the rig within 5 s")
        if not self.flags & RigFlags.LANDED:
            raise PreflightRefused(f"the rig is not resting on the ground (altitude {self.estimator.state().z:.2f} m)")
        self._check_interrupt()
        self._armed_sent = True
        res = self._command(rp.Arm, "ARM")
        if res != AckResult.ACCEPTED:
            raise PreflightRefused(f"arming refused: {res.name}")
        # Armed from now on (the next TELEMETRY says so too; in lockstep it comes with the first step).
        self._flags(self.flags | RigFlags.ARMED)

    # ------------------------------------------------------------------ the loop's hooks
    def _fresh(self, now_ns: int, stale_s: float) -> bool:
        return self._last_rx_ns is not None and (now_ns - self._last_rx_ns) / 1e9 <= stale_s

    def _control_lost(self, t_s: float) -> str | None:
        f = self.flags
        if f & RigFlags.CUTOFF:
            causes = [x.name for x in RigFlags if x & rp.CUTOFF_CAUSES and x & f]
            return f"safety cut-off: {', '.join(causes) or 'unknown cause'}"
        if f & RigFlags.WATCHDOG:
            return "the rig's link watchdog is landing it"
        if not f & RigFlags.ARMED:
            return "disarmed"
        return None

    def _send_command(self, state: State, cmd: Command) -> None:
        self._control_frame(cmd.thrust_n, cmd.roll_accel_rad_s2, cmd.pitch_accel_rad_s2, cmd.yaw_accel_rad_s2)

    def _housekeeping(self, k: int) -> None:
        self._heartbeat()

    def _landed(self) -> bool:
        return bool(self.flags & RigFlags.LANDED)

    def _mission_origin(self, state: State) -> tuple[float, float, float]:
        # The ultrasonic reads the height above the ground: the mission's altitudes are absolute.
        return (state.x, 0.0, 0.0)

    def _wait(self, predicate: Callable[[], bool], timeout_s: float, *, level_thrust_n: float | None) -> bool:
        """Pump until ``predicate`` (wall time ``timeout_s``), sending level frames at ``level_thrust_n``
        every control period (None: send nothing; in lockstep nothing moves then)."""
        end = time.monotonic() + timeout_s
        next_hb = time.monotonic() + 1.0
        while time.monotonic() < end:
            self._pump()
            if predicate():
                return True
            if self.interrupts.count >= 3:
                return False
            if time.monotonic() >= next_hb:
                next_hb += 1.0
                self._heartbeat()
            if level_thrust_n is not None:
                self._step_idle(level_thrust_n, level=True)
            else:
                self._pump_wait(0.01)
        return predicate()

    def _disarm_landed(self, kind: str = "landed", text: str = "landed and disarmed") -> None:
        """DISARM (motors off) and, once acknowledged, the event ``kind``/``text``."""
        try:
            if self._command(rp.Disarm, "DISARM") == AckResult.ACCEPTED:
                self.event(kind, text)
        except LinkError as exc:
            self.event("warning", f"DISARM not acknowledged: {exc}")

    def _finish(self, reason: str) -> None:
        fc = self.flight_cfg
        descend = 0.9 * self.model.hover_thrust_n
        gone = self._vehicle_gone()
        if gone is not None:
            self.event("warning", f"{gone}: nothing left to land")
            return
        if reason == "vehicle_took_over":
            self._wait(lambda: not self.flags & RigFlags.ARMED, fc.land_timeout_s, level_thrust_n=None)
            if self.flags & RigFlags.CUTOFF:
                self._disarm_landed("phase", "cut-off cleared with DISARM (motors were off)")
            elif not self.flags & RigFlags.ARMED:
                self.event("landed", "disarmed by the rig")
            return
        if reason == "telemetry_lost":
            if not self.lockstep:
                # The rig's watchdog levels it, descends and disarms on the ground by itself.
                self.event("phase", "telemetry lost: control stopped, the rig's link watchdog lands it")
                ok = self._wait(lambda: self._fresh(self.now_ns(), fc.telemetry_stale_s) and self._landed(),
                                fc.land_timeout_s, level_thrust_n=None)
                if ok and self.flags & RigFlags.ARMED:
                    self._disarm_landed()
                elif ok:
                    self.event("landed", "landed and disarmed by the rig's watchdog")
                else:
                    self.event("warning", f"no telemetry within {fc.land_timeout_s:g} s: touchdown not seen")
                return
            # In lockstep the rig's time moves only with control frames (its watchdog never trips):
            # level frames below hover for land_timeout_s of rig time bring it down, then DISARM.
            self.event("phase", "telemetry lost: level descent at 90 % of hover thrust")
            frames = int(round(fc.land_timeout_s / self.config.experiment.ts_s))
            for _ in range(frames):
                self._pump()
                if self._landed() and self._fresh(self.now_ns(), fc.telemetry_stale_s):
                    break
                if self._fresh(self.now_ns(), fc.telemetry_stale_s):
                    self._level(descend)
                else:  # no attitude to level on: hold the angular rates (no angular acceleration)
                    self._control_frame(descend, 0.0, 0.0, 0.0)
                self._pump_wait(0.002)
            self._disarm_landed()
            return
        if not self._landed():
            # Geofence, a second Ctrl-C, or a descent that did not reach the ground: level, below hover.
            self.event("phase", "level descent at 90 % of hover thrust")
            if not self._wait(self._landed, fc.land_timeout_s, level_thrust_n=descend):
                self.event("warning", f"not on the ground {fc.land_timeout_s:g} s after the descent began; "
                                      "DISARM anyway (motors off)")
        self._disarm_landed()

    def _link_summary(self) -> dict:
        c = self.link.counters
        st = self.status
        out = {"received": c.frames, "sent": self.link.sent, "bad_data": c.errors,
               "received_bytes": self.link.received_bytes, "sent_bytes": self.link.sent_bytes,
               "decoder": c.as_dict(), "rtt_ms": self.rtt_ms, "blocked": dict(self.guard.blocked),
               "telemetry_rejected": dict(self.validator.rejected)}
        if st is not None:
            out["rig_rx"] = {"frames": st.rx_frames, "checksum_errors": st.rx_checksum_errors,
                             "length_errors": st.rx_length_errors, "truncated_frames": st.rx_truncated_frames,
                             "discarded_bytes": st.rx_discarded_bytes, "cutoffs": st.cutoffs,
                             "watchdog_trips": st.watchdog_trips}
        return out

    def fly(self) -> FlightResult:
        """Preflight must have passed.  Flies the mission, descends, disarms; returns the summary."""
        return self.run_mission()
