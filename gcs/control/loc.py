"""LOC: finite-horizon discrete LQR on the exactly linearised model (paper section 2).

Design (pure): :func:`finite_horizon_lqr` runs the backward Riccati recursion
in steps-to-go j (erratum 1: ``A - BF``, not ``A + BF``)::

    P(0) = H
    F(j) = (R + B' P(j-1) B)^-1 B' P(j-1) A
    P(j) = (A - B F(j))' P(j-1) (A - B F(j)) + F(j)' R F(j) + Q

and at time k the law applies ``u = -F(N - k) x``.  Policy: z through the
exact linearisation ``u = m (u1 + g) / (cos(theta) cos(phi))`` (eq. 3), yaw,
and the small-angle y-phi and x-theta subsystems, all in error coordinates
(state - reference, attitude references 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gcs.config import Config
from gcs.control.base import Controller, FiniteHorizonController, Limits, StagedLaw, wrap_angle
from gcs.errors import DesignError
from quadrotor.state import Command, State
from gcs.model import ModelParams, linear_psi, linear_x_theta, linear_y_phi, linear_z, tilt_cos

__all__ = ["finite_horizon_lqr", "LocDesign", "design_loc", "LocLaw", "make_loc"]


def _check_weights(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray, h: np.ndarray) -> None:
    n, m = b.shape
    if a.shape != (n, n):
        raise DesignError(f"A matrix is the wrong shape: {a.shape}, expected {(n, n)}")
    if q.shape != (n, n):
        raise DesignError(f"Q matrix is the wrong shape: {q.shape}, expected {(n, n)}")
    if h.shape != (n, n):
        raise DesignError(f"H matrix is the wrong shape: {h.shape}, expected {(n, n)}")
    if r.shape != (m, m):
        raise DesignError(f"R matrix is the wrong shape: {r.shape}, expected {(m, m)}")
    for name, mat in (("Q", q), ("H", h)):
        if not np.allclose(mat, mat.T):
            raise DesignError(f"{name} matrix is not symmetric")
        if np.linalg.eigvalsh(mat).min() < -1e-9 * max(1.0, np.abs(mat).max()):
            raise DesignError(f"{name} matrix is not positive semidefinite")
    if not np.allclose(r, r.T) or np.linalg.eigvalsh(r).min() <= 0:
        raise DesignError("R matrix is not symmetric positive definite")


def finite_horizon_lqr(A, B, Q, R, H, N: int, *, rtol: float = 1e-14) -> tuple[np.ndarray, np.ndarray]:
    """Finite-horizon discrete LQR gain table.

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
    Q, H : array_like, shape (n, n)
        Stage and terminal state weights, symmetric positive semidefinite.
    R : array_like, shape (m, m)
        Input weight, symmetric positive definite.
    N : int
        Horizon in steps, >= 1.
    rtol : float
        Once ``|P(j) - P(j-1)| <= rtol |P(j)|`` the recursion has reached its
        fixed point and the remaining entries repeat the last gain.

    Returns
    -------
    F : ndarray, shape (N, m, n)
        ``F[j - 1]`` is the gain with j steps to go; apply ``u(k) = -F[N - k - 1] x(k)``.
    P : ndarray, shape (N + 1, n, n)
        Cost-to-go matrices, ``P[0] = H``; the optimal cost from x(0) is ``x' P[N] x / 2``.
    """
    a, b = np.atleast_2d(np.asarray(A, float)), np.atleast_2d(np.asarray(B, float))
    q, r, h = (np.atleast_2d(np.asarray(x, float)) for x in (Q, R, H))
    if b.ndim != 2 or b.shape[0] != a.shape[0]:
        raise DesignError(f"B matrix is the wrong shape: {b.shape}")
    _check_weights(a, b, q, r, h)
    if int(N) != N or N < 1:
        raise DesignError(f"horizon N must be an integer >= 1, got {N!r}")
    n, m = b.shape
    F = np.empty((N, m, n))
    P = np.empty((N + 1, n, n))
    P[0] = h
    p = h
    for j in range(1, N + 1):
        f = np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)
        acl = a - b @ f
        p_new = acl.T @ p @ acl + f.T @ r @ f + q
        p_new = 0.5 * (p_new + p_new.T)
        F[j - 1] = f
        P[j] = p_new
        if np.max(np.abs(p_new - p)) <= rtol * np.max(np.abs(p_new)):
            F[j:] = f
            P[j + 1:] = p_new
            break
        p = p_new
    return F, P


@dataclass(frozen=True)
class LocDesign:
    """Gain tables of the four LOC subsystems, each shape (N, 1, n)."""

    ts_s: float
    horizon_steps: int
    F_z: np.ndarray
    F_psi: np.ndarray
    F_y_phi: np.ndarray
    F_x_theta: np.ndarray


def design_loc(config: Config) -> LocDesign:
    """Riccati gain tables for z (exact linearisation), psi, y-phi and x-theta."""
    e = config.experiment
    ts, n, g = e.ts_s, e.horizon_steps, config.vehicle.gravity_m_s2
    systems = {"z": linear_z(ts), "psi": linear_psi(ts), "y_phi": linear_y_phi(ts, g), "x_theta": linear_x_theta(ts, g)}
    tables = {}
    for name, (a, b) in systems.items():
        q, r, h = config.loc[name].resolved(e.matrices)
        try:
            tables[name], _ = finite_horizon_lqr(a, b, q, r, h, n)
        except DesignError as exc:
            raise DesignError(f"{config.source}: loc.{name}: {exc}") from None
    return LocDesign(ts, n, tables["z"], tables["psi"], tables["y_phi"], tables["x_theta"])


def _settled_length(table: np.ndarray) -> int:
    """Number of leading rows after which every row equals the last one."""
    differs = np.any(table[:, 0, :] != table[-1, 0, :], axis=1)
    idx = np.flatnonzero(differs)
    return int(idx[-1]) + 2 if idx.size else 1


class LocLaw(StagedLaw):
    """The LOC policy with j steps to go."""

    def __init__(self, design: LocDesign, model: ModelParams, limits: Limits) -> None:
        self.design = design
        self.model = model
        self.limits = limits
        # Plain lists of rows (a lookup and a 2- or 4-term dot product per subsystem), cut
        # where the recursion reached its fixed point: rows past it are all equal.
        tables = (design.F_z, design.F_psi, design.F_y_phi, design.F_x_theta)
        settled = max(_settled_length(t) for t in tables)
        self._settled = settled
        self._fz, self._fpsi, self._fy, self._fx = (t[:settled, 0, :].tolist() for t in tables)

    def step_j(self, j: int, state: State, ref: State) -> Command:
        i = (j if j < self._settled else self._settled) - 1
        phi, th = state[6], state[7]
        fz = self._fz[i]
        u1 = -(fz[0] * (state[2] - ref[2]) + fz[1] * (state[5] - ref[5]))
        thrust = self.model.mass_kg * (u1 + self.model.gravity_m_s2) / tilt_cos(phi, th)
        fp = self._fpsi[i]
        t_yaw = -(fp[0] * wrap_angle(state[8] - ref[8]) + fp[1] * (state[11] - ref[11]))
        fy = self._fy[i]
        t_roll = -(fy[0] * (state[1] - ref[1]) + fy[1] * (state[4] - ref[4]) + fy[2] * phi + fy[3] * state[9])
        fx = self._fx[i]
        t_pitch = -(fx[0] * (state[0] - ref[0]) + fx[1] * (state[3] - ref[3]) + fx[2] * th + fx[3] * state[10])
        return self.limits.saturate(thrust, t_roll, t_pitch, t_yaw)


def make_loc(config: Config, model: ModelParams, limits: Limits, fallback: Controller | None) -> FiniteHorizonController:
    """Design LOC for ``config`` and wrap it in its horizon schedule."""
    design = design_loc(config)
    e = config.experiment
    return FiniteHorizonController("loc", LocLaw(design, model, limits), e.horizon_steps, e.after_horizon, fallback)
