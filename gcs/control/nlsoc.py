"""NLSOC: suboptimal nonlinear finite-horizon control of affine systems (paper section 3).

For ``x(k+1) = f0(x) + f1(x) u`` and the cost
``x(N)' H x(N) / 2 + sum (x' Q x + u' R u) / 2`` the law is the one-step-ahead
minimiser of the next state's weighted cost::

    u(k) = -(f1' E f1 + R)^-1 f1' E f0(x(k)),   E = H at the last step (j = 1), else Q

evaluated at the current state (erratum 4).  :func:`one_step_control` is the
general law in matrix form (the reference); :class:`AffineSubsystem` flies it
without numpy, looping over the structural non-zeros of f1 only, which gives
the same numbers at a fraction of the cost (a test compares them).

Applied to z-psi (eq. 16), y-phi and x-theta (eq. 20) in error coordinates.
``nlsoc`` flies the gravity-compensated law of erratum 8: the thrust is
``m g / (cos(theta) cos(phi))`` plus the same law applied to the model with the
``-g Ts`` term removed (R then weighs the deviation from hover);
``nlsoc-literal`` flies the printed law, which does not compensate gravity.
The x-theta matrices are the y-phi ones mirrored, ``E = S E S`` with
``S = diag(-1, -1, 1, 1)`` (erratum 6), unless the printed matrices are asked for.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from gcs.config import Config
from gcs.control.base import Controller, FiniteHorizonController, Limits, StagedLaw, wrap_angle
from gcs.errors import DesignError
from quadrotor.state import Command, State
from gcs.model import ModelParams, tilt_cos

__all__ = ["one_step_control", "AffineSubsystem", "NlsocDesign", "design_nlsoc", "NlsocLaw", "make_nlsoc",
           "z_psi_subsystem", "lateral_subsystem", "MIRROR"]

#: S = diag(-1, -1, 1, 1): maps y-phi coordinates to mirrored x-theta ones (erratum 6).
MIRROR = np.diag([-1.0, -1.0, 1.0, 1.0])

_dot = operator.mul


def one_step_control(f0, f1, E, R) -> np.ndarray:
    """The general NLSOC law ``u = -(f1' E f1 + R)^-1 f1' E f0``.

    Parameters
    ----------
    f0 : array_like, shape (n,)
        Drift term evaluated at the current state.
    f1 : array_like, shape (n, m)
        Input matrix evaluated at the current state.
    E : array_like, shape (n, n)
        H at the last step of the horizon, Q otherwise.
    R : array_like, shape (m, m)
        Positive definite input weight.

    Returns
    -------
    ndarray, shape (m,)
    """
    f0 = np.asarray(f0, float).reshape(-1)
    f1 = np.asarray(f1, float)
    if f1.ndim == 1:
        f1 = f1.reshape(-1, 1)
    E, R = np.atleast_2d(np.asarray(E, float)), np.atleast_2d(np.asarray(R, float))
    n, m = f1.shape
    if f0.shape != (n,):
        raise ValueError(f"f0 has shape {f0.shape}, expected ({n},)")
    if E.shape != (n, n):
        raise ValueError(f"E matrix is the wrong shape: {E.shape}, expected {(n, n)}")
    if R.shape != (m, m):
        raise ValueError(f"R matrix is the wrong shape: {R.shape}, expected {(m, m)}")
    return -np.linalg.solve(f1.T @ E @ f1 + R, f1.T @ E @ f0)


@dataclass(frozen=True)
class AffineSubsystem:
    """An affine discrete system ``x+ = f0(x, ctx) + f1(x, ctx) u`` with its weights.

    Attributes
    ----------
    name : str
    n, m : int
        State and input sizes.
    f0 : callable (x, ctx) -> list of n floats
    f1_pattern : tuple of (row, column)
        Structural non-zeros of f1 (all entries for a dense f1).
    f1_values : callable (x, ctx) -> list of floats, one per pattern entry
    Q, R, H : ndarray
    """

    name: str
    n: int
    m: int
    f0: Callable[[Sequence[float], object], list]
    f1_pattern: tuple[tuple[int, int], ...]
    f1_values: Callable[[Sequence[float], object], list]
    Q: np.ndarray
    R: np.ndarray
    H: np.ndarray

    def __post_init__(self) -> None:
        for name, mat, shape in (("Q", self.Q, (self.n, self.n)), ("H", self.H, (self.n, self.n)), ("R", self.R, (self.m, self.m))):
            if np.shape(mat) != shape:
                raise DesignError(f"{self.name}: {name} matrix is the wrong shape: {np.shape(mat)}, expected {shape}")
        if np.linalg.eigvalsh(0.5 * (self.R + self.R.T)).min() <= 0:
            raise DesignError(f"{self.name}: R matrix is not positive definite")
        object.__setattr__(self, "_rows", {True: self.H.tolist(), False: self.Q.tolist()})
        object.__setattr__(self, "_r", self.R.tolist())

    def f1_dense(self, x: Sequence[float], ctx: object) -> np.ndarray:
        """f1 as an (n, m) array."""
        out = np.zeros((self.n, self.m))
        for (i, a), v in zip(self.f1_pattern, self.f1_values(x, ctx)):
            out[i, a] = v
        return out

    def control(self, j: int, x: Sequence[float], ctx: object) -> list[float]:
        """The law with j steps to go (E = H when j == 1, else Q), as a list of m floats."""
        E = self._rows[j == 1]  # type: ignore[attr-defined]
        f0 = self.f0(x, ctx)
        vals = self.f1_values(x, ctx)
        pat = self.f1_pattern
        m = self.m
        b = [0.0] * m
        M = [row[:] for row in self._r]  # type: ignore[attr-defined]
        for (i, a), v in zip(pat, vals):
            Ei = E[i]
            b[a] += v * sum(map(_dot, Ei, f0))
            for (i2, a2), v2 in zip(pat, vals):
                M[a][a2] += v * Ei[i2] * v2
        if m == 1:
            return [-b[0] / M[0][0]]
        if m == 2:
            (p, q), (r, s) = M
            det = p * s - q * r
            return [-(s * b[0] - q * b[1]) / det, -(p * b[1] - r * b[0]) / det]
        return (-np.linalg.solve(np.array(M), np.array(b))).tolist()


@dataclass
class _Ctx:
    """Per-step context of the subsystem models: attitude and the thrust applied."""

    cos_roll: float = 1.0
    sin_roll: float = 0.0
    cos_pitch: float = 1.0
    sin_pitch: float = 0.0
    thrust_n: float = 0.0


def z_psi_subsystem(ts: float, model: ModelParams, Q, R, H, *, gravity_in_f0: bool) -> AffineSubsystem:
    """Eq. 16 in error coordinates, state [e_z, e_vz, e_yaw, e_yaw_rate], input [u, tau_psi].

    With ``gravity_in_f0=False`` the ``-g Ts`` term is dropped: the input is then the
    thrust deviation from hover (erratum 8).
    """
    gts = model.gravity_m_s2 * ts if gravity_in_f0 else 0.0
    k = ts / model.mass_kg

    def f0(x, ctx):
        return [x[0] + ts * x[1], x[1] - gts, x[2] + ts * x[3], x[3]]

    def f1_values(x, ctx):
        return [k * ctx.cos_pitch * ctx.cos_roll, ts]

    return AffineSubsystem("z_psi", 4, 2, f0, ((1, 0), (3, 1)), f1_values,
                           np.asarray(Q, float), np.asarray(R, float), np.asarray(H, float))


def lateral_subsystem(axis: str, ts: float, model: ModelParams, Q, R, H) -> AffineSubsystem:
    """y-phi (eq. 20) or x-theta in error coordinates, state [e_pos, e_vel, angle, rate], input tau.

    The velocity row uses the thrust applied this step: ``+Ts u cos(theta) sin(phi) / m``
    for y, ``-Ts u sin(theta) / m`` for x.
    """
    k = ts / model.mass_kg
    if axis == "y_phi":
        def f0(x, ctx):
            return [x[0] + ts * x[1], x[1] + k * ctx.thrust_n * ctx.cos_pitch * ctx.sin_roll, x[2] + ts * x[3], x[3]]
    elif axis == "x_theta":
        def f0(x, ctx):
            return [x[0] + ts * x[1], x[1] - k * ctx.thrust_n * ctx.sin_pitch, x[2] + ts * x[3], x[3]]
    else:
        raise ValueError(f"axis must be 'y_phi' or 'x_theta', got {axis!r}")

    def f1_values(x, ctx):
        return [ts]

    return AffineSubsystem(axis, 4, 1, f0, ((3, 0),), f1_values,
                           np.asarray(Q, float), np.asarray(R, float), np.asarray(H, float))


@dataclass(frozen=True)
class NlsocDesign:
    """The three affine subsystems with their weights."""

    ts_s: float
    horizon_steps: int
    gravity_compensated: bool
    z_psi: AffineSubsystem
    y_phi: AffineSubsystem
    x_theta: AffineSubsystem


def design_nlsoc(config: Config, model: ModelParams, *, gravity_compensated: bool = True) -> NlsocDesign:
    """Resolve the matrices (corrected or printed, x-theta mirrored) and build the subsystems."""
    e = config.experiment
    mats = {}
    for name in ("z_psi", "y_phi", "x_theta"):
        ms = config.nlsoc[name]
        q, r, h = ms.resolved(e.matrices)
        if ms.mirror and e.matrices == "corrected":
            q, h = MIRROR @ q @ MIRROR, MIRROR @ h @ MIRROR
        mats[name] = (q, r, h)
    try:
        zp = z_psi_subsystem(e.ts_s, model, *mats["z_psi"], gravity_in_f0=not gravity_compensated)
        yp = lateral_subsystem("y_phi", e.ts_s, model, *mats["y_phi"])
        xt = lateral_subsystem("x_theta", e.ts_s, model, *mats["x_theta"])
    except DesignError as exc:
        raise DesignError(f"{config.source}: nlsoc.{exc}") from None
    return NlsocDesign(e.ts_s, e.horizon_steps, gravity_compensated, zp, yp, xt)


class NlsocLaw(StagedLaw):
    """The NLSOC policy with j steps to go: z-psi first, then the lateral laws with the applied thrust."""

    def __init__(self, design: NlsocDesign, model: ModelParams, limits: Limits) -> None:
        self.design = design
        self.model = model
        self.limits = limits
        self._ctx = _Ctx()

    def step_j(self, j: int, state: State, ref: State) -> Command:
        d = self.design
        ctx = self._ctx
        phi, th = state[6], state[7]
        ctx.cos_roll, ctx.sin_roll = math.cos(phi), math.sin(phi)
        ctx.cos_pitch, ctx.sin_pitch = math.cos(th), math.sin(th)
        ez = (state[2] - ref[2], state[5] - ref[5], wrap_angle(state[8] - ref[8]), state[11] - ref[11])
        du, t_yaw = d.z_psi.control(j, ez, ctx)
        if d.gravity_compensated:
            thrust = self.model.hover_thrust_n / tilt_cos(phi, th) + du
        else:
            thrust = du
        umax = self.limits.max_thrust_n
        thrust = 0.0 if thrust < 0.0 else umax if thrust > umax else thrust
        ctx.thrust_n = thrust
        ey = (state[1] - ref[1], state[4] - ref[4], phi, state[9])
        (t_roll,) = d.y_phi.control(j, ey, ctx)
        ex = (state[0] - ref[0], state[3] - ref[3], th, state[10])
        (t_pitch,) = d.x_theta.control(j, ex, ctx)
        return self.limits.saturate(thrust, t_roll, t_pitch, t_yaw)


def make_nlsoc(config: Config, model: ModelParams, limits: Limits, fallback: Controller | None,
               *, gravity_compensated: bool = True) -> FiniteHorizonController:
    """Design NLSOC for ``config`` and wrap it in its horizon schedule."""
    design = design_nlsoc(config, model, gravity_compensated=gravity_compensated)
    e = config.experiment
    name = "nlsoc" if gravity_compensated else "nlsoc-literal"
    return FiniteHorizonController(name, NlsocLaw(design, model, limits), e.horizon_steps, e.after_horizon, fallback)
