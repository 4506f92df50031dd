"""ArduCopter's attitude and rate controllers (``AC_AttitudeControl`` + ``AC_AttitudeControl_Multi``).

What a guided attitude target goes through, every 2.5 ms (``SCHED_LOOP_RATE`` 400 Hz):

* ``input_quaternion(q, w)``: with ``ATC_RATE_FF_ENAB = 1`` the attitude target moves towards
  ``q`` along the jerk-limited command model (``ATC_INPUT_TC``, ``ATC_ACC_*_MAX``), its angular
  velocity being the feed-forward; with 0 the target is ``q`` at once and ``w`` the feed-forward.
  Either way the stored desired quaternion is then rolled forward by ``w dt`` (ArduCopter keeps
  integrating the last message's body rates until the next one comes).
* ``input_rate_bf(w)`` (ATTITUDE_IGNORE): rates shaped the same way (rate time constant
  ``ATC_RATE_*_TC``, 0 here) and integrated into the target.
* ``attitude_controller_run_quat``: thrust-vector then heading error, angle P ``ATC_ANG_*_P``
  through the square-root controller limited by ``ATC_ACC_*_MAX / 2``, plus the target's
  angular velocity rotated into the body (faded out above 30 deg of thrust-vector error).
* ``rate_controller_run``: three :class:`~.filters.RatePid` on the gyro low-passed at
  ``INS_GYRO_FILTER``; their outputs are the normalised roll, pitch and yaw of the mixer.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from quadrotor.frames import euler_to_quaternion, quat_conjugate, quat_multiply, quat_rotate, quaternion_to_euler
from sitl.copter.ardupilot_emulation.filters import LowPass2p, RatePid
from sitl.copter.ardupilot_emulation.shaping import attitude_command_model, sqrt_controller

__all__ = ["AttitudeControl", "from_axis_angle", "to_axis_angle"]

Quat = tuple[float, float, float, float]
Vec3 = tuple[float, float, float]
_THRUST_ERROR_ANGLE = math.radians(30.0)    # AC_ATTITUDE_THRUST_ERROR_ANGLE_RAD
_RP_ACCEL_MIN, _RP_ACCEL_MAX = math.radians(40.0), math.radians(720.0)   # controller accel bounds, rad/s/s
_Y_ACCEL_MIN, _Y_ACCEL_MAX = math.radians(10.0), math.radians(120.0)
_YAW_MAX_ERROR = math.radians(45.0)
RATE_RELAX_TC_S = 0.5                      # AC_ATTITUDE_RATE_RELAX_TC


def from_axis_angle(v: Sequence[float]) -> Quat:
    """Quaternion of the rotation vector ``v`` [rad]."""
    a = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if a < 1e-12:
        return (1.0, 0.0, 0.0, 0.0)
    s = math.sin(0.5 * a) / a
    return (math.cos(0.5 * a), v[0] * s, v[1] * s, v[2] * s)


def to_axis_angle(q: Sequence[float]) -> Vec3:
    """Rotation vector [rad] of ``q`` (angle wrapped to +-pi, as ``Quaternion::to_axis_angle``)."""
    w, x, y, z = q
    n = math.sqrt(x * x + y * y + z * z)
    if n < 1e-12:
        return (0.0, 0.0, 0.0)
    k = math.remainder(2.0 * math.atan2(n, w), 2.0 * math.pi) / n
    return (x * k, y * k, z * k)


def _normalised(q: Sequence[float]) -> Quat:
    n = math.sqrt(sum(v * v for v in q))
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def _clamp(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else hi if v > hi else v


class AttitudeControl:
    """The attitude and rate loops of one vehicle; parameters are read from ``params`` (a ParamStore).

    Parameters
    ----------
    params : mapping of str to float
        ``ATC_*`` and ``INS_GYRO_FILTER``.
    dt : float
        Loop period [s].
    """

    def __init__(self, params, dt: float) -> None:
        self.params = params
        self.dt = dt
        self.attitude_target: Quat = (1.0, 0.0, 0.0, 0.0)
        self.ang_vel_target: list[float] = [0.0, 0.0, 0.0]
        self.ang_accel_target: list[float] = [0.0, 0.0, 0.0]
        self.rate_demand: Vec3 = (0.0, 0.0, 0.0)
        self.thrust_angle = 0.0
        self.refresh()

    def refresh(self) -> None:
        """Re-read the parameters (after a change)."""
        p, dt = self.params, self.dt
        self.ff_enabled = p["ATC_RATE_FF_ENAB"] >= 1
        self.input_tc = p["ATC_INPUT_TC"]
        self.ang_p = (p["ATC_ANG_RLL_P"], p["ATC_ANG_PIT_P"], p["ATC_ANG_YAW_P"])
        self.accel_max = tuple(math.radians(p[n]) for n in ("ATC_ACC_R_MAX", "ATC_ACC_P_MAX", "ATC_ACC_Y_MAX"))
        self.rate_max = tuple(math.radians(p[n]) for n in ("ATC_RATE_R_MAX", "ATC_RATE_P_MAX", "ATC_RATE_Y_MAX"))
        self.pids = tuple(
            RatePid(p[f"ATC_RAT_{a}_P"], p[f"ATC_RAT_{a}_I"], p[f"ATC_RAT_{a}_D"], p[f"ATC_RAT_{a}_IMAX"],
                    p[f"ATC_RAT_{a}_FLTT"], p[f"ATC_RAT_{a}_FLTE"], p[f"ATC_RAT_{a}_FLTD"])
            for a in ("RLL", "PIT", "YAW"))
        self.gyro_filters = tuple(LowPass2p(1.0 / dt, p["INS_GYRO_FILTER"]) for _ in range(3))
        self.gyro_filtered: Vec3 = (0.0, 0.0, 0.0)

    # ------------------------------------------------------------------ targets
    def reset_yaw_target(self, q_body: Sequence[float]) -> None:
        """The target's heading = the body's, no yaw rate (``reset_yaw_target_and_rate``)."""
        roll, pitch, _ = quaternion_to_euler(self.attitude_target)
        self.attitude_target = euler_to_quaternion(roll, pitch, quaternion_to_euler(q_body)[2])
        self.ang_vel_target[2] = 0.0
        self.ang_accel_target[2] = 0.0

    def input_level(self, q_body: Sequence[float]) -> None:
        """Level roll and pitch at the target's heading, no yaw rate: what ArduCopter flies on the ground
        and while it spools up (``input_euler_angle_roll_pitch_euler_rate_yaw_rad(0, 0, 0)``)."""
        level = euler_to_quaternion(0.0, 0.0, quaternion_to_euler(self.attitude_target)[2])
        self.input_quaternion(level, (0.0, 0.0, 0.0), q_body)

    def relax_rate_i(self) -> None:
        """The rate integrators towards 0 in :data:`RATE_RELAX_TC_S` (``reset_rate_controller_I_terms_smoothly``)."""
        for pid in self.pids:
            pid.relax_i(self.dt, RATE_RELAX_TC_S)

    def reset_rate_i(self) -> None:
        """Zero the rate integrators (on the ground, ``reset_rate_controller_I_terms``)."""
        for pid in self.pids:
            pid.reset_i()
            pid.reset_filter()

    def _limit_rates(self, w: Sequence[float]) -> list[float]:
        return [_clamp(v, -m, m) if m > 0.0 else v for v, m in zip(w, self.rate_max, strict=True)]

    def _update_target(self) -> None:
        dt = self.dt
        w = self.ang_vel_target
        self.attitude_target = _normalised(quat_multiply(self.attitude_target,
                                                         from_axis_angle((w[0] * dt, w[1] * dt, w[2] * dt))))

    def input_quaternion(self, q_desired: Sequence[float], ang_vel_body: Sequence[float],
                         q_body: Sequence[float]) -> Quat:
        """Fly towards ``q_desired`` with body-rate input ``ang_vel_body``; returns the desired quaternion rolled on."""
        dt = self.dt
        self._update_target()
        w_in = self._limit_rates(ang_vel_body)
        w_ned = quat_rotate(q_desired, w_in)  # as ArduPilot: attitude_desired_quat * ang_vel_body
        if self.ff_enabled:
            err = to_axis_angle(quat_multiply(quat_conjugate(self.attitude_target), q_desired))
            tcs = (self.input_tc, self.input_tc, self.input_tc)
            for i in range(3):
                self.ang_vel_target[i], self.ang_accel_target[i] = attitude_command_model(
                    err[i], 0.0, self.ang_vel_target[i], self.ang_accel_target[i], self.rate_max[i],
                    self.accel_max[i], tcs[i], dt)
        else:
            self.attitude_target = tuple(q_desired)  # type: ignore[assignment]
            self.ang_vel_target = list(w_ned)
        rolled = _normalised(quat_multiply(q_desired, from_axis_angle((w_ned[0] * dt, w_ned[1] * dt, w_ned[2] * dt))))
        self._run_quat(q_body)
        return rolled

    def input_rate_bf(self, rates: Sequence[float], q_body: Sequence[float]) -> None:
        """Body-rate demand [rad/s] (``input_rate_bf_roll_pitch_yaw_rads``; rate time constants 0)."""
        dt = self.dt
        self._update_target()
        if self.ff_enabled:
            for i in range(3):
                self.ang_vel_target[i], self.ang_accel_target[i] = attitude_command_model(
                    0.0, rates[i], self.ang_vel_target[i], self.ang_accel_target[i], 0.0, self.accel_max[i], 0.0, dt)
        else:
            self.attitude_target = _normalised(quat_multiply(
                self.attitude_target, from_axis_angle((rates[0] * dt, rates[1] * dt, rates[2] * dt))))
            self.ang_vel_target = [0.0, 0.0, 0.0]
            self.ang_accel_target = [0.0, 0.0, 0.0]
        self._run_quat(q_body)

    # ------------------------------------------------------------------ attitude loop
    def _errors(self, q_body: Sequence[float]) -> tuple[Vec3, float]:
        """Thrust-vector (x, y) then heading (z) error [rad] and the thrust-vector error angle."""
        up = (0.0, 0.0, -1.0)
        t_vec = quat_rotate(self.attitude_target, up)
        b_vec = quat_rotate(q_body, up)
        self.thrust_angle = math.acos(_clamp(-b_vec[2], -1.0, 1.0))
        cross = (b_vec[1] * t_vec[2] - b_vec[2] * t_vec[1], b_vec[2] * t_vec[0] - b_vec[0] * t_vec[2],
                 b_vec[0] * t_vec[1] - b_vec[1] * t_vec[0])
        err_angle = math.acos(_clamp(sum(a * b for a, b in zip(b_vec, t_vec, strict=True)), -1.0, 1.0))
        n = math.sqrt(sum(c * c for c in cross))
        axis = up if n < 1e-12 or err_angle == 0.0 else (cross[0] / n, cross[1] / n, cross[2] / n)
        axis_b = quat_rotate(quat_conjugate(q_body), axis)
        corr = from_axis_angle((axis_b[0] * err_angle, axis_b[1] * err_angle, axis_b[2] * err_angle))
        rx, ry, _ = to_axis_angle(corr)
        heading = quat_multiply(quat_multiply(quat_conjugate(corr), quat_conjugate(q_body)), self.attitude_target)
        rz = to_axis_angle(heading)[2]
        kp_rate_yaw = self.params["ATC_RAT_YAW_P"]
        if kp_rate_yaw > 0.0 and self.ang_p[2] > 0.0:
            acc = _clamp(self.accel_max[2] / 2.0, _Y_ACCEL_MIN, _Y_ACCEL_MAX)
            lim = min(_inv_sqrt_controller(1.0 / kp_rate_yaw, self.ang_p[2], acc), _YAW_MAX_ERROR)
            if abs(rz) > lim:
                rz = _clamp(math.remainder(rz, 2.0 * math.pi), -lim, lim)
                self.attitude_target = quat_multiply(quat_multiply(tuple(q_body), corr), from_axis_angle((0, 0, rz)))
        return (rx, ry, rz), err_angle

    def _run_quat(self, q_body: Sequence[float]) -> None:
        err, thrust_err = self._errors(q_body)
        dt = self.dt
        w = []
        for i in range(3):
            acc = self.accel_max[i]
            lo, hi = (_Y_ACCEL_MIN, _Y_ACCEL_MAX) if i == 2 else (_RP_ACCEL_MIN, _RP_ACCEL_MAX)
            lim = _clamp(acc / 2.0, lo, hi) if acc > 0.0 else 0.0
            w.append(sqrt_controller(err[i], self.ang_p[i], lim, dt))
        w = self._limit_rates(w)
        ff = quat_rotate(quat_multiply(quat_conjugate(q_body), self.attitude_target), self.ang_vel_target)
        gz = self.gyro_filtered[2]
        if thrust_err > 2.0 * _THRUST_ERROR_ANGLE:
            w[2] = gz
        elif thrust_err > _THRUST_ERROR_ANGLE:
            s = 1.0 - (thrust_err - _THRUST_ERROR_ANGLE) / _THRUST_ERROR_ANGLE
            w[0] += ff[0] * s
            w[1] += ff[1] * s
            w[2] = gz * (1.0 - s) + (w[2] + ff[2]) * s
        else:
            w = [w[0] + ff[0], w[1] + ff[1], w[2] + ff[2]]
        self.rate_demand = (w[0], w[1], w[2])

    # ------------------------------------------------------------------ rate loop
    def filter_gyro(self, gyro: Sequence[float]) -> Vec3:
        """Low-pass the gyro [rad/s] (``INS_GYRO_FILTER``); call once per loop before the controllers."""
        f = self.gyro_filters
        self.gyro_filtered = (f[0].apply(gyro[0]), f[1].apply(gyro[1]), f[2].apply(gyro[2]))
        return self.gyro_filtered

    def rate_controller_run(self, limits: Sequence[bool]) -> Vec3:
        """Normalised roll, pitch, yaw commands; ``limits``: the mixer saturated that axis last loop."""
        g = self.gyro_filtered
        d = self.rate_demand
        return tuple(pid.update(d[i], g[i], self.dt, limits[i]) for i, pid in enumerate(self.pids))  # type: ignore[return-value]


def _inv_sqrt_controller(output: float, p: float, d_max: float) -> float:
    """The error at which :func:`sqrt_controller` gives ``output`` (AP_Math ``inv_sqrt_controller``)."""
    if d_max > 0.0 and p == 0.0:
        return output * output / (2.0 * d_max)
    if d_max <= 0.0 and p != 0.0:
        return output / p
    if d_max <= 0.0 and p == 0.0:
        return 0.0
    linear_velocity = d_max / p
    if abs(output) < linear_velocity:
        return output / p
    linear_dist = d_max / (p * p)
    stopping = linear_dist / 2.0 + output * output / (2.0 * d_max)
    return stopping if output > 0.0 else -stopping
