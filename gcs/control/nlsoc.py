"""NLSOC: suboptimal nonlinear finite-horizon control of affine systems (paper section 3).

For ``x(k+1) = f0(x) + f1(x) u`` and the cost
``x(N)' H x(N) / 2 + sum (x' Q x + u' R u) / 2`` the law is the one-step-ahead
minimiser of the next state's weighted cost::

    u(k) = -(f1' E f1 + R)^-1 f1' E f0(x(k)),   E = H at the last step (j = 1), else Q

evaluated at the current state (eq. 12 for the last step, its k >= 2 form after eq. 15;
erratum 4).  :func:`one_step_control` is the law in numpy (the reference, any n, m);
:func:`one_step_law` evaluates the same formula in plain Python for n = 4, m <= 2 and is
what flies (numpy costs microseconds per call; a test compares the two).

Applied to the models of :mod:`gcs.model` in error coordinates: z-psi (eq. 16,
:class:`gcs.model.ZPsiModel`), y-phi (eq. 20, :class:`gcs.model.YPhiModel`) and x-theta
(:class:`gcs.model.XThetaModel`).  :func:`design_nlsoc` takes the matrices;
:func:`design_nlsoc_from_config` reads them from a config.
``nlsoc`` flies the gravity-compensated law of erratum 8: the thrust is
``m g / (cos(theta) cos(phi))`` plus the same law applied to the model with the
``-g Ts`` term removed (R then weighs the deviation from hover);
``nlsoc-literal`` flies the printed law, which does not compensate gravity.
The x-theta matrices are the y-phi ones mirrored, ``E = S E S`` with
``S = diag(-1, -1, 1, 1)`` (erratum 6), unless the printed matrices are asked for.

A disturbance acceleration ``d`` (``step(..., disturbance_m_s2=d)``) enters f0 as gravity does
(:mod:`gcs.model`): the compensated thrust carries ``m (g - d_z) / (cos(theta) cos(phi))`` (the
literal law has ``-(g - d_z) Ts`` in f0), the lateral f0 have ``+ Ts d`` in their velocity rows,
and their angle states are measured from the tilt that balances ``d`` (:func:`gcs.model.disturbance_tilt`),
as the thrust is measured from hover: in steady state the law then holds the set point.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from gcs.config import Config
from gcs.control.base import (NO_DISTURBANCE, Controller, Disturbance, FiniteHorizonController, Limits, StagedLaw,
                              wrap_angle)
from gcs.control.smallmat import dot, mat_vec, vec_mat
from gcs.errors import DesignError
from gcs.model import AffineContext, ModelParams, XThetaModel, YPhiModel, ZPsiModel, disturbance_tilt, tilt_cos
from quadrotor.state import Command, State

__all__ = ["one_step_control", "one_step_law", "AffineSubsystem", "NlsocDesign", "design_nlsoc",
           "design_nlsoc_from_config", "nlsoc_weights", "NlsocLaw", "make_nlsoc", "z_psi_subsystem",
           "lateral_subsystem", "MIRROR", "NLSOC_SUBSYSTEMS"]

#: S = diag(-1, -1, 1, 1): maps y-phi coordinates to mirrored x-theta ones (erratum 6).
MIRROR = np.diag([-1.0, -1.0, 1.0, 1.0])

#: The subsystems NLSOC controls, in the order it flies them (z-psi first: its thrust feeds eq. 20).
NLSOC_SUBSYSTEMS = ("z_psi", "y_phi", "x_theta")


def one_step_control(f0, f1, E, R) -> np.ndarray:
    """The general NLSOC law ``u = -(f1' E f1 + R)^-1 f1' E f0`` (eq. 12; eq. 19 for z-psi), numpy.

    The reference for :func:`one_step_law`, for any n and m.

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


def one_step_law(f0: Sequence[float], f1: Sequence[Sequence[float]], E: Sequence[Sequence[float]],
                 R: Sequence[Sequence[float]]) -> list[float]:
    """The same law as :func:`one_step_control`, ``u = -(f1' E f1 + R)^-1 f1' E f0``, in plain Python.

    What flies at every control step: for n = 4 and m = 1 or 2 the products are written out
    (:mod:`gcs.control.smallmat`) and ``(f1' E f1 + R)`` is inverted in closed form; other
    sizes go to :func:`one_step_control`.  ``f1' E f1`` is evaluated as ``(f1' E) f1`` and
    ``f1' E f0`` as ``f1' (E f0)``: the rounding of the sparse loop that flew before, so the
    commands are the same to the last bit.

    Parameters
    ----------
    f0 : sequence of n floats
    f1 : n rows of m floats
    E : n rows of n floats
        H at the last step of the horizon, Q otherwise (need not be symmetric).
    R : m rows of m floats

    Returns
    -------
    list of m floats
    """
    if len(f0) != 4 or len(R) > 2:
        return one_step_control(f0, f1, E, R).tolist()
    Ef0 = mat_vec(E, f0)
    if len(R) == 1:
        (a0,), (a1,), (a2,), (a3,) = f1
        a = (a0, a1, a2, a3)                                   # f1's column
        g = R[0][0] + dot(vec_mat(a, E), a)                    # f1' E f1 + R
        return [-dot(a, Ef0) / g]                              # -(...)^-1 f1' E f0
    (a0, b0), (a1, b1), (a2, b2), (a3, b3) = f1
    a, b = (a0, a1, a2, a3), (b0, b1, b2, b3)                  # f1's columns
    aE, bE = vec_mat(a, E), vec_mat(b, E)                      # f1' E
    (r00, r01), (r10, r11) = R
    g00, g01 = r00 + dot(aE, a), r01 + dot(aE, b)              # G = f1' E f1 + R
    g10, g11 = r10 + dot(bE, a), r11 + dot(bE, b)
    h0, h1 = dot(a, Ef0), dot(b, Ef0)                          # f1' E f0
    det = g00 * g11 - g01 * g10
    return [-(g11 * h0 - g01 * h1) / det, -(g00 * h1 - g10 * h0) / det]   # -G^-1 (f1' E f0)


class AffineModel(Protocol):
    """An affine discrete model ``x(k+1) = f0(x, ctx) + f1(x, ctx) u`` (eq. 9), as in :mod:`gcs.model`."""

    n: int
    m: int

    def f0(self, x: Sequence[float], ctx: AffineContext) -> Sequence[float]: ...

    def f1(self, x: Sequence[float], ctx: AffineContext) -> Sequence[Sequence[float]]: ...


@dataclass(frozen=True)
class AffineSubsystem:
    """An affine subsystem (its model, eq. 16 or eq. 20) with the weights of its cost (eq. 17).

    Attributes
    ----------
    name : str
    model : AffineModel
        ``f0(x, ctx)`` and ``f1(x, ctx)`` (n = ``model.n``, m = ``model.m``).
    Q, R, H : ndarray, shapes (n, n), (m, m), (n, n)
    """

    name: str
    model: AffineModel
    Q: np.ndarray
    R: np.ndarray
    H: np.ndarray

    def __post_init__(self) -> None:
        n, m = self.model.n, self.model.m
        for name, mat, shape in (("Q", self.Q, (n, n)), ("H", self.H, (n, n)), ("R", self.R, (m, m))):
            if np.shape(mat) != shape:
                raise DesignError(f"{self.name}: {name} matrix is the wrong shape: {np.shape(mat)}, expected {shape}")
        if np.linalg.eigvalsh(0.5 * (self.R + self.R.T)).min() <= 0:
            raise DesignError(f"{self.name}: R matrix is not positive definite")
        # The weights as lists of rows, for one_step_law: E = H at the last step, Q before.
        object.__setattr__(self, "_E", {True: self.H.tolist(), False: self.Q.tolist()})
        object.__setattr__(self, "_R", self.R.tolist())

    @property
    def n(self) -> int:
        return self.model.n

    @property
    def m(self) -> int:
        return self.model.m

    def f1_dense(self, x: Sequence[float] | None, ctx: AffineContext) -> np.ndarray:
        """f1 as an (n, m) array."""
        return np.array(self.model.f1(x, ctx), float).reshape(self.n, self.m)

    def control(self, j: int, x: Sequence[float], ctx: AffineContext) -> list[float]:
        """The law with j steps to go (E = H when j == 1, else Q), as a list of m floats."""
        E = self._E[j == 1]  # type: ignore[attr-defined]
        model = self.model
        return one_step_law(model.f0(x, ctx), model.f1(x, ctx), E, self._R)  # type: ignore[attr-defined]


def _weights(Q, R, H) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return np.asarray(Q, float), np.atleast_2d(np.asarray(R, float)), np.asarray(H, float)


def z_psi_subsystem(ts: float, model: ModelParams, Q, R, H, *, gravity_in_f0: bool) -> AffineSubsystem:
    """Eq. 16 (:class:`gcs.model.ZPsiModel`) in error coordinates with its weights.

    State [e_z, e_vz, e_yaw, e_yaw_rate], input [u, tau_psi]; with ``gravity_in_f0=False``
    the ``-g Ts`` term is dropped: the input is then the thrust deviation from hover (erratum 8).
    """
    zp = ZPsiModel(ts, model.mass_kg, model.gravity_m_s2, gravity_in_f0=gravity_in_f0)
    return AffineSubsystem("z_psi", zp, *_weights(Q, R, H))


def lateral_subsystem(axis: str, ts: float, model: ModelParams, Q, R, H) -> AffineSubsystem:
    """y-phi (eq. 20, :class:`gcs.model.YPhiModel`) or x-theta (:class:`gcs.model.XThetaModel`)
    in error coordinates, state [e_pos, e_vel, angle, rate], input tau, with its weights.

    The velocity row uses the thrust applied this step (``ctx.thrust_n``).
    """
    models = {"y_phi": YPhiModel, "x_theta": XThetaModel}
    if axis not in models:
        raise ValueError(f"axis must be 'y_phi' or 'x_theta', got {axis!r}")
    return AffineSubsystem(axis, models[axis](ts, model.mass_kg), *_weights(Q, R, H))


@dataclass(frozen=True)
class NlsocDesign:
    """The three affine subsystems with their weights."""

    ts_s: float
    horizon_steps: int
    gravity_compensated: bool
    z_psi: AffineSubsystem
    y_phi: AffineSubsystem
    x_theta: AffineSubsystem


def design_nlsoc(ts_s: float, mass_kg: float, gravity_m_s2: float, weights: Mapping[str, tuple],
                 horizon_steps: int, *, gravity_compensated: bool = True) -> NlsocDesign:
    """The NLSOC subsystems: eq. 16 (z-psi) and eq. 20 (y-phi, x-theta) with their weights.

    Parameters
    ----------
    ts_s : float
        Sampling period [s].
    mass_kg, gravity_m_s2 : float
        The model's mass [kg] and gravity [m/s^2].
    weights : mapping
        ``{"z_psi": (Q, R, H), "y_phi": ..., "x_theta": ...}``: Q, H shape (4, 4); R shape
        (2, 2) for z-psi, (1, 1) for the lateral subsystems.  Used as given (mirror the x-theta
        ones beforehand, erratum 6: :func:`nlsoc_weights`).
    horizon_steps : int
        N (the law only needs to know the last step, j = 1).
    gravity_compensated : bool
        True: z-psi without the ``-g Ts`` term, the thrust law adds hover (erratum 8, ``nlsoc``);
        False: the printed law (``nlsoc-literal``).

    Returns
    -------
    NlsocDesign

    Raises
    ------
    gcs.errors.DesignError
        Wrong shapes, R not positive definite (message prefixed ``nlsoc.<subsystem>``).
    """
    model = ModelParams(mass_kg, gravity_m_s2)
    try:
        zp = z_psi_subsystem(ts_s, model, *weights["z_psi"], gravity_in_f0=not gravity_compensated)
        yp = lateral_subsystem("y_phi", ts_s, model, *weights["y_phi"])
        xt = lateral_subsystem("x_theta", ts_s, model, *weights["x_theta"])
    except DesignError as exc:
        raise DesignError(f"nlsoc.{exc}") from None
    return NlsocDesign(ts_s, horizon_steps, gravity_compensated, zp, yp, xt)


def nlsoc_weights(config: Config) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``{subsystem: (Q, R, H)}`` of the config's NLSOC matrices in its matrix mode (corrected or
    printed), the x-theta ones mirrored, ``S E S``, where the config asks for it (erratum 6)."""
    e = config.experiment
    out = {}
    for name in NLSOC_SUBSYSTEMS:
        ms = config.nlsoc[name]
        q, r, h = ms.resolved(e.matrices)
        if ms.mirror and e.matrices == "corrected":
            q, h = MIRROR @ q @ MIRROR, MIRROR @ h @ MIRROR
        out[name] = (q, r, h)
    return out


def design_nlsoc_from_config(config: Config, *, gravity_compensated: bool = True) -> NlsocDesign:
    """:func:`design_nlsoc` for ``config`` (its period, vehicle, :func:`nlsoc_weights` and horizon)."""
    e, v = config.experiment, config.vehicle
    try:
        return design_nlsoc(e.ts_s, v.mass_kg, v.gravity_m_s2, nlsoc_weights(config), e.horizon_steps,
                            gravity_compensated=gravity_compensated)
    except DesignError as exc:
        raise DesignError(f"{config.source}: {exc}") from None


class NlsocLaw(StagedLaw):
    """The NLSOC policy with j steps to go: z-psi first, then the lateral laws with the applied thrust."""

    def __init__(self, design: NlsocDesign, model: ModelParams, limits: Limits) -> None:
        self.design = design
        self.model = model
        self.limits = limits
        self._ctx = AffineContext()
        self._hover_n = model.hover_thrust_n if design.gravity_compensated else None

    def step_j(self, j: int, state: State, ref: State, disturbance_m_s2: Disturbance = NO_DISTURBANCE) -> Command:
        d = self.design
        ctx = self._ctx
        phi, th = state[6], state[7]
        ctx.set_attitude(phi, th)
        ctx.accel_x, ctx.accel_y, ctx.accel_z = dx, dy, dz = disturbance_m_s2
        ez = (state[2] - ref[2], state[5] - ref[5], wrap_angle(state[8] - ref[8]), state[11] - ref[11])
        du, t_yaw = d.z_psi.control(j, ez, ctx)
        # erratum 8: the compensated law's input is the thrust beyond hover (hover against g - d_z)
        hover = self._hover_n
        if hover is not None and dz:
            hover = self.model.mass_kg * (self.model.gravity_m_s2 - dz)
        thrust = du if hover is None else hover / tilt_cos(phi, th) + du
        umax = self.limits.max_thrust_n
        ctx.thrust_n = thrust = 0.0 if thrust < 0.0 else umax if thrust > umax else thrust
        phi_d, th_d = disturbance_tilt(thrust, self.model.mass_kg, self.model.gravity_m_s2, dx, dy)
        ey = (state[1] - ref[1], state[4] - ref[4], phi - phi_d, state[9])
        (t_roll,) = d.y_phi.control(j, ey, ctx)
        ex = (state[0] - ref[0], state[3] - ref[3], th - th_d, state[10])
        (t_pitch,) = d.x_theta.control(j, ex, ctx)
        return self.limits.saturate(thrust, t_roll, t_pitch, t_yaw)


def make_nlsoc(config: Config, model: ModelParams, limits: Limits, fallback: Controller | None,
               *, name: str = "nlsoc", gravity_compensated: bool = True) -> FiniteHorizonController:
    """Design NLSOC for ``config`` and wrap it in its horizon schedule (``name`` and the gravity
    handling come from the controller's :class:`gcs.control.registry.ControllerSpec`)."""
    design = design_nlsoc_from_config(config, gravity_compensated=gravity_compensated)
    e = config.experiment
    return FiniteHorizonController(name, NlsocLaw(design, model, limits), e.horizon_steps, e.after_horizon, fallback)
