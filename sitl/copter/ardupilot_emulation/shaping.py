"""ArduPilot's command shaping (``libraries/AP_Math/control.cpp``), one axis, in plain Python.

``sqrt_controller`` is the angle loop's P with a second-order limit (linear within
``limit / p**2`` of the target, a square root beyond, never overshooting in one step);
``attitude_command_model`` is ``AC_AttitudeControl::attitude_command_model``: the jerk-limited
shaping of an angle error (or a rate demand) into an angular velocity and acceleration target,
with the acceleration limit ``ATC_ACC_*_MAX`` and the time constant ``ATC_INPUT_TC``
(jerk = acceleration limit / time constant).  Units: rad, rad/s, rad/s^2, s.
"""

from __future__ import annotations

import math

__all__ = ["sqrt_controller", "sqrt_controller_accel", "shape_accel", "shape_pos_vel_accel",
           "attitude_command_model"]


def _clamp(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else hi if v > hi else v


def sqrt_controller(error: float, p: float, second_ord_lim: float, dt: float) -> float:
    """Rate demand for ``error`` with gain ``p`` [1/s] and limit ``second_ord_lim`` (0 = linear)."""
    if second_ord_lim <= 0.0:
        rate = error * p
    elif p == 0.0:
        rate = math.copysign(math.sqrt(2.0 * second_ord_lim * abs(error)), error) if error else 0.0
    else:
        linear = second_ord_lim / (p * p)
        if error > linear:
            rate = math.sqrt(2.0 * second_ord_lim * (error - linear / 2.0))
        elif error < -linear:
            rate = -math.sqrt(2.0 * second_ord_lim * (-error - linear / 2.0))
        else:
            rate = error * p
    if dt > 0.0:
        lim = abs(error) / dt
        return _clamp(rate, -lim, lim)
    return rate


def sqrt_controller_accel(error: float, rate_cmd: float, rate_state: float, p: float, second_ord_lim: float) -> float:
    """The rate of change of :func:`sqrt_controller`'s demand while closing at ``rate_state``."""
    if rate_cmd * rate_state <= 0.0:
        return 0.0
    if second_ord_lim <= 0.0:
        return -p * rate_state
    if p <= 0.0:
        return 0.0 if rate_cmd == 0.0 else -(second_ord_lim / abs(rate_cmd)) * rate_state
    if abs(error) <= second_ord_lim / (p * p):
        return -p * rate_state
    return 0.0 if rate_cmd == 0.0 else -(second_ord_lim / abs(rate_cmd)) * rate_state


def shape_accel(accel_desired: float, accel: float, jerk_max: float, dt: float) -> float:
    """``accel`` moved towards ``accel_desired`` by at most ``jerk_max dt``."""
    step = jerk_max * dt
    return accel + _clamp(accel_desired - accel, -step, step)


def shape_pos_vel_accel(pos_desired: float, vel_desired: float, accel_desired: float, pos: float, vel: float,
                        accel: float, vel_min: float, vel_max: float, accel_min: float, accel_max: float,
                        jerk_max: float, dt: float, limit_total: bool) -> float:
    """The new acceleration of the jerk-limited square-root command model (AP_Math's 1-D form)."""
    pos_error = pos_desired - pos
    accel_lim = -accel_min if pos_error > 0.0 else accel_max
    k_v = jerk_max / accel_lim
    vel_corr = vel - vel_desired
    vel_corr_cmd = sqrt_controller(pos_error, k_v, accel_lim, dt)
    vel_corr_cmd += sqrt_controller_accel(pos_error, vel_corr_cmd, vel_corr, k_v, accel_lim) / k_v
    if vel_min < 0.0:
        vel_corr_cmd = max(vel_corr_cmd, vel_min)
    if vel_max > 0.0:
        vel_corr_cmd = min(vel_corr_cmd, vel_max)
    vel_target = vel_desired + vel_corr_cmd
    if limit_total:
        if vel_min < 0.0:
            vel_target = max(vel_target, vel_min)
        if vel_max > 0.0:
            vel_target = min(vel_target, vel_max)
    accel_target = _clamp((vel_target - vel) * k_v, accel_min, accel_max) + accel_desired
    if limit_total:
        accel_target = _clamp(accel_target, accel_min, accel_max)
    return shape_accel(accel_target, accel, jerk_max, dt)


def attitude_command_model(error_angle: float, desired_ang_vel: float, ang_vel: float, ang_accel: float,
                           max_ang_vel: float, accel_max: float, input_tc: float,
                           dt: float) -> tuple[float, float]:
    """One step of ``attitude_command_model``: the new ``(target angular velocity, acceleration)``.

    Parameters
    ----------
    error_angle : float
        Angle still to turn [rad] (0 when shaping a rate demand).
    desired_ang_vel : float
        Rate demand [rad/s] (0 when shaping an angle).
    ang_vel, ang_accel : float
        The shaped target so far.
    max_ang_vel : float
        Rate limit [rad/s] (0 = none).
    accel_max : float
        Acceleration limit [rad/s^2] (0 = 1800 deg/s^2, as ArduPilot).
    input_tc : float
        Time constant [s] (0 = ten steps).
    dt : float
        Step [s].
    """
    if dt <= 0.0:
        return ang_vel, ang_accel
    if accel_max <= 0.0:
        accel_max = math.radians(1800.0)
    if input_tc <= 0.0:
        input_tc = dt * 10.0
    wrapped = math.remainder(error_angle, 2.0 * math.pi)
    ang_accel = shape_pos_vel_accel(wrapped, desired_ang_vel, 0.0, 0.0, ang_vel, ang_accel, -max_ang_vel,
                                    max_ang_vel, -accel_max, accel_max, accel_max / input_tc, dt, True)
    return ang_vel + ang_accel * dt, ang_accel
