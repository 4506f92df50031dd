"""The controllers' models of the quadrotor: eq. 1 discretised, and the paper's subsystem splits.

Eq. 1 itself is :mod:`quadrotor.dynamics` (shared with the plant); here are its Euler
discretisation and the linear subsystem models the designs use.

Subsystems (the paper's splits), as index tuples into :class:`State`:

* ``z``      [z, vz]                 (LOC, exact linearisation eq. 3)
* ``psi``    [yaw, yaw_rate]         (LOC)
* ``z_psi``  [z, vz, yaw, yaw_rate]  (NLSOC, eq. 16)
* ``y_phi``  [y, vy, roll, roll_rate]
* ``x_theta`` [x, vx, pitch, pitch_rate]
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from quadrotor.dynamics import eq1_acceleration
from quadrotor.state import Command, State

__all__ = [
    "State", "Command", "ModelParams", "SUBSYSTEMS",
    "continuous_dynamics", "euler_step", "subsystem_state",
    "linear_z", "linear_psi", "linear_y_phi", "linear_x_theta", "MIN_TILT_COS", "tilt_cos",
]

#: Smallest cos(theta) cos(phi) used when dividing by it (|tilt| about 78 deg).
MIN_TILT_COS = 0.2


def tilt_cos(roll: float, pitch: float) -> float:
    """cos(pitch) cos(roll), floored at :data:`MIN_TILT_COS` (for thrust compensation)."""
    cc = math.cos(pitch) * math.cos(roll)
    return cc if cc > MIN_TILT_COS else MIN_TILT_COS


#: Index tuples of the paper's subsystems into :class:`State`.
SUBSYSTEMS: dict[str, tuple[int, ...]] = {
    "z": (2, 5),
    "psi": (8, 11),
    "z_psi": (2, 5, 8, 11),
    "y_phi": (1, 4, 6, 9),
    "x_theta": (0, 3, 7, 10),
}


@dataclass(frozen=True)
class ModelParams:
    """Mass [kg] and gravity [m/s^2] of the reduced model (paper: m = 1 kg, g = 9.81)."""

    mass_kg: float = 1.0
    gravity_m_s2: float = 9.81

    def __post_init__(self) -> None:
        if not self.mass_kg > 0:
            raise ValueError(f"mass_kg must be > 0, got {self.mass_kg!r}")
        if not self.gravity_m_s2 > 0:
            raise ValueError(f"gravity_m_s2 must be > 0, got {self.gravity_m_s2!r}")

    @property
    def hover_thrust_n(self) -> float:
        """Thrust holding a level vehicle [N]."""
        return self.mass_kg * self.gravity_m_s2


def continuous_dynamics(state: Sequence[float], command: Sequence[float], params: ModelParams) -> np.ndarray:
    """Time derivative of the state, eq. 1.

    Parameters
    ----------
    state : sequence of 12 floats, :class:`State` order
    command : sequence of 4 floats, :class:`Command` order
    params : ModelParams

    Returns
    -------
    ndarray, shape (12,)
    """
    s = np.asarray(state, dtype=float)
    if s.shape != (12,):
        raise ValueError("state must have 12 elements")
    u, tp, tt, tr = (float(c) for c in command)
    m, g = params.mass_kg, params.gravity_m_s2
    acc = eq1_acceleration(u / m, s[6], s[7], g)
    return np.concatenate([s[3:6], acc, s[9:12], (tp, tt, tr)])


def euler_step(state: Sequence[float], command: Sequence[float], ts: float, params: ModelParams) -> np.ndarray:
    """One step of the Euler discretisation ``x(k+1) = x(k) + Ts f(x(k), u(k))``."""
    if not ts > 0:
        raise ValueError(f"ts must be > 0, got {ts!r}")
    s = np.asarray(state, dtype=float)
    return s + ts * continuous_dynamics(s, command, params)


def subsystem_state(state: Sequence[float], name: str) -> np.ndarray:
    """The state of subsystem ``name`` (a key of :data:`SUBSYSTEMS`)."""
    try:
        idx = SUBSYSTEMS[name]
    except KeyError:
        raise ValueError(f"unknown subsystem {name!r}; expected one of {sorted(SUBSYSTEMS)}") from None
    return np.asarray(state, dtype=float)[list(idx)]


def _double_integrator(ts: float) -> tuple[np.ndarray, np.ndarray]:
    if not ts > 0:
        raise ValueError(f"ts must be > 0, got {ts!r}")
    return np.array([[1.0, ts], [0.0, 1.0]]), np.array([[0.0], [ts]])


def linear_z(ts: float) -> tuple[np.ndarray, np.ndarray]:
    """A, B of the exactly linearised z subsystem (eq. 4); input u1 [m/s^2]."""
    return _double_integrator(ts)


def linear_psi(ts: float) -> tuple[np.ndarray, np.ndarray]:
    """A, B of the yaw subsystem; input tau_psi [rad/s^2]."""
    return _double_integrator(ts)


def _lateral(ts: float, sign: float, g: float) -> tuple[np.ndarray, np.ndarray]:
    if not ts > 0:
        raise ValueError(f"ts must be > 0, got {ts!r}")
    a = np.array([[1.0, ts, 0.0, 0.0],
                  [0.0, 1.0, sign * g * ts, 0.0],
                  [0.0, 0.0, 1.0, ts],
                  [0.0, 0.0, 0.0, 1.0]])  # eq. 8 prints A(4,4) = T: erratum 2, it is 1
    b = np.array([[0.0], [0.0], [0.0], [ts]])
    return a, b


def linear_y_phi(ts: float, gravity_m_s2: float = 9.81) -> tuple[np.ndarray, np.ndarray]:
    """A, B of the small-angle y-phi subsystem (eq. 8, corrected A(4,4) = 1)."""
    return _lateral(ts, +1.0, gravity_m_s2)


def linear_x_theta(ts: float, gravity_m_s2: float = 9.81) -> tuple[np.ndarray, np.ndarray]:
    """A, B of the small-angle x-theta subsystem: as y-phi with A(2,3) = -g T (m x'' = -u sin theta)."""
    return _lateral(ts, -1.0, gravity_m_s2)
