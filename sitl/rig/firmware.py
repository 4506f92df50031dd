"""The 4-DOF rig's onboard autopilot: the 200 Hz loop, arming, safety cut-off, link watchdog.

Pure logic without I/O: :class:`RigFirmware` takes decoded messages
(:meth:`~RigFirmware.handle`) and advances one 5 ms tick at a time
(:meth:`~RigFirmware.tick`), returning the messages to send.
:class:`sitl.rig.server.RigServer` puts it behind a serial port.

Each tick: (1) link watchdog, (2) motor thrusts from the latest control
frame (or the descent controller, or off), (3) the plant over 5 ms,
(4) safety checks on the new state, (5) sensors and one TELEMETRY frame
stamped with the tick's end; every whole second of rig time also a STATUS.

States (:class:`~quadrotor.rig_protocol.RigState`):

* DISARMED: motors off.  ARM is accepted only when landed (resting on the
  ground, z = 0 and vz = 0); the motors then idle (zero thrust) until the
  first control frame.
* ARMED: the latest CONTROL (thrust and angular accelerations, mixed to the
  four motors and each motor clipped to its range) or CONTROL_PWM is applied
  every tick until the next one.
* CUTOFF: the safety cut-off tripped: motors off, the causes are in the
  flags, latched until DISARM (ARM is refused with DENIED_CUTOFF; DISARM then
  ARM re-arms).  Trips, checked while armed: |vz| or |vx| above its limit,
  |roll rate| or |pitch rate| above its limit, altitude above its limit
  (all on the true state: an ideal onboard detector), and a CONTROL demand
  outside the command limits or not finite (on receipt).
* DESCENT: no control frame for ``watchdog_timeout_s`` while armed (counted
  from arming or the last control frame): the rig levels itself and descends
  at ``descent_rate_m_s`` (onboard vertical-speed loop); on the ground it
  disarms.  A control frame before touchdown returns to ARMED.

DISARM stops the motors at once, in the air too (the kill switch), and
clears a latched cut-off.  Control frames received while disarmed or cut
off are ignored (counted) but their ``seq`` is still echoed in TELEMETRY.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import Any

from quadrotor import rig_protocol as rp
from quadrotor.rig_protocol import AckResult, RigFlags, RigState
from quadrotor.state import State
from sitl.rig.dynamics import RigParams, mix, pwm_to_thrust, step
from sitl.rig.sensors import RigSensorParams, RigSensors

__all__ = ["RigSafetyParams", "RigFirmware", "FIRMWARE_VERSION", "TICK_NS"]

#: Version reported in STATUS.
FIRMWARE_VERSION = (1, 0, 0)
#: The onboard loop period: 200 Hz [ns].
TICK_NS = 5_000_000
_STATUS_PERIOD_NS = 1_000_000_000


@dataclass(frozen=True)
class RigSafetyParams:
    """Limits of the safety cut-off, command limits, link watchdog and descent.

    Attributes
    ----------
    max_vz_m_s, max_vx_m_s : float
        Cut-off above these speeds.
    max_angular_rate_rad_s : float
        Cut-off above this roll or pitch rate.
    max_altitude_m : float
        Cut-off above this altitude.
    max_thrust_n : float
        CONTROL thrust must be in ``[0, max_thrust_n]``.
    max_angular_accel_rad_s2 : float
        Each CONTROL angular acceleration must be within +-this.
    watchdog_timeout_s : float
        Armed without a control frame this long: controlled descent.
    descent_rate_m_s : float
        Sink rate of the controlled descent.
    descent_gain_1_s : float
        Vertical-speed loop gain of the descent [1/s].
    level_kp_1_s2, level_kd_1_s : float
        Attitude PD that levels the rig during the descent.
    """

    max_vz_m_s: float = 1.5
    max_vx_m_s: float = 1.5
    max_angular_rate_rad_s: float = 10.0
    max_altitude_m: float = 1.0
    max_thrust_n: float = 24.5
    max_angular_accel_rad_s2: float = 200.0
    watchdog_timeout_s: float = 0.5
    descent_rate_m_s: float = 0.3
    descent_gain_1_s: float = 4.0
    level_kp_1_s2: float = 100.0
    level_kd_1_s: float = 20.0

    def __post_init__(self) -> None:
        for name in ("max_vz_m_s", "max_vx_m_s", "max_angular_rate_rad_s", "max_altitude_m", "max_thrust_n",
                     "max_angular_accel_rad_s2", "watchdog_timeout_s", "descent_rate_m_s", "descent_gain_1_s",
                     "level_kp_1_s2", "level_kd_1_s"):
            v = getattr(self, name)
            if not (v > 0 and math.isfinite(v)):
                raise ValueError(f"{name} must be > 0 and finite, got {v!r}")


def _within(value: float, lo: float, hi: float) -> bool:
    tol = 1e-6 * max(1.0, abs(lo), abs(hi))  # float32 rounding of a demand saturated at the limit
    return math.isfinite(value) and lo - tol <= value <= hi + tol


class RigFirmware:
    """The emulated onboard autopilot of the 4-DOF rig (see the module docstring).

    Parameters
    ----------
    params : RigParams or None
    sensors : RigSensorParams or None
    safety : RigSafetyParams or None
    seed : int
        Seeds the sensor noise.
    rx_counters : DecoderCounters or None
        The serial decoder's counters, reported in STATUS.
    initial : State or None
        Initial true state (default: landed at the origin).
    """

    def __init__(self, params: RigParams | None = None, sensors: RigSensorParams | None = None,
                 safety: RigSafetyParams | None = None, seed: int = 0,
                 rx_counters: rp.DecoderCounters | None = None, initial: State | None = None) -> None:
        self.params = params or RigParams()
        self.safety = safety or RigSafetyParams()
        self.sensors = RigSensors(sensors or RigSensorParams(), random.Random(f"{seed}/rig/sensors"))
        self.rx_counters = rx_counters if rx_counters is not None else rp.DecoderCounters()
        self._reduced = self.params.reduced
        self.plant = initial if initial is not None else State()
        self.time_ns = 0
        self.state = RigState.DISARMED
        self.cut_causes = RigFlags(0)
        self.motors_n: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
        self._demand: tuple[float, float, float] | tuple[float, float, float, float] | None = None
        self._pwm_mode = False
        self._last_control_ns = 0
        self._tick_flags = RigFlags(0)
        self.control_seq = 0
        self.controls_applied = 0
        self.controls_ignored = 0
        self.cutoffs = 0
        self.watchdog_trips = 0
        self.heartbeat_echo_us = 0
        self.ticks = 0
        self.last_reading = self.sensors.measure(self.plant)
        if self.last_reading.altitude_out_of_range:
            self._tick_flags = RigFlags.ALT_OUT_OF_RANGE

    # ------------------------------------------------------------------ properties
    @property
    def time_s(self) -> float:
        """Rig time [s]."""
        return self.time_ns * 1e-9

    @property
    def time_us(self) -> int:
        """Rig time as sent [µs], modulo 2**32."""
        return (self.time_ns // 1000) & 0xFFFFFFFF

    @property
    def landed(self) -> bool:
        """Resting on the ground (true state)."""
        return self.plant.z <= 1e-9 and abs(self.plant.vz) <= 1e-9

    @property
    def motors_on(self) -> bool:
        return self.state in (RigState.ARMED, RigState.DESCENT)

    def flags(self) -> RigFlags:
        """The current :class:`RigFlags`."""
        f = self._tick_flags | self.cut_causes
        if self.motors_on:
            f |= RigFlags.ARMED
        if self.state == RigState.CUTOFF:
            f |= RigFlags.CUTOFF
        if self.state == RigState.DESCENT:
            f |= RigFlags.WATCHDOG
        if self.landed:
            f |= RigFlags.LANDED
        if self._pwm_mode:
            f |= RigFlags.PWM_MODE
        return f

    # ------------------------------------------------------------------ messages
    def handle(self, msg: rp.Message) -> tuple[list[rp.Message], bool]:
        """Apply a message from the PC.

        Returns
        -------
        replies : list of messages
            ACK for ARM / DISARM, STATUS for HEARTBEAT.
        is_control : bool
            True for CONTROL / CONTROL_PWM (in lockstep they advance time).
        """
        if isinstance(msg, rp.Control):
            self._control(msg.seq, (msg.thrust_n, msg.roll_accel_rad_s2, msg.pitch_accel_rad_s2,
                                    msg.yaw_accel_rad_s2), pwm=False)
            return [], True
        if isinstance(msg, rp.ControlPwm):
            self._control(msg.seq, tuple(pwm_to_thrust(p, self.params) for p in msg.pwm), pwm=True)
            return [], True
        if isinstance(msg, rp.Arm):
            return [rp.Ack(rp.Arm.TYPE, msg.seq, self.arm())], False
        if isinstance(msg, rp.Disarm):
            return [rp.Ack(rp.Disarm.TYPE, msg.seq, self.disarm())], False
        if isinstance(msg, rp.Heartbeat):
            self.heartbeat_echo_us = msg.time_us
            return [self.status()], False
        return [], False

    def _control(self, seq: int, values: tuple[float, ...], pwm: bool) -> None:
        self.control_seq = seq
        if not self.motors_on:
            self.controls_ignored += 1
            return
        if not pwm:
            s = self.safety
            thrust, *accels = values
            if not (_within(thrust, 0.0, s.max_thrust_n)
                    and all(_within(a, -s.max_angular_accel_rad_s2, s.max_angular_accel_rad_s2) for a in accels)):
                self.controls_ignored += 1
                self._cut(RigFlags.CUT_COMMAND)
                return
            values = tuple(values[:3])
        self._demand = values  # type: ignore[assignment]
        self._pwm_mode = pwm
        self._last_control_ns = self.time_ns
        self.controls_applied += 1
        if self.state == RigState.DESCENT:
            self.state = RigState.ARMED

    def arm(self) -> AckResult:
        """ARM: accepted when landed and no cut-off is latched."""
        if self.motors_on:
            return AckResult.ACCEPTED
        if self.state == RigState.CUTOFF:
            return AckResult.DENIED_CUTOFF
        if not self.landed:
            return AckResult.DENIED_NOT_LANDED
        self.state = RigState.ARMED
        self._demand = None
        self._pwm_mode = False
        self._last_control_ns = self.time_ns
        return AckResult.ACCEPTED

    def disarm(self) -> AckResult:
        """DISARM: motors off at once; clears a latched cut-off."""
        self.state = RigState.DISARMED
        self.cut_causes = RigFlags(0)
        self._demand = None
        self.motors_n = (0.0, 0.0, 0.0, 0.0)
        return AckResult.ACCEPTED

    def _cut(self, causes: RigFlags) -> None:
        self.state = RigState.CUTOFF
        self.cut_causes = causes
        self._demand = None
        self.motors_n = (0.0, 0.0, 0.0, 0.0)
        self.cutoffs += 1

    # ------------------------------------------------------------------ the 200 Hz loop
    def _descent_motors(self) -> tuple[tuple[float, float, float, float], bool]:
        s, st, p = self.safety, self.plant, self.params
        tilt = max(0.5, math.cos(st.roll) * math.cos(st.pitch))
        thrust = p.mass_kg * (p.gravity_m_s2 + s.descent_gain_1_s * (-s.descent_rate_m_s - st.vz)) / tilt
        a_roll = -s.level_kp_1_s2 * st.roll - s.level_kd_1_s * st.roll_rate
        a_pitch = -s.level_kp_1_s2 * st.pitch - s.level_kd_1_s * st.pitch_rate
        return mix(thrust, a_roll, a_pitch, p)

    def _motors(self) -> tuple[tuple[float, float, float, float], bool]:
        if self.state == RigState.ARMED:
            d = self._demand
            if d is None:
                return (0.0, 0.0, 0.0, 0.0), False
            if len(d) == 4:
                return d, False  # type: ignore[return-value]
            return mix(d[0], d[1], d[2], self.params)
        if self.state == RigState.DESCENT:
            return self._descent_motors()
        return (0.0, 0.0, 0.0, 0.0), False

    def _check_safety(self) -> None:
        st, s = self.plant, self.safety
        causes = RigFlags(0)
        if abs(st.vz) > s.max_vz_m_s:
            causes |= RigFlags.CUT_VELOCITY_Z
        if abs(st.vx) > s.max_vx_m_s:
            causes |= RigFlags.CUT_VELOCITY_X
        if abs(st.roll_rate) > s.max_angular_rate_rad_s or abs(st.pitch_rate) > s.max_angular_rate_rad_s:
            causes |= RigFlags.CUT_ANGULAR_RATE
        if st.z > s.max_altitude_m:
            causes |= RigFlags.CUT_ALTITUDE
        if causes:
            self._cut(causes)

    def tick(self) -> list[rp.Message]:
        """Advance 5 ms; returns TELEMETRY (and STATUS on a whole second)."""
        if self.state == RigState.ARMED and self.time_ns - self._last_control_ns > self.safety.watchdog_timeout_s * 1e9:
            self.state = RigState.DESCENT
            self.watchdog_trips += 1
        motors, saturated = self._motors()
        self.motors_n = motors
        res = step(self.plant, motors, TICK_NS * 1e-9, self.params, self._reduced)
        self.plant = res.state
        self.time_ns += TICK_NS
        self.ticks += 1
        if self.state == RigState.DESCENT and self.landed:
            self.disarm()
        if self.motors_on:
            self._check_safety()
        reading = self.sensors.measure(self.plant)
        self.last_reading = reading
        f = RigFlags(0)
        if saturated:
            f |= RigFlags.MOTOR_SATURATED
        if res.roll_at_stop:
            f |= RigFlags.ROLL_AT_STOP
        if res.pitch_at_stop:
            f |= RigFlags.PITCH_AT_STOP
        if reading.altitude_out_of_range:
            f |= RigFlags.ALT_OUT_OF_RANGE
        self._tick_flags = f
        out: list[rp.Message] = [rp.Telemetry(
            self.time_us, reading.roll_rad, reading.pitch_rad, reading.yaw_rad, reading.roll_rate_rad_s,
            reading.pitch_rate_rad_s, reading.yaw_rate_rad_s, reading.x_m, int(round(reading.altitude_m * 1000)),
            self.flags(), self.control_seq)]
        if self.time_ns % _STATUS_PERIOD_NS == 0:
            out.append(self.status())
        return out

    def status(self) -> rp.Status:
        """A STATUS message of the current state."""
        c = self.rx_counters
        m32 = 0xFFFFFFFF
        return rp.Status(self.time_us, self.state, rp.PROTOCOL_VERSION, *FIRMWARE_VERSION, self.flags(),
                         c.frames & m32, c.checksum_errors & m32, c.length_errors & m32, c.unknown_types & m32,
                         c.invalid_values & m32, c.truncated_frames & m32, c.discarded_bytes & m32,
                         self.cutoffs & 0xFFFF, self.watchdog_trips & 0xFFFF, self.heartbeat_echo_us)

    def snapshot(self) -> dict[str, Any]:
        """State and counters (truth), for tests and tools."""
        return {
            "time_s": self.time_s, "state": self.state, "flags": self.flags(), "cut_causes": self.cut_causes,
            "plant": self.plant, "motors_n": self.motors_n, "landed": self.landed, "ticks": self.ticks,
            "control_seq": self.control_seq, "controls_applied": self.controls_applied,
            "controls_ignored": self.controls_ignored, "cutoffs": self.cutoffs,
            "watchdog_trips": self.watchdog_trips, "reading": self.last_reading,
        }
