"""Seeded wind: a steady component plus first-order Gauss-Markov gusts.

The gust on each axis is an Ornstein-Uhlenbeck process with standard
deviation ``gust_std_m_s`` and correlation time ``gust_tau_s``, discretised
exactly (``g[k+1] = a g[k] + std sqrt(1 - a^2) n``, ``a = exp(-dt/tau)``), so the
statistics do not depend on the update period.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["WindParams", "Wind"]


@dataclass(frozen=True)
class WindParams:
    """Wind model parameters (paper frame, z up).

    Attributes
    ----------
    mean_speed_m_s : float
        Horizontal steady wind speed.
    direction_deg : float or None
        Direction the wind blows *towards*, from +x towards +y; ``None`` draws
        it uniformly per run from the seed.
    vertical_m_s : float
        Steady vertical wind component.
    gust_std_m_s : float
        Standard deviation of the gusts on each axis (vertical gusts are half).
    gust_tau_s : float
        Gust correlation time.
    """

    mean_speed_m_s: float = 0.0
    direction_deg: float | None = None
    vertical_m_s: float = 0.0
    gust_std_m_s: float = 0.0
    gust_tau_s: float = 2.0

    def __post_init__(self) -> None:
        for name in ("mean_speed_m_s", "vertical_m_s", "gust_std_m_s", "gust_tau_s"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)!r}")
        if self.direction_deg is not None and not math.isfinite(self.direction_deg):
            raise ValueError(f"direction_deg must be finite, got {self.direction_deg!r}")
        if self.mean_speed_m_s < 0:
            raise ValueError("mean_speed_m_s must be >= 0")
        if self.gust_std_m_s < 0:
            raise ValueError("gust_std_m_s must be >= 0")
        if not self.gust_tau_s > 0:
            raise ValueError("gust_tau_s must be > 0")


class Wind:
    """Wind velocity generator; deterministic for a given generator state."""

    def __init__(self, params: WindParams, rng: np.random.Generator) -> None:
        self.params = params
        self._rng = rng
        direction = params.direction_deg
        if direction is None:
            direction = float(rng.uniform(0.0, 360.0))
        a = math.radians(direction)
        self.mean_m_s = (
            params.mean_speed_m_s * math.cos(a),
            params.mean_speed_m_s * math.sin(a),
            params.vertical_m_s,
        )
        self._std = (params.gust_std_m_s, params.gust_std_m_s, 0.5 * params.gust_std_m_s)
        # Start the gusts in their stationary distribution.
        self._gust = [s * float(rng.standard_normal()) for s in self._std]

    def sample(self, dt: float) -> tuple[float, float, float]:
        """Advance the gusts by ``dt`` seconds and return the wind [m/s]."""
        if self.params.gust_std_m_s > 0.0:
            a = math.exp(-dt / self.params.gust_tau_s)
            b = math.sqrt(1.0 - a * a)
            n = self._rng.standard_normal(3)
            self._gust = [a * g + s * b * float(k) for g, s, k in zip(self._gust, self._std, n)]
        mx, my, mz = self.mean_m_s
        gx, gy, gz = self._gust
        return (mx + gx, my + gy, mz + gz)
