"""ArduCopter's motor output (``AP_MotorsMulticopter`` + ``AP_MotorsMatrix``, quad X) and arming delay.

After arming the motors stay stopped for ``ARMING_DELAY_S`` (2 s, ArduCopter's ``ARMING_DELAY_SEC``:
the interlock is off), then spool up: ground idle is reached over ``MOT_SPOOL_TIME``, then, once a
positive thrust is demanded, the thrust limit ramps from 0 at ``1 / MOT_SPOOL_TIME`` until it
covers the demand (throttle unlimited).  Spool states: SHUT_DOWN, GROUND_IDLE, SPOOLING_UP,
THROTTLE_UNLIMITED, SPOOLING_DOWN.

Mixing (``output_armed_stabilizing``): roll and pitch first, yaw within the room left (at least
``MOT_YAW_HEADROOM``/1000), everything scaled down if the spread exceeds the range, then the
collective fitted into what is left.  The per-motor thrusts (0..1 of full) go through
``MOT_THST_EXPO``, ``MOT_SPIN_MIN``/``MAX`` to an actuator value and ArduPilot's SITL motor
turns that back into thrust along the same curve, so thrust is linear in the mixer's output;
the rotor thrust is ``output x full thrust`` [N] (below ``MOT_SPIN_MIN`` it is zero).
"""

from __future__ import annotations

import math
from enum import IntEnum

__all__ = ["Motors", "SpoolState", "ARMING_DELAY_S", "MOTOR_FACTORS", "thrust_to_actuator", "actuator_to_thrust"]

ARMING_DELAY_S = 2.0
#: (roll, pitch, yaw) factors of motors 1..4 (AP_MotorsMatrix QUAD X, normalised to 0.5).
MOTOR_FACTORS = ((-0.5, 0.5, 0.5), (0.5, -0.5, 0.5), (0.5, 0.5, -0.5), (-0.5, -0.5, -0.5))


class SpoolState(IntEnum):
    """AP_Motors::SpoolState."""

    SHUT_DOWN = 0
    GROUND_IDLE = 1
    SPOOLING_UP = 2
    THROTTLE_UNLIMITED = 3
    SPOOLING_DOWN = 4


def thrust_to_actuator(thrust: float, expo: float, spin_min: float, spin_max: float) -> float:
    """Actuator value (0..1 of the PWM range) for a thrust (0..1 of full), MOT_THST_EXPO's curve."""
    t = min(1.0, max(0.0, thrust))
    e = min(1.0, max(-1.0, expo))
    ratio = t if e == 0.0 else ((e - 1.0) + math.sqrt((1.0 - e) ** 2 + 4.0 * e * t)) / (2.0 * e)
    return spin_min + (spin_max - spin_min) * min(1.0, max(0.0, ratio))


def actuator_to_thrust(actuator: float, expo: float, spin_min: float, spin_max: float) -> float:
    """Thrust (0..1 of full) of an actuator value: ArduPilot SITL's motor, ``(1-e) c + e c^2``."""
    c = min(1.0, max(0.0, (actuator - spin_min) / (spin_max - spin_min)))
    return (1.0 - expo) * c + expo * c * c


class Motors:
    """The four motors of one vehicle.

    Parameters
    ----------
    params : ParamStore
        ``MOT_*`` parameters.
    full_thrust_n : float
        Thrust of one motor at full output [N].
    dt : float
        Loop period [s].
    """

    def __init__(self, params, full_thrust_n: float, dt: float) -> None:
        self.params = params
        self.full_n = full_thrust_n
        self.dt = dt
        self.armed = False
        self.arm_time_s = 0.0
        self.spool = SpoolState.SHUT_DOWN
        self.desired = SpoolState.SHUT_DOWN  # SHUT_DOWN, GROUND_IDLE or THROTTLE_UNLIMITED
        self.spin_up = 0.0
        self.thrust_max = 0.0
        self.limit_rpy = (True, True, True)
        self.limit_throttle_lower = True
        self.throttle_out = 0.0
        self.outputs = (0.0, 0.0, 0.0, 0.0)

    def arm(self, now_s: float) -> None:
        """Armed: stopped for the arming delay, then spooling as desired."""
        self.armed = True
        self.arm_time_s = now_s

    def disarm(self) -> None:
        """Motors off at once."""
        self.armed = False
        self.spool = SpoolState.SHUT_DOWN
        self.spin_up = self.thrust_max = 0.0

    def in_arming_delay(self, now_s: float) -> bool:
        """Still within the 2 s after arming (no thrust yet)."""
        return self.armed and now_s - self.arm_time_s < ARMING_DELAY_S

    def _spool_logic(self, now_s: float, throttle: float) -> None:
        step = self.dt / max(self.params["MOT_SPOOL_TIME"], 0.05)
        s = self.spool
        if not self.armed or self.in_arming_delay(now_s):
            self.spool, self.spin_up, self.thrust_max = SpoolState.SHUT_DOWN, 0.0, 0.0
            return
        if s == SpoolState.SHUT_DOWN:
            if self.desired != SpoolState.SHUT_DOWN:
                self.spool = SpoolState.GROUND_IDLE
        elif s == SpoolState.GROUND_IDLE:
            self._ground_idle(step)
        elif s == SpoolState.SPOOLING_UP:
            if self.desired != SpoolState.THROTTLE_UNLIMITED:
                self.spool = SpoolState.SPOOLING_DOWN
                return
            self.thrust_max += step
            if self.thrust_max >= min(throttle, 1.0):
                self.thrust_max, self.spool = 1.0, SpoolState.THROTTLE_UNLIMITED
        elif s == SpoolState.THROTTLE_UNLIMITED:
            if self.desired != SpoolState.THROTTLE_UNLIMITED:
                self.spool = SpoolState.SPOOLING_DOWN
        else:  # SPOOLING_DOWN
            if self.desired == SpoolState.THROTTLE_UNLIMITED:
                self.spool = SpoolState.SPOOLING_UP
                return
            self.thrust_max -= step
            if self.thrust_max <= 0.0:
                self.thrust_max, self.spool = 0.0, SpoolState.GROUND_IDLE

    def _ground_idle(self, step: float) -> None:
        if self.desired == SpoolState.SHUT_DOWN:
            self.spin_up -= step
            if self.spin_up <= 0.0:
                self.spin_up, self.spool = 0.0, SpoolState.SHUT_DOWN
        elif self.desired == SpoolState.THROTTLE_UNLIMITED:
            self.spin_up += step
            if self.spin_up >= 1.0:
                self.spin_up, self.spool = 1.0, SpoolState.SPOOLING_UP
        else:
            spin_min = self.params["MOT_SPIN_MIN"]
            idle = self.params["MOT_SPIN_ARM"] / spin_min if spin_min > 0 else 0.0
            self.spin_up = min(idle, self.spin_up + step) if self.spin_up < idle else max(idle, self.spin_up - step)
        self.thrust_max = 0.0

    def output(self, now_s: float, roll: float, pitch: float, yaw: float, throttle: float,
               throttle_avg_max: float) -> tuple[float, float, float, float]:
        """One loop: spool logic, then rotor thrusts [N] for the normalised roll, pitch, yaw and throttle."""
        self._spool_logic(now_s, throttle)
        if self.spool in (SpoolState.SHUT_DOWN, SpoolState.GROUND_IDLE):
            self.limit_rpy = (True, True, True)
            self.limit_throttle_lower = True
            self.throttle_out = 0.0
            self.outputs = (0.0, 0.0, 0.0, 0.0)
            return self.outputs
        out = self._mix(roll, pitch, yaw, throttle, throttle_avg_max)
        p = self.params
        expo, lo, hi = p["MOT_THST_EXPO"], p["MOT_SPIN_MIN"], p["MOT_SPIN_MAX"]
        f = self.full_n
        self.outputs = out
        return tuple(f * actuator_to_thrust(thrust_to_actuator(t, expo, lo, hi), expo, lo, hi)  # type: ignore[return-value]
                     for t in out)

    def _mix(self, roll: float, pitch: float, yaw: float, throttle: float,
             throttle_avg_max: float) -> tuple[float, float, float, float]:
        tmax = self.thrust_max
        lim_r = lim_p = lim_y = False
        self.limit_throttle_lower = False
        thr = throttle
        if thr <= 0.0:
            thr = 0.0
            self.limit_throttle_lower = True
        thr = min(thr, tmax)
        avg_max = min(max(throttle_avg_max, thr), tmax)
        best = min(0.5, avg_max)
        rp = [roll * fr + pitch * fp for fr, fp, _ in MOTOR_FACTORS]
        yaw_allowed = 1.0
        for i, (_, _, fy) in enumerate(MOTOR_FACTORS):
            room = 1.0 - (best + rp[i]) if yaw * fy > 0.0 else best + rp[i]
            yaw_allowed = min(yaw_allowed, max(room, 0.0) / abs(fy))
        yaw_allowed = max(yaw_allowed, self.params["MOT_YAW_HEADROOM"] * 0.001)
        if abs(yaw) > yaw_allowed:
            yaw = min(max(yaw, -yaw_allowed), yaw_allowed)
            lim_y = True
        rpy = [rp[i] + yaw * MOTOR_FACTORS[i][2] for i in range(4)]
        low, high = min(rpy), max(rpy)
        scale = 1.0 / (high - low) if high - low > 1.0 else 1.0
        if avg_max + low < 0.0:
            scale = min(scale, -avg_max / low)
        high *= scale
        low *= scale
        best = -low
        adj = thr - best
        if scale < 1.0:
            lim_r = lim_p = lim_y = True
            adj = 0.0
        elif adj < 0.0:
            adj = 0.0
        elif adj > 1.0 - (best + high):
            adj = 1.0 - (best + high)
        base = best + adj
        self.throttle_out = base
        self.limit_rpy = (lim_r, lim_p, lim_y)
        return tuple(min(1.0, max(0.0, base + scale * v)) for v in rpy)  # type: ignore[return-value]
