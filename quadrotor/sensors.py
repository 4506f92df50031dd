"""Sensor models for the reduced plant: IMU attitude/rates, position, altitude.

Altitude sensors follow the paper's vehicles: a barometer with 10 cm
resolution (outdoor Pixhawk, MS5611) or an ultrasonic ranger with 4 cm
resolution (indoor rig).  A reading is ``quantise(true + noise)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple
from collections.abc import Sequence

import numpy as np

__all__ = ["SensorParams", "Measurement", "Sensors", "ALTITUDE_KINDS"]

ALTITUDE_KINDS = ("ideal", "baro", "ultrasonic")


class Measurement(NamedTuple):
    """One set of sensor readings (paper frame, z up; SI units)."""

    x: float
    y: float
    z: float
    roll: float
    pitch: float
    yaw: float
    roll_rate: float
    pitch_rate: float
    yaw_rate: float


@dataclass(frozen=True)
class SensorParams:
    """Sensor noise and resolution.

    Attributes
    ----------
    altitude : {"ideal", "baro", "ultrasonic"}
        Altitude sensor kind (sets nothing by itself; the numbers below do).
    altitude_noise_std_m, altitude_resolution_m : float
        Gaussian noise and quantisation step of the altitude (0 = none).
    position_noise_std_m : float
        Noise of the horizontal position.
    attitude_noise_std_rad, rate_noise_std_rad_s : float
        IMU attitude and angular-rate noise.
    """

    altitude: str = "ideal"
    altitude_noise_std_m: float = 0.0
    altitude_resolution_m: float = 0.0
    position_noise_std_m: float = 0.0
    attitude_noise_std_rad: float = 0.0
    rate_noise_std_rad_s: float = 0.0

    def __post_init__(self) -> None:
        if self.altitude not in ALTITUDE_KINDS:
            raise ValueError(f"altitude must be one of {ALTITUDE_KINDS}, got {self.altitude!r}")
        for name in ("altitude_noise_std_m", "altitude_resolution_m", "position_noise_std_m",
                     "attitude_noise_std_rad", "rate_noise_std_rad_s"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0")

    @property
    def is_ideal(self) -> bool:
        """True when every reading is exact."""
        return (self.altitude_noise_std_m == 0 and self.altitude_resolution_m == 0
                and self.position_noise_std_m == 0 and self.attitude_noise_std_rad == 0
                and self.rate_noise_std_rad_s == 0)


class Sensors:
    """Draws measurements from the true state with a seeded generator."""

    def __init__(self, params: SensorParams, rng: np.random.Generator) -> None:
        self.params = params
        self._rng = rng
        p = params
        self._std = np.array([p.position_noise_std_m, p.position_noise_std_m, p.altitude_noise_std_m]
                             + [p.attitude_noise_std_rad] * 3 + [p.rate_noise_std_rad_s] * 3)

    def measure(self, state: Sequence[float]) -> Measurement:
        """Readings for a plant state in ``quadrotor.state.STATE_FIELDS`` order."""
        noise = (self._rng.standard_normal(9) * self._std).tolist()
        z = state[2] + noise[2]
        res = self.params.altitude_resolution_m
        if res > 0.0:
            z = math.floor(z / res + 0.5) * res
        if self.params.altitude == "ultrasonic" and z < 0.0:
            z = 0.0  # a range sensor reads no negative distance
        return Measurement(
            state[0] + noise[0], state[1] + noise[1], z,
            state[6] + noise[3], state[7] + noise[4], state[8] + noise[5],
            state[9] + noise[6], state[10] + noise[7], state[11] + noise[8],
        )
