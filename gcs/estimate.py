"""State estimation in the paper's frame from noisy, quantised, possibly late telemetry.

Each position axis runs a two-state Kalman filter (position, velocity) of a
constant-velocity model driven by the acceleration the model predicts from
the last command (thrust along the tilted body axis, minus gravity)::

    predict  p- = p + dt v + dt^2/2 a,   v- = v + dt a,   P- = F P F' + G G' sigma_a^2
    correct  with a position reading (variance noise^2 + resolution^2 / 12)
             and/or a velocity reading

``sigma_a`` (``accel_noise_std_m_s2``) covers what the model does not know
(wind, drag, thrust error).  Predictions run every control tick; corrections
whenever a reading arrives, so telemetry slower than the loop (or a late
frame) is handled.  Altitude is never estimated below the ground (z >= 0).
Attitude and Euler-angle rates are taken from the latest IMU reading.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
import scipy.linalg

from quadrotor.state import Command, State
from quadrotor.dynamics import eq1_acceleration
from gcs.model import ModelParams

__all__ = ["kalman_gain_cv", "AxisFilter", "StateEstimator"]


def kalman_gain_cv(ts: float, accel_noise_std: float, meas_std: float) -> tuple[float, float]:
    """Steady-state Kalman gain (k_pos, k_vel) of a constant-velocity model measured in position."""
    if not ts > 0 or not accel_noise_std > 0 or not meas_std > 0:
        raise ValueError("ts, accel_noise_std and meas_std must be > 0")
    a = np.array([[1.0, ts], [0.0, 1.0]])
    c = np.array([[1.0, 0.0]])
    g = np.array([[0.5 * ts * ts], [ts]])
    p = scipy.linalg.solve_discrete_are(a.T, c.T, accel_noise_std ** 2 * (g @ g.T), np.array([[meas_std ** 2]]))
    k = p @ c.T / (c @ p @ c.T + meas_std ** 2)
    return float(k[0, 0]), float(k[1, 0])


class AxisFilter:
    """Kalman filter of one axis: state (position [m], velocity [m/s]), covariance kept explicitly."""

    def __init__(self, accel_noise_std_m_s2: float, position: float = 0.0, velocity: float = 0.0,
                 position_var: float = 1.0, velocity_var: float = 1.0) -> None:
        if not accel_noise_std_m_s2 > 0:
            raise ValueError("accel_noise_std_m_s2 must be > 0")
        self.q = accel_noise_std_m_s2 ** 2
        self.p, self.v = position, velocity
        self.ppp, self.ppv, self.pvv = position_var, 0.0, velocity_var

    def predict(self, dt: float, accel: float) -> None:
        """Advance by dt [s] with the known acceleration [m/s^2]."""
        h2 = 0.5 * dt * dt
        self.p += dt * self.v + h2 * accel
        self.v += dt * accel
        q = self.q
        ppp, ppv, pvv = self.ppp, self.ppv, self.pvv
        self.ppp = ppp + 2 * dt * ppv + dt * dt * pvv + q * h2 * h2
        self.ppv = ppv + dt * pvv + q * h2 * dt
        self.pvv = pvv + q * dt * dt

    def correct_position(self, z: float, var: float) -> None:
        """Fuse a position reading of variance ``var`` [m^2]."""
        s = self.ppp + var
        kp, kv = self.ppp / s, self.ppv / s
        innov = z - self.p
        self.p += kp * innov
        self.v += kv * innov
        ppp, ppv, pvv = self.ppp, self.ppv, self.pvv
        self.ppp = (1 - kp) * ppp
        self.ppv = (1 - kp) * ppv
        self.pvv = pvv - kv * ppv

    def correct_velocity(self, z: float, var: float) -> None:
        """Fuse a velocity reading of variance ``var`` [(m/s)^2]."""
        s = self.pvv + var
        kp, kv = self.ppv / s, self.pvv / s
        innov = z - self.v
        self.p += kp * innov
        self.v += kv * innov
        ppp, ppv, pvv = self.ppp, self.ppv, self.pvv
        self.ppp = ppp - kp * ppv
        self.ppv = ppv - kp * pvv
        self.pvv = (1 - kv) * pvv


def model_acceleration(model: ModelParams, command: Command | None, roll: float, pitch: float) -> tuple[float, float, float]:
    """Acceleration [m/s^2] (paper frame) of the reduced model (eq. 1) under ``command`` (zero for None)."""
    if command is None:
        return (0.0, 0.0, 0.0)
    return eq1_acceleration(command[0] / model.mass_kg, roll, pitch, model.gravity_m_s2)


class StateEstimator:
    """Position/velocity filters on x, y, z plus attitude from the IMU.

    Two ways to drive it:

    * :meth:`update` with one full reading per control period (the in-process simulation);
    * :meth:`predict` every tick, :meth:`correct_position`, :meth:`correct_velocity` and
      :meth:`set_attitude` whenever telemetry arrives, then :meth:`state` (the flight loop).

    Parameters
    ----------
    ts : float
        Control period [s].
    model : ModelParams
    position_std_m : (float, float, float)
        Measurement noise of x, y, z [m] used by :meth:`update` (include quantisation).
    accel_noise_std_m_s2 : float
        Process noise: unmodelled acceleration.
    ground_z_m : float or None
        Altitude of the ground (the estimate never goes below it); None = no ground
        constraint (a real vehicle's local origin need not be on the ground).
    """

    def __init__(self, ts: float, model: ModelParams, position_std_m: Sequence[float], accel_noise_std_m_s2: float,
                 *, ground_z_m: float | None = 0.0) -> None:
        self.ts = ts
        self.ground_z_m = ground_z_m
        self.model = model
        self.position_var = [max(float(s), 1e-4) ** 2 for s in position_std_m]
        self.accel_noise_std_m_s2 = accel_noise_std_m_s2
        self.reset()

    def reset(self) -> None:
        """Forget the estimate; the next position reading initialises it."""
        self.axes: list[AxisFilter] | None = None
        self.attitude = (0.0,) * 6

    def predict(self, dt: float, last_command: Command | None) -> None:
        """Advance the filters by dt [s] under the command applied meanwhile."""
        if self.axes is None:
            return
        acc = model_acceleration(self.model, last_command, self.attitude[0], self.attitude[1])
        for f, a in zip(self.axes, acc):
            f.predict(dt, a)
        self._clamp_ground()

    def correct_position(self, pos: Sequence[float], var: Sequence[float] | None = None) -> None:
        """Fuse a position reading (x, y, z up) [m]; the first one initialises the filters."""
        var = self.position_var if var is None else var
        if self.axes is None:
            self.axes = [AxisFilter(self.accel_noise_std_m_s2, p, 0.0, v, 1.0) for p, v in zip(pos, var)]
            self._clamp_ground()
            return
        for f, z, v in zip(self.axes, pos, var):
            f.correct_position(z, v)
        self._clamp_ground()

    def correct_velocity(self, vel: Sequence[float], var: Sequence[float]) -> None:
        """Fuse a velocity reading (paper frame) [m/s]."""
        if self.axes is None:
            return
        for f, z, v in zip(self.axes, vel, var):
            f.correct_velocity(z, v)
        self._clamp_ground()

    def set_attitude(self, roll: float, pitch: float, yaw: float, roll_rate: float, pitch_rate: float, yaw_rate: float) -> None:
        """Latest attitude [rad] and Euler-angle rates [rad/s]."""
        self.attitude = (roll, pitch, yaw, roll_rate, pitch_rate, yaw_rate)

    def _clamp_ground(self) -> None:
        g = self.ground_z_m
        if g is None:
            return
        fz = self.axes[2]  # type: ignore[index]
        if fz.p < g:
            fz.p = g
            if fz.v < 0.0:
                fz.v = 0.0

    @property
    def initialised(self) -> bool:
        return self.axes is not None

    def state(self) -> State:
        """The current estimate (zeros before the first position reading)."""
        if self.axes is None:
            return State(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, *self.attitude)
        x, y, z = self.axes
        return State(x.p, y.p, z.p, x.v, y.v, z.v, *self.attitude)

    def update(self, reading: Sequence[float], last_command: Command | None) -> State:
        """One control period: reading ``(x, y, z, roll, pitch, yaw, roll_rate, pitch_rate, yaw_rate)``.

        ``last_command`` is the command applied since the previous reading (None at the start).
        """
        if self.axes is not None:
            self.predict(self.ts, last_command)
        self.correct_position((reading[0], reading[1], reading[2]))
        self.set_attitude(*reading[3:9])
        return self.state()
