"""ArduCopter's flight controller in the built-in SITL: :class:`ArduCopterAutopilot`.

It is the built-in :class:`~sitl.copter.autopilot.Autopilot` (modes, arming checks, land detector,
auto-disarm, battery failsafe) with ArduCopter's own pieces in place of the simple ones:

* inner loops: :class:`~.attitude.AttitudeControl` and :class:`~.motors.Motors` (normalised rate
  PIDs, mixer, thrust curve, arming delay and spool-up) instead of the torque-level loops;
* guided attitude (``ModeGuided::angle_control_run``): the last quaternion rolled forward by its
  body rates every loop; a positive thrust on the ground spools the motors up and takes off once
  the throttle is unlimited; on ``GUID_TIMEOUT`` the target becomes level at the target's heading
  with zero rates and the thrust a zero climb rate (ArduCopter holds altitude: no LAND, no text);
* readiness and status (:mod:`.status`): arming refused with "PreArm: ..." until the EKF is ready,
  no LOCAL_POSITION_NED before, HEARTBEAT base_mode / system_status as the firmware's.
"""

from __future__ import annotations

import math

from quadrotor.frames import euler_to_quaternion, quaternion_to_euler
from sitl.copter.ardupilot_emulation.attitude import AttitudeControl
from sitl.copter.ardupilot_emulation.motors import Motors, SpoolState
from sitl.copter.ardupilot_emulation.status import (BASE_MODE_ARMED, BASE_MODE_DISARMED, IDENTITY, Readiness)
from sitl.copter.autopilot import SEVERITY_CRITICAL, SEVERITY_INFO, Autopilot
from sitl.copter.battery import BatteryState
from sitl.copter.control import angle_boost
from sitl.copter.modes import GUIDED_MODES
from sitl.copter.sensors import ImuReading, NavReading

__all__ = ["ArduCopterAutopilot"]


class ArduCopterAutopilot(Autopilot):
    """The emulated ArduCopter.

    Parameters
    ----------
    vehicle : VehicleParams
    params : ParamStore
        With the emulation's parameters (:func:`~.vehicle.emulation_params`).
    ekf_ready_s : float
        Simulated time after boot before the EKF is ready [s].
    dt : float
        Loop period [s] (2.5 ms at 400 Hz).
    """

    identity = IDENTITY

    def __init__(self, vehicle, params, ekf_ready_s: float, dt: float) -> None:
        self.att = AttitudeControl(params, dt)
        self.motors = Motors(params, vehicle.rotors.max_thrust_n, dt)
        self.readiness = Readiness(ekf_ready_s)
        self._desired_q: tuple[float, float, float, float] | None = None
        self._timed_out = False
        self._now_s = 0.0
        super().__init__(vehicle, params, 0.0)
        params.add_listener(lambda name, value: self.att.refresh() if name.startswith(("ATC_", "INS_")) else None)

    # ------------------------------------------------------------------ status
    @property
    def system_status(self) -> int:
        """MAV_STATE as ArduCopter: BOOT, STANDBY (landed, armed or not), ACTIVE, CRITICAL."""
        if self.readiness.booting(self._now_s):
            return 1
        if not self.armed or self.land_complete:
            return 3
        return 5 if self.failsafe else 4

    @property
    def base_mode(self) -> int:
        """81 disarmed, 209 armed."""
        return BASE_MODE_ARMED if self.armed else BASE_MODE_DISARMED

    def position_ready(self, now_ns: int) -> bool:
        """LOCAL_POSITION_NED only once the EKF is ready."""
        return self.readiness.ready(now_ns * 1e-9)

    # ------------------------------------------------------------------ commands
    def arm(self, now_ns: int, force: bool = False) -> tuple[bool, str]:
        """Refused with "PreArm: ..." until the EKF is ready, then the built-in checks; starts the arming delay."""
        reason = "" if force else self.readiness.prearm_reason(now_ns * 1e-9)
        if reason and not self.armed:
            self.say(SEVERITY_CRITICAL, f"PreArm: {reason}")
            return False, reason
        was = self.armed
        ok, why = super().arm(now_ns, force)
        if ok and not was:
            self.motors.arm(now_ns * 1e-9)
            self.att.reset_rate_i()
            self._desired_q = None
            self._timed_out = False
        return ok, why

    def disarm(self, now_ns: int, force: bool = False, why: str = "") -> tuple[bool, str]:
        """As the built-in one; the motors stop."""
        ok, reason = super().disarm(now_ns, force, why)
        if ok:
            self.motors.disarm()
        return ok, reason

    def _take(self, target, reason: str) -> tuple[bool, str]:
        ok, why = super()._take(target, reason)
        if ok:
            self._desired_q = target.q
            self._timed_out = False
        return ok, why

    def set_actuator_controls(self, controls, now_ns: int) -> tuple[bool, str]:
        """Ignored: ArduCopter has no SET_ACTUATOR_CONTROL_TARGET handler."""
        return self._take(None, "SET_ACTUATOR_CONTROL_TARGET not handled")

    def _guided_timeout(self, now_ns: int) -> None:
        self._timed_out = True

    # ------------------------------------------------------------------ loop
    def update(self, now_ns: int, dt: float, imu: ImuReading, nav: NavReading,
               battery: BatteryState) -> tuple[float, float, float, float]:
        """One 400 Hz loop: the gyro filter, the readiness messages, then the built-in mode logic."""
        self._now_s = now_ns * 1e-9
        self.att.filter_gyro((imu.p, imu.q, imu.r))
        for text in self.readiness.news(self._now_s):
            self.say(SEVERITY_INFO, text)
        return super().update(now_ns, dt, imu, nav, battery)

    def _q_body(self) -> tuple[float, float, float, float]:
        i = self._last_imu
        return (1.0, 0.0, 0.0, 0.0) if i is None else (i.qw, i.qx, i.qy, i.qz)

    def _output(self, throttle: float) -> tuple[float, float, float, float]:
        roll, pitch, yaw = self.att.rate_controller_run(self.motors.limit_rpy)
        mix = self._p("ATC_THR_MIX_MAX")
        avg_max = max(throttle, throttle * (1.0 - mix) + self._hover * mix)
        self.throttle = throttle
        self._last_mix = None
        self.att_target_q = self.att.attitude_target
        self.rate_target = self.att.rate_demand
        return self.motors.output(self._now_s, roll, pitch, yaw, throttle, avg_max)

    def _ground_idle(self) -> tuple[float, float, float, float]:
        """``make_safe_ground_handling``: ground idle, the rate integrators relaxed towards 0 (0.5 s), the
        heading target reset while idle, a level target; the loops run on the estimated attitude."""
        self._reset_loops()
        q = self._q_body()
        self.att.relax_rate_i()
        if self.motors.spool in (SpoolState.SHUT_DOWN, SpoolState.GROUND_IDLE):
            self.att.reset_yaw_target(q)
        self.att.input_level(q)
        self.motors.desired = SpoolState.GROUND_IDLE
        return self._output(0.0)

    def _fly(self, q_target, rate_ff, rates_only: bool, throttle: float, boost: bool, dt: float,
             imu: ImuReading) -> tuple[float, float, float, float]:
        self.motors.desired = SpoolState.THROTTLE_UNLIMITED
        qb = (imu.qw, imu.qx, imu.qy, imu.qz)
        if rates_only:
            self.att.input_rate_bf(rate_ff, qb)
        else:
            self._desired_q = self.att.input_quaternion(q_target, rate_ff, qb)
        if boost and self._boost:
            throttle = angle_boost(throttle, math.cos(self.att.thrust_angle))
        return self._output(min(max(throttle, 0.0), 1.0))

    def _run_mode(self, now_ns: int, dt: float, imu: ImuReading, nav: NavReading) -> tuple[float, float, float, float]:
        if self.mode not in GUIDED_MODES:
            return super()._run_mode(now_ns, dt, imu, nav)
        t = self.target
        if t is None or self._timed_out or t.kind == "actuator":
            yaw = quaternion_to_euler(self.att.attitude_target)[2] if t is not None else self._yaw_hold
            q, rates, rates_only, use_thrust, value = euler_to_quaternion(0.0, 0.0, yaw), (0.0, 0.0, 0.0), False, \
                False, 0.0
        else:
            q = self._desired_q if self._desired_q is not None else t.q
            rates, rates_only, use_thrust, value = t.rates, t.kind == "rates", t.use_thrust, t.value
        if self.land_complete:
            if value <= 0.0:
                return self._ground_idle()
            # take-off (zero_throttle_and_relax_ac): zero throttle and a level target, the rate loop running
            # (integrators too) until the motors run unlimited; a pinned vehicle whose estimated attitude
            # is not level winds them up, and rolls when the ground lets go (docs/FIDELITY.md)
            self.att.input_level(self._q_body())
            self.motors.desired = SpoolState.THROTTLE_UNLIMITED
            cmd = self._output(0.0)
            if self.motors.spool == SpoolState.THROTTLE_UNLIMITED:
                self.land_complete = False
                self._landed_since_ns = None
                self._reset_loops()
            return cmd
        thr = value if use_thrust else self._climb_throttle(value, dt, nav)
        return self._fly(q, rates, rates_only, thr, use_thrust, dt, imu)
