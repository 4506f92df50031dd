"""State estimation in the paper's frame from noisy, quantised position/attitude readings.

Each position axis runs a steady-state Kalman filter of a constant-velocity
model driven by the acceleration the model predicts from the last command
(thrust along the tilted body axis, minus gravity)::

    predict  p- = p + T v + T^2/2 a,   v- = v + T a
    correct  [p, v] = [p-, v-] + K (y - p-)

The gain K comes from the discrete algebraic Riccati equation with white
acceleration noise (``accel_noise_std_m_s2``) and a measurement variance of
``noise^2 + resolution^2 / 12`` (quantisation as uniform noise).  Altitude
is known never to be below the ground (z >= 0).  Attitude and rates pass
through (an IMU's are good enough at 100 Hz).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
import scipy.linalg

from gcs.model import Command, ModelParams, State

__all__ = ["kalman_gain_cv", "StateEstimator"]


def kalman_gain_cv(ts: float, accel_noise_std: float, meas_std: float) -> tuple[float, float]:
    """Steady-state Kalman gain (k_pos, k_vel) of a constant-velocity model measured in position.

    Parameters
    ----------
    ts : float
        Sample period [s], > 0.
    accel_noise_std : float
        White acceleration noise [m/s^2], > 0.
    meas_std : float
        Measurement noise [m], > 0.
    """
    if not ts > 0 or not accel_noise_std > 0 or not meas_std > 0:
        raise ValueError("ts, accel_noise_std and meas_std must be > 0")
    a = np.array([[1.0, ts], [0.0, 1.0]])
    c = np.array([[1.0, 0.0]])
    g = np.array([[0.5 * ts * ts], [ts]])
    qw = accel_noise_std ** 2 * (g @ g.T)
    r = np.array([[meas_std ** 2]])
    p = scipy.linalg.solve_discrete_are(a.T, c.T, qw, r)
    k = p @ c.T / (c @ p @ c.T + r)
    return float(k[0, 0]), float(k[1, 0])


class StateEstimator:
    """Position/velocity filters on x, y, z plus attitude pass-through.

    Parameters
    ----------
    ts : float
        Control period [s].
    model : ModelParams
    position_std_m : (float, float, float)
        Effective measurement noise of x, y, z [m] (include quantisation).
    accel_noise_std_m_s2 : float
        Process noise: unmodelled acceleration (wind, drag, model error).
    """

    def __init__(self, ts: float, model: ModelParams, position_std_m: Sequence[float], accel_noise_std_m_s2: float) -> None:
        self.ts = ts
        self.model = model
        stds = [max(float(s), 1e-4) for s in position_std_m]
        self.gains = [kalman_gain_cv(ts, accel_noise_std_m_s2, s) for s in stds]
        self.reset()

    def reset(self) -> None:
        """Forget the estimate; the next reading initialises it."""
        self._pos: list[float] | None = None
        self._vel = [0.0, 0.0, 0.0]

    def update(self, reading: Sequence[float], last_command: Command | None) -> State:
        """New estimate from a reading ``(x, y, z, roll, pitch, yaw, roll_rate, pitch_rate, yaw_rate)``.

        ``last_command`` is the command applied since the previous reading (None at the start).
        """
        y = reading
        if self._pos is None:
            self._pos = [y[0], y[1], max(y[2], 0.0)]
        else:
            ts = self.ts
            if last_command is not None:
                phi, th = y[3], y[4]
                um = last_command[0] / self.model.mass_kg
                acc = (-um * math.sin(th), um * math.cos(th) * math.sin(phi),
                       um * math.cos(th) * math.cos(phi) - self.model.gravity_m_s2)
            else:
                acc = (0.0, 0.0, 0.0)
            for i in range(3):
                p = self._pos[i] + ts * self._vel[i] + 0.5 * ts * ts * acc[i]
                v = self._vel[i] + ts * acc[i]
                kp, kv = self.gains[i]
                innov = y[i] - p
                self._pos[i] = p + kp * innov
                self._vel[i] = v + kv * innov
            if self._pos[2] < 0.0:
                self._pos[2] = 0.0
                if self._vel[2] < 0.0:
                    self._vel[2] = 0.0
        px, py, pz = self._pos
        vx, vy, vz = self._vel
        return State(px, py, pz, vx, vy, vz, y[3], y[4], y[5], y[6], y[7], y[8])
