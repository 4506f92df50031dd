"""Sensors of the emulated autopilot (NED): IMU attitude/rates, local position/velocity, baro, rangefinder.

Each reading is ``truth + white Gaussian noise``, quantised where the real
sensor is (barometer 10 cm, ultrasonic rangefinder 4 cm).  The noise comes
from a seeded :class:`numpy.random.Generator` drawn in blocks (one numpy
call per 4096 samples), so a run is reproducible from its seed and the
400 Hz loop pays no numpy call overhead.

The paper-frame sensor model used by ``gcs sim`` stays in :mod:`quadrotor.sensors`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from quadrotor.frames import Kinematics, quaternion_to_euler
from sitl.copter.vehicle import SensorParams6

__all__ = ["ImuReading", "NavReading", "NoiseSource", "NedSensors"]

_new = tuple.__new__


class ImuReading(NamedTuple):
    """Attitude (Euler [rad] and the matching quaternion) and body rates [rad/s]."""

    roll: float
    pitch: float
    yaw: float
    p: float
    q: float
    r: float
    qw: float
    qx: float
    qy: float
    qz: float


class NavReading(NamedTuple):
    """Local position [m] / velocity [m/s] estimate (NED), baro altitude above home [m], range [m] (-1: none)."""

    n: float
    e: float
    d: float
    vn: float
    ve: float
    vd: float
    baro_alt_m: float
    range_m: float


class NoiseSource:
    """Standard normal samples from a seeded generator, drawn in blocks.

    Parameters
    ----------
    rng : numpy.random.Generator
    block : int
        Samples per numpy call.
    """

    def __init__(self, rng: np.random.Generator, block: int = 4096) -> None:
        self._rng = rng
        self._block = block
        self._buf: list[float] = []
        self._i = 0

    def take(self, count: int) -> list[float]:
        """The next ``count`` samples."""
        i = self._i
        if i + count > len(self._buf):
            self._buf = self._buf[i:] + self._rng.standard_normal(max(self._block, count)).tolist()
            i = 0
        self._i = i + count
        return self._buf[i:i + count]


def _quantise(value: float, step: float) -> float:
    return round(value / step) * step if step > 0.0 else value


class NedSensors:
    """Draw sensor readings from the true kinematics.

    Attitude noise is a small random rotation of the body (standard deviation
    ``attitude_noise_std_rad`` about each body axis), so the Euler angles and
    the quaternion of a reading agree.

    Parameters
    ----------
    params : SensorParams6
    rng : numpy.random.Generator
        Seeded generator (use a stream of its own).
    """

    def __init__(self, params: SensorParams6, rng: np.random.Generator) -> None:
        self.params = params
        self._noise = NoiseSource(rng)
        self._half_att = 0.5 * params.attitude_noise_std_rad
        self._rate = params.rate_noise_std_rad_s

    def imu(self, k: Kinematics) -> ImuReading:
        """Attitude and rates with IMU noise."""
        n = self._noise.take(6)
        sa = self._half_att
        qw, qx, qy, qz = k.qw, k.qx, k.qy, k.qz
        if sa > 0.0:
            # q * (1, a/2, b/2, c/2), renormalised: a small body-frame rotation.
            dx, dy, dz = sa * n[0], sa * n[1], sa * n[2]
            w = qw - qx * dx - qy * dy - qz * dz
            x = qx + qw * dx + qy * dz - qz * dy
            y = qy + qw * dy - qx * dz + qz * dx
            z = qz + qw * dz + qx * dy - qy * dx
            inv = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
            qw, qx, qy, qz = w * inv, x * inv, y * inv, z * inv
        roll, pitch, yaw = quaternion_to_euler((qw, qx, qy, qz))
        sr = self._rate
        return _new(ImuReading, (roll, pitch, yaw, k.p + sr * n[3], k.q + sr * n[4], k.r + sr * n[5], qw, qx, qy, qz))

    def nav(self, k: Kinematics) -> NavReading:
        """Position/velocity estimate, barometric altitude and (if fitted) range."""
        sp = self.params
        n = self._noise.take(8)
        sx = sp.position_noise_std_m
        sv = sp.velocity_noise_std_m_s
        alt = -k.d
        baro = _quantise(alt + sp.baro_noise_std_m * n[6], sp.baro_resolution_m)
        rng = -1.0
        if sp.rangefinder:
            # Distance along the body z axis to the flat ground.
            cos_tilt = 1.0 - 2.0 * (k.qx * k.qx + k.qy * k.qy)
            if cos_tilt > 0.1:
                dist = alt / cos_tilt + sp.rangefinder_noise_std_m * n[7]
                dist = _quantise(max(dist, 0.0), sp.rangefinder_resolution_m)
                rng = dist if dist <= sp.rangefinder_max_m else -1.0
        return _new(NavReading, (k.n + sx * n[0], k.e + sx * n[1], k.d + sx * n[2],
                                 k.vn + sv * n[3], k.ve + sv * n[4], k.vd + sv * n[5], baro, rng))
