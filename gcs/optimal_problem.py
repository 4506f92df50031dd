"""The altitude (z-psi) subproblem as an affine-LQ problem: eq. 16 at theta = phi = 0, eq. 17.

With theta = phi = 0 the z-psi subsystem of eq. 16 is affine with constant matrices
(:func:`gcs.model.z_psi_affine_model`).  In absolute coordinates ``s = [z, vz, yaw, yaw_rate]``
(z up, SI units)::

    s(k+1) = A s(k) + B v(k) + d
    A = [[1, Ts, 0, 0], [0, 1, 0, 0], [0, 0, 1, Ts], [0, 0, 0, 1]]
    B = [[0, 0], [Ts/m, 0], [0, 0], [0, Ts]]

with one of two input conventions (the ``u`` that R weighs in eq. 17):

* **gravity-compensated** (``nlsoc``, erratum 8): ``v = [thrust - m g, tau_psi]``, ``d = 0``;
* **literal** (``nlsoc-literal``, the printed law): ``v = [thrust, tau_psi]``,
  ``d = [0, -g Ts, 0, 0]``.

In error coordinates ``x(k) = s(k) - r(k)`` (r the mission reference: the takeoff ramp
and the hold, with its velocity)::

    x(k+1) = s(k+1) - r(k+1) = A x(k) + B v(k) + c(k),   c(k) = A r(k) - r(k+1) + d

so a reference that moves makes the error dynamics affine with a time-varying ``c(k)``.
Inside the ramp ``z_r(k+1) = z_r(k) + Ts vz_r`` and ``vz_r`` is constant, so the reference
part of ``c`` vanishes; where the ramp ends the velocity reference drops from the climb
rate to 0 and ``c_2 = vz_r(k) - vz_r(k+1)`` is the climb rate for that one step.  ``c`` is
computed from the reference the controllers see (:class:`gcs.mission.Mission`), so nothing
depends on this reasoning being exact.

The cost is eq. 17 with the NLSOC z-psi matrices (``config.nlsoc["z_psi"]``); its exact
optimum is :func:`gcs.control.riccati.affine_lqr` (:meth:`AltitudeProblem.solve`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gcs.config import Config
from gcs.control.riccati import affine_lqr
from gcs.errors import DesignError
from gcs.mission import Mission
from gcs.model import SUBSYSTEMS, z_psi_affine_model

__all__ = ["COST_CONVENTIONS", "UNCONSTRAINED", "reference_offsets", "AltitudeProblem", "altitude_problem",
           "unconstrained_config", "check_convention", "horizon_steps_of"]

#: Thrust [N] and angular-acceleration [rad/s^2] limits of the "unconstrained" controller copies.
UNCONSTRAINED = 1e9

#: Input conventions of the cost: ``"compensated"`` (R weighs thrust - m g) and ``"literal"`` (thrust).
COST_CONVENTIONS = ("compensated", "literal")

Z_PSI = list(SUBSYSTEMS["z_psi"])


def reference_offsets(A, refs, d=None) -> np.ndarray:
    """``c(k) = A r(k) - r(k+1) + d`` of the error dynamics ``x(k+1) = A x(k) + B v(k) + c(k)``.

    Parameters
    ----------
    A : array_like, shape (n, n)
    refs : array_like, shape (N + 1, n)
        Reference in the subsystem's coordinates at k = 0 .. N.
    d : array_like, shape (n,), or None
        Constant affine term of the absolute model (None = 0).

    Returns
    -------
    ndarray, shape (N, n)
    """
    a = np.asarray(A, float)
    refs = np.asarray(refs, float)
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise DesignError(f"A matrix must be square (n, n), got shape {a.shape}")
    n = a.shape[0]
    if refs.ndim != 2 or refs.shape[1] != n or refs.shape[0] < 2:
        raise DesignError(f"refs has shape {refs.shape}, expected (N + 1, {n}) with N >= 1")
    dd = np.zeros(n) if d is None else np.asarray(d, float)
    if dd.shape != (n,):
        raise DesignError(f"d has shape {dd.shape}, expected ({n},)")
    return refs[:-1] @ a.T - refs[1:] + dd



@dataclass(frozen=True)
class AltitudeProblem:
    """The z-psi affine-LQ problem of one config, horizon and cost convention.

    Attributes
    ----------
    experiment : str
    convention : {"compensated", "literal"}
        What R weighs: thrust - m g, or the thrust itself.
    ts_s : float
    horizon_steps : int
        N.
    mass_kg, gravity_m_s2 : float
    A : ndarray, shape (4, 4)
    B : ndarray, shape (4, 2)
    d : ndarray, shape (4,)
        Absolute-model offset (gravity for the literal convention, else 0).
    c : ndarray, shape (N, 4)
        Error-model offsets in time order, ``c[k] = A r(k) - r(k+1) + d``.
    Q, H : ndarray, shape (4, 4)
    R : ndarray, shape (2, 2)
        Eq. 17 weights: ``config.nlsoc["z_psi"]`` in the config's matrix mode.
    refs : ndarray, shape (N + 1, 12)
        The mission reference (full :class:`gcs.model.State` rows) at k = 0 .. N.
    """

    experiment: str
    convention: str
    ts_s: float
    horizon_steps: int
    mass_kg: float
    gravity_m_s2: float
    A: np.ndarray
    B: np.ndarray
    d: np.ndarray
    c: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    H: np.ndarray
    refs: np.ndarray

    @property
    def gravity_compensated(self) -> bool:
        return self.convention == "compensated"

    @property
    def hover_offset_n(self) -> float:
        """What is subtracted from the thrust to get the cost's input: m g or 0 [N]."""
        return self.mass_kg * self.gravity_m_s2 if self.gravity_compensated else 0.0

    def x0(self, start: Sequence[float] = (0.0, 0.0, 0.0, 0.0)) -> np.ndarray:
        """Initial error state ``s(0) - r(0)`` for the absolute start [z, vz, yaw, yaw_rate]
        (default: at rest on the ground)."""
        return np.asarray(start, float) - self.refs[0, Z_PSI]

    def solve(self):
        """:func:`affine_lqr` of this problem: ``K, k_ff, P, p, s``."""
        return affine_lqr(self.A, self.B, self.c, self.Q, self.R, self.H, self.horizon_steps)


def check_convention(convention: str) -> None:
    """Raise ValueError unless ``convention`` is one of :data:`COST_CONVENTIONS`."""
    if convention not in COST_CONVENTIONS:
        raise ValueError(f"convention must be one of {', '.join(COST_CONVENTIONS)}, got {convention!r}")


def horizon_steps_of(config: Config, horizon_s: float) -> int:
    """``horizon_s`` in control steps of ``config`` (ValueError unless a whole number >= 1)."""
    ts = config.experiment.ts_s
    if not (isinstance(horizon_s, (int, float)) and math.isfinite(horizon_s) and horizon_s >= ts):
        raise ValueError(f"horizon_s must be a number >= one step ({ts:g} s), got {horizon_s!r}")
    steps = horizon_s / ts
    if abs(steps - round(steps)) > 1e-6 * max(1.0, steps):
        raise ValueError(f"horizon {horizon_s:g} s is not a whole number of steps of {ts:g} s")
    return round(steps)


def altitude_problem(config: Config, horizon_s: float, convention: str = "compensated") -> AltitudeProblem:
    """Build the z-psi affine-LQ problem of ``config`` over ``horizon_s``.

    The reference is the config's mission (takeoff ramp, hold, ...), sampled at k Ts for
    k = 0 .. N exactly as :func:`gcs.sim.simulate` samples it, and held after the mission
    ends.  The weights are ``config.nlsoc["z_psi"]`` in the config's matrix mode.

    Parameters
    ----------
    config : Config
    horizon_s : float
        Horizon [s], a whole number of control periods.
    convention : {"compensated", "literal"}

    Returns
    -------
    AltitudeProblem
    """
    check_convention(convention)
    e, v = config.experiment, config.vehicle
    N = horizon_steps_of(config, horizon_s)
    a, b, d = z_psi_affine_model(e.ts_s, v.mass_kg, v.gravity_m_s2, gravity_compensated=(convention == "compensated"))
    mission = Mission(config.mission, zero_velocity=e.zero_velocity_reference)
    refs = np.array([mission.reference(k * e.ts_s) for k in range(N + 1)], float)
    c = reference_offsets(a, refs[:, Z_PSI], d)
    q, r, h = config.nlsoc["z_psi"].resolved(e.matrices)
    return AltitudeProblem(e.name, convention, e.ts_s, N, v.mass_kg, v.gravity_m_s2, a, b, d, c, q, r, h, refs)


def unconstrained_config(config: Config, horizon_s: float) -> Config:
    """A copy of ``config`` with horizon ``horizon_s`` and limits raised to :data:`UNCONSTRAINED`.

    ``after_horizon`` is irrelevant (the comparison never goes past the horizon).  The
    ``raw`` TOML of the copy is the original's: do not re-parse it.
    """
    horizon_steps_of(config, horizon_s)
    e = dataclasses.replace(config.experiment, horizon_s=float(horizon_s))
    v = dataclasses.replace(config.vehicle, max_thrust_n=UNCONSTRAINED, max_angular_accel_rad_s2=UNCONSTRAINED)
    return dataclasses.replace(config, experiment=e, vehicle=v)
