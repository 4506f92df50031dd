"""Sensors of the 4-DOF rig: IMU, ultrasonic altimeter, x position.

Ultrasonic model (paper section 5.1: "the sensor is located on the aerial
platform at a distance of 5 cm from the ground (nearby to the minimum
measurement of the sensor). Then, when the helicopter is landed, this sensor
reports zero altitude or another measure around of 5 cm"):

* the sensor sits ``mount_height_m`` (5 cm) above the ground when the rig is
  landed (z = 0) and measures the vertical range ``r = z + mount_height_m``
  (its beam is wide, so tilt within the stops does not lengthen the echo);
* closer than ``min_range_m`` (7 cm) it reports its minimum, farther than
  ``max_range_m`` its maximum; both set the ALT_OUT_OF_RANGE flag;
* the rig subtracts the mount height and rounds to the 4 cm resolution:
  ``reading = q(clamp(r) - mount_height_m + noise)`` with
  ``q(v) = resolution * floor(v / resolution + 1/2)``, floored at 0.

Landed, the clamped range gives 7 - 5 = 2 cm, half a step: with noise the
reading jumps between 0 and 4 cm, as the paper reports.  Noise-free it is
q(0.02) = 4 cm.

IMU: attitude and rates plus Gaussian noise (yaw is locked: noise around 0).
x: position plus Gaussian noise (the PC differentiates it for vx).  Noise
comes from a seeded :class:`random.Random`, so readings repeat for a seed.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

__all__ = ["RigSensorParams", "RigReading", "RigSensors", "quantise"]


@dataclass(frozen=True)
class RigSensorParams:
    """Noise, resolution and range of the rig's sensors.

    Attributes
    ----------
    altitude_resolution_m : float
        Ultrasonic quantisation step (4 cm).
    altitude_noise_std_m : float
        Ultrasonic noise before quantisation.
    mount_height_m : float
        Height of the ultrasonic sensor above the ground when landed.
    min_range_m, max_range_m : float
        Ultrasonic range limits (measured from the sensor).
    attitude_noise_std_rad, rate_noise_std_rad_s : float
        IMU noise.
    x_noise_std_m : float
        Noise of the x position.
    """

    altitude_resolution_m: float = 0.04
    altitude_noise_std_m: float = 0.01
    mount_height_m: float = 0.05
    min_range_m: float = 0.07
    max_range_m: float = 3.0
    attitude_noise_std_rad: float = 0.002
    rate_noise_std_rad_s: float = 0.01
    x_noise_std_m: float = 0.005

    def __post_init__(self) -> None:
        for name in ("altitude_resolution_m", "min_range_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("altitude_noise_std_m", "mount_height_m", "attitude_noise_std_rad", "rate_noise_std_rad_s",
                     "x_noise_std_m"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if not self.max_range_m > self.min_range_m:
            raise ValueError("max_range_m must be above min_range_m")
        if (self.max_range_m - self.mount_height_m) * 1000 > 65535:
            raise ValueError("max_range_m does not fit the uint16 millimetre field")

    @classmethod
    def ideal(cls) -> RigSensorParams:
        """No noise (quantisation and range limits kept)."""
        return cls(altitude_noise_std_m=0.0, attitude_noise_std_rad=0.0, rate_noise_std_rad_s=0.0,
                   x_noise_std_m=0.0)


class RigReading(NamedTuple):
    """One sample of the rig's sensors (paper frame, z up; SI units)."""

    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    roll_rate_rad_s: float
    pitch_rate_rad_s: float
    yaw_rate_rad_s: float
    x_m: float
    altitude_m: float
    altitude_out_of_range: bool


def quantise(value: float, step: float) -> float:
    """Round to the nearest multiple of ``step`` (halves up)."""
    return step * math.floor(value / step + 0.5)


class RigSensors:
    """Draws readings from the true plant state.

    Parameters
    ----------
    params : RigSensorParams
    rng : random.Random
    """

    def __init__(self, params: RigSensorParams, rng: random.Random) -> None:
        self.params = params
        self._rng = rng

    def altitude(self, z_m: float, noise_m: float = 0.0) -> tuple[float, bool]:
        """Ultrasonic reading [m] for a true altitude, and whether the range was clamped."""
        p = self.params
        r = z_m + p.mount_height_m
        out = r < p.min_range_m or r > p.max_range_m
        r = p.min_range_m if r < p.min_range_m else p.max_range_m if r > p.max_range_m else r
        reading = quantise(r - p.mount_height_m + noise_m, p.altitude_resolution_m)
        top = quantise(p.max_range_m - p.mount_height_m, p.altitude_resolution_m)
        return (0.0 if reading < 0.0 else top if reading > top else reading), out

    def measure(self, state: Sequence[float]) -> RigReading:
        """Readings for a :class:`~quadrotor.state.State`."""
        p = self.params
        g = self._rng.gauss
        sa, sr = p.attitude_noise_std_rad, p.rate_noise_std_rad_s
        # Always draw the same number of samples so that the stream does not depend on the parameters.
        n = [g(0.0, 1.0) for _ in range(8)]
        alt, out = self.altitude(state[2], n[7] * p.altitude_noise_std_m)
        return RigReading(state[6] + sa * n[0], state[7] + sa * n[1], state[8] + sa * n[2],
                          state[9] + sr * n[3], state[10] + sr * n[4], state[11] + sr * n[5],
                          state[0] + p.x_noise_std_m * n[6], alt, out)
