"""The controllers' own quadratic cost J, eq. 5 (LOC) and eq. 17 (NLSOC), written once.

Per control step k, with e = state - reference and ``c = cos(phi) cos(theta)`` floored at
:data:`gcs.model.MIN_TILT_COS`:

``"loc"`` (eq. 5, the z subsystem after the exact linearisation eq. 3)
    ``x = [e_z, e_vz]``, ``u = u1 = thrust c / m - g``.
``"nlsoc"`` (eq. 17, the z-psi subsystem)
    ``x = [e_z, e_vz, wrap(e_psi), e_psi_rate]``,
    ``u = [thrust - m g / c, tau_psi]`` (gravity-compensated, ``nlsoc``) or
    ``u = [thrust, tau_psi]`` (the printed law, ``nlsoc-literal``).

``J = 1/2 sum_{k<M} (x(k)' Q x(k) + u(k)' R u(k)) + 1/2 x(M)' H x(M)``, M = min(N, K) for a
flight of K steps.  The stage terms ``(1/2 x'Qx, 1/2 u'Ru, their sum)`` come in two forms:
vectorised over a flight (:func:`stage_costs`, :func:`flight_cost`) and per tick in plain
Python (:class:`StageCost`, for the flight log, which computes them at every tick in its own
process).  Both take x and u from :func:`cost_state` / :func:`cost_input` (the definition).
Which cost a controller has comes from its :class:`gcs.control.registry.ControllerSpec`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from operator import mul
from typing import Any

import numpy as np

from gcs.config import Config
from gcs.control.base import wrap_angle
from gcs.control.registry import REGISTRY
from gcs.model import MIN_TILT_COS, SUBSYSTEMS

__all__ = ["COST_KINDS", "COST_EQUATION", "COST_WEIGHTS", "CostSpec", "controller_cost", "cost_state", "cost_input",
           "cost_variables", "quadratic_cost", "stage_costs", "flight_cost", "flight_stage_costs", "StageCost"]

#: The two costs: ``"loc"`` and ``"nlsoc"``.
COST_KINDS = ("loc", "nlsoc")
#: Equation number of each cost.
COST_EQUATION = {"loc": 5, "nlsoc": 17}
#: (config section, subsystem) whose Q, R, H each cost uses.
COST_WEIGHTS = {"loc": ("loc", "z"), "nlsoc": ("nlsoc", "z_psi")}
#: Indices of each cost's x into :class:`gcs.model.State`.
_STATE_INDEX = {"loc": SUBSYSTEMS["z"], "nlsoc": SUBSYSTEMS["z_psi"]}


@dataclass(frozen=True)
class CostSpec:
    """What J of a controller weighs: eq. 5 (``"loc"``) or eq. 17 (``"nlsoc"``).

    Attributes
    ----------
    kind : {"loc", "nlsoc"}
    Q, R, H : ndarray
        Shapes (n, n), (m, m), (n, n): n = 2, m = 1 for ``"loc"``; n = 4, m = 2 for ``"nlsoc"``.
    horizon_steps : int
        N.
    gravity_compensated : bool
        eq. 17's u is the thrust beyond hover (True) or the thrust (False); eq. 5 ignores it.
    """

    kind: str
    Q: np.ndarray
    R: np.ndarray
    H: np.ndarray
    horizon_steps: int
    gravity_compensated: bool = True

    def to_dict(self, mass_kg: float, gravity_m_s2: float) -> dict[str, Any]:
        """A picklable plain-Python description for :meth:`StageCost.from_dict` (keys ``kind``,
        ``Q``, ``R``, ``gravity_compensated``, ``mass_kg``, ``gravity_m_s2``)."""
        return {"kind": self.kind, "Q": [list(map(float, r)) for r in self.Q],
                "R": [list(map(float, r)) for r in self.R], "gravity_compensated": bool(self.gravity_compensated),
                "mass_kg": float(mass_kg), "gravity_m_s2": float(gravity_m_s2)}


def controller_cost(name: str, config: Config) -> CostSpec | None:
    """The cost J of controller ``name`` (its spec's ``cost``; None for PD and for unknown names)."""
    spec = REGISTRY.get(name)
    if spec is None or spec.cost is None:
        return None
    e = config.experiment
    section, subsystem = COST_WEIGHTS[spec.cost]
    q, r, h = getattr(config, section)[subsystem].resolved(e.matrices)
    return CostSpec(spec.cost, q, r, h, e.horizon_steps, gravity_compensated=spec.gravity_compensated)


# --------------------------------------------------------------------------- the definition

def cost_state(kind: str, state, ref):
    """x of the cost: ``state - ref`` at the cost's indices, e_psi wrapped (eq. 17).

    Parameters
    ----------
    kind : {"loc", "nlsoc"}
    state, ref : ndarray, shape (K, 12), or sequences of 12 floats (one tick)

    Returns
    -------
    ndarray, shape (K, n), or a list of n floats for one tick
    """
    idx = _STATE_INDEX[kind]
    if isinstance(state, np.ndarray) and state.ndim == 2:
        x = state[:, idx] - np.asarray(ref)[:, idx]
        if kind == "nlsoc":
            x[:, 2] = wrap_angle(x[:, 2])
        return x
    x = [state[i] - ref[i] for i in idx]
    if kind == "nlsoc":
        x[2] = wrap_angle(x[2])
    return x


def cost_input(kind: str, thrust_n, tau_psi, cos_tilt, mass_kg: float, gravity_m_s2: float,
               gravity_compensated: bool = True) -> tuple:
    """u of the cost, elementwise (floats or arrays alike).

    Parameters
    ----------
    kind : {"loc", "nlsoc"}
    thrust_n, tau_psi : float or ndarray
        Applied thrust [N] and yaw angular acceleration [rad/s^2].
    cos_tilt : float or ndarray
        ``cos(phi) cos(theta)`` floored at :data:`gcs.model.MIN_TILT_COS`.
    mass_kg, gravity_m_s2 : float
    gravity_compensated : bool
        eq. 17 only: subtract the hover thrust ``m g / cos_tilt``.

    Returns
    -------
    tuple
        ``(u1,)`` for eq. 5, ``(thrust input, tau_psi)`` for eq. 17.
    """
    if kind == "loc":
        return (thrust_n * cos_tilt / mass_kg - gravity_m_s2,)
    return (thrust_n - (mass_kg * gravity_m_s2 / cos_tilt if gravity_compensated else 0.0), tau_psi)


def cost_variables(kind: str, state: np.ndarray, ref: np.ndarray, command: np.ndarray, mass_kg: float,
                   gravity_m_s2: float, gravity_compensated: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """x and u of a flight.

    Parameters
    ----------
    state, ref : ndarray, shape (S, 12), S >= K
        States and references (a flight record holds K + 1 of each).
    command : ndarray, shape (K, 4)
        Applied commands; u(k) uses the attitude of ``state[k]``.

    Returns
    -------
    x : ndarray, shape (S, n)
    u : ndarray, shape (K, m)
    """
    k = command.shape[0]
    x = cost_state(kind, state, ref)
    cc = np.maximum(np.cos(state[:k, 6]) * np.cos(state[:k, 7]), MIN_TILT_COS)
    u = np.column_stack(cost_input(kind, command[:, 0], command[:, 3], cc, mass_kg, gravity_m_s2,
                                   gravity_compensated))
    return x, u


def quadratic_cost(x: np.ndarray, u: np.ndarray, Q, R, H) -> float:
    """``1/2 sum_{k<M} (x'Qx + u'Ru) + 1/2 x(M)' H x(M)`` with M = len(u); x has at least M + 1 rows."""
    m_steps = u.shape[0]
    xs = x[:m_steps]
    stage = np.einsum("ki,ij,kj->", xs, Q, xs) + np.einsum("ki,ij,kj->", u, R, u)
    xf = x[m_steps]
    return float(0.5 * stage + 0.5 * xf @ H @ xf)


def stage_costs(x: np.ndarray, u: np.ndarray, Q, R) -> np.ndarray:
    """``[1/2 x'Qx, 1/2 u'Ru, their sum]`` at each of the len(u) steps, shape (K, 3)."""
    k = u.shape[0]
    xs = 0.5 * np.einsum("ki,ij,kj->k", x[:k], Q, x[:k])
    us = 0.5 * np.einsum("ki,ij,kj->k", u, R, u)
    return np.column_stack([xs, us, xs + us])


def flight_cost(state: np.ndarray, ref: np.ndarray, command: np.ndarray, cost: CostSpec, mass_kg: float,
                gravity_m_s2: float) -> float:
    """J of a flight record (K + 1 states and references, K commands), over M = min(N, K) steps."""
    x, u = cost_variables(cost.kind, state, ref, command, mass_kg, gravity_m_s2, cost.gravity_compensated)
    m_steps = min(cost.horizon_steps, command.shape[0])
    return quadratic_cost(x, u[:m_steps], cost.Q, cost.R, cost.H)


def flight_stage_costs(state: np.ndarray, ref: np.ndarray, command: np.ndarray, cost: CostSpec, mass_kg: float,
                       gravity_m_s2: float) -> np.ndarray:
    """Stage terms ``[1/2 x'Qx, 1/2 u'Ru, sum]`` at each of the K ticks, shape (K, 3).

    ``J = sum of the third column over the first min(N, K) ticks + 1/2 x(M)' H x(M)``
    (:func:`flight_cost`).  ``state`` and ``ref`` may hold K or K + 1 rows.
    """
    k = command.shape[0]
    x, u = cost_variables(cost.kind, state[:k], ref[:k], command, mass_kg, gravity_m_s2, cost.gravity_compensated)
    return stage_costs(x, u, cost.Q, cost.R)


# --------------------------------------------------------------------------- one tick, plain Python

def _half_quad(v: Sequence[float], M: Sequence[Sequence[float]]) -> float:
    """``v' M v / 2``."""
    total = 0.0
    for vi, row in zip(v, M, strict=True):
        total += vi * sum(map(mul, row, v))
    return 0.5 * total


class StageCost:
    """Stage terms ``(1/2 x'Qx, 1/2 u'Ru, sum)`` of a cost at one tick, in plain Python.

    The same x and u as :func:`flight_stage_costs` (:func:`cost_state`, :func:`cost_input`),
    equal to it to rounding.  Picklable; build it from a :class:`CostSpec` (:meth:`from_spec`)
    or from :meth:`CostSpec.to_dict` in another process (:meth:`from_dict`).

    Parameters
    ----------
    kind : {"loc", "nlsoc"}
    Q, R : sequences of rows (shapes (n, n) and (m, m))
    mass_kg, gravity_m_s2 : float
    gravity_compensated : bool
    """

    def __init__(self, kind: str, Q, R, mass_kg: float, gravity_m_s2: float, gravity_compensated: bool = True) -> None:
        if kind not in COST_KINDS:
            raise ValueError(f"kind must be one of {', '.join(COST_KINDS)}, got {kind!r}")
        self.kind = kind
        self.Q = [[float(v) for v in row] for row in Q]
        self.R = [[float(v) for v in row] for row in R]
        self.mass_kg, self.gravity_m_s2 = float(mass_kg), float(gravity_m_s2)
        self.gravity_compensated = bool(gravity_compensated)

    @classmethod
    def from_spec(cls, cost: CostSpec, mass_kg: float, gravity_m_s2: float) -> StageCost:
        return cls(cost.kind, cost.Q, cost.R, mass_kg, gravity_m_s2, cost.gravity_compensated)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> StageCost:
        """From :meth:`CostSpec.to_dict` (``gravity_compensated`` defaults to True)."""
        return cls(d["kind"], d["Q"], d["R"], d["mass_kg"], d["gravity_m_s2"], d.get("gravity_compensated", True))

    def terms(self, state: Sequence[float], ref: Sequence[float],
              command: Sequence[float]) -> tuple[float, float, float]:
        """``(1/2 x'Qx, 1/2 u'Ru, sum)`` for one tick's state, reference (12 floats each) and command (4)."""
        cc = math.cos(state[6]) * math.cos(state[7])
        x = cost_state(self.kind, state, ref)
        u = cost_input(self.kind, command[0], command[3], cc if cc > MIN_TILT_COS else MIN_TILT_COS,
                       self.mass_kg, self.gravity_m_s2, self.gravity_compensated)
        xs, us = _half_quad(x, self.Q), _half_quad(u, self.R)
        return xs, us, xs + us
