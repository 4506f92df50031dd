"""The true optimum of the altitude (z-psi) subproblem, and each controller's optimality gap.

With theta = phi = 0 the z-psi subsystem of eq. 16 is affine with constant matrices.  In
absolute coordinates ``s = [z, vz, yaw, yaw_rate]`` (z up, SI units)::

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

The cost is eq. 17, ``J = x(N)' H x(N) / 2 + sum_{k<N} (x(k)' Q x(k) + v(k)' R v(k)) / 2``
with the NLSOC z-psi matrices (``config.nlsoc["z_psi"]``) for every controller.

Affine-LQ recursion (:func:`affine_lqr`), in steps to go ``j`` (time ``k = N - j``, ``c = c(k)``),
with the value function ``V_j(x) = x' P_j x / 2 + p_j' x + s_j``::

    P_0 = H,  p_0 = 0,  s_0 = 0
    G    = R + B' P_{j-1} B
    K_j  = G^-1 B' P_{j-1} A                   (the LQR gain: independent of c)
    kf_j = G^-1 B' (P_{j-1} c + p_{j-1})        (feed-forward)
    u    = -K_j x - kf_j                        (the minimiser of x'Qx/2 + u'Ru/2 + V_{j-1}(Ax + Bu + c))
    A_cl = A - B K_j,   d_cl = c - B kf_j       (closed loop: x+ = A_cl x + d_cl)
    P_j  = A_cl' P_{j-1} A_cl + K_j' R K_j + Q
    p_j  = A_cl' (P_{j-1} c + p_{j-1})
    s_j  = s_{j-1} + kf_j' R kf_j / 2 + d_cl' P_{j-1} d_cl / 2 + p_{j-1}' d_cl

(setting the gradient ``R u + B'(P_{j-1}(Ax + Bu + c) + p_{j-1})`` to zero gives ``u``;
substituting it, the linear term ``K' R kf + A_cl'(P d_cl + p)`` reduces to ``A_cl'(P c + p)``
because ``K' G = A' P B``).  With ``c = 0``: ``p = 0``, ``s = 0``, ``kf = 0`` and ``K, P`` are
the LOC Riccati recursion (:func:`gcs.control.loc.finite_horizon_lqr`).  The optimal cost
from ``x(0)`` is ``V_N(x(0))`` (:func:`affine_lqr_cost`).

The comparison (:func:`optimality_table`): each controller of :data:`gcs.control.CONTROLLERS`
is designed by :func:`gcs.control.make_controller` for a copy of the config whose horizon is
set to the one studied and whose thrust and angular-acceleration limits are raised to
:data:`UNCONSTRAINED` (the LQ optimum is unconstrained; the floor ``thrust >= 0`` of
:class:`gcs.control.Limits` cannot be lifted, so the steps where it acts are counted).  It
is flown on the same affine model (not the SITL: no drag, no ground contact, no sensor
noise; theta = phi = 0, lateral axes at rest) from rest at z = 0 with the mission reference
(its takeoff ramp and hold, held after the mission ends), and its eq. 17 cost is evaluated
under both input conventions.  ``J_controller / J_optimal >= 1`` by construction.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from gcs.config import Config
from gcs.control import CONTROLLERS, Controller, make_controller
from gcs.errors import DesignError
from gcs.mission import Mission
from gcs.model import SUBSYSTEMS
from quadrotor.state import Command, State

__all__ = [
    "affine_lqr", "affine_lqr_cost", "z_psi_affine_model", "reference_offsets",
    "AltitudeProblem", "altitude_problem", "unconstrained_config", "OptimalAffinePolicy",
    "Rollout", "simulate_policy", "eq17_cost", "GapRow", "optimality_table", "format_table",
    "UNCONSTRAINED", "COST_CONVENTIONS",
]

#: Thrust [N] and angular-acceleration [rad/s^2] limits of the "unconstrained" controller copies.
UNCONSTRAINED = 1e9

#: Input conventions of the cost: ``"compensated"`` (R weighs thrust - m g) and ``"literal"`` (thrust).
COST_CONVENTIONS = ("compensated", "literal")

_Z_PSI = list(SUBSYSTEMS["z_psi"])


# --------------------------------------------------------------------------- design (pure)

def _square(name: str, mat: np.ndarray, n: int) -> None:
    if mat.shape != (n, n):
        raise DesignError(f"{name} matrix is the wrong shape: {mat.shape}, expected {(n, n)}")


def _check_problem(a, b, c, q, r, h, N):
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise DesignError(f"A matrix must be square (n, n), got shape {a.shape}")
    n = a.shape[0]
    if b.ndim == 1:
        b = b.reshape(-1, 1)
    if b.ndim != 2 or b.shape[0] != n or b.shape[1] < 1:
        raise DesignError(f"B matrix is the wrong shape: {b.shape}, expected ({n}, m)")
    m = b.shape[1]
    if isinstance(N, bool) or not isinstance(N, (int, np.integer)) or N < 1:
        raise DesignError(f"horizon N must be an integer >= 1, got {N!r}")
    N = int(N)
    q, r, h = (np.atleast_2d(np.asarray(x, float)) for x in (q, r, h))
    _square("Q", q, n)
    _square("H", h, n)
    _square("R", r, m)
    for name, mat in (("Q", q), ("H", h)):
        if not np.allclose(mat, mat.T, rtol=1e-12, atol=0.0):
            raise DesignError(f"{name} matrix is not symmetric")
        if np.linalg.eigvalsh(mat).min() < -1e-9 * max(1.0, np.abs(mat).max()):
            raise DesignError(f"{name} matrix is not positive semidefinite")
    if not np.allclose(r, r.T, rtol=1e-12, atol=0.0) or np.linalg.eigvalsh(r).min() <= 0:
        raise DesignError("R matrix is not symmetric positive definite")
    if c is None:
        cc = np.zeros((N, n))
    else:
        c = np.asarray(c, float)
        if c.shape == (n,):
            cc = np.broadcast_to(c, (N, n))
        elif c.shape == (N, n):
            cc = c
        else:
            raise DesignError(f"c has shape {c.shape}, expected ({n},) (constant) or ({N}, {n}) (one row per step k)")
    for name, mat in (("A", a), ("B", b), ("Q", q), ("R", r), ("H", h), ("c", cc)):
        if not np.all(np.isfinite(mat)):
            raise DesignError(f"{name} has non-finite entries")
    return a, b, cc, q, r, h, N


def affine_lqr(A, B, c, Q, R, H, N: int):
    """Exact finite-horizon optimum of an affine-LQ problem with a time-varying offset.

    Minimises ``x(N)' H x(N) / 2 + sum_{k<N} (x(k)' Q x(k) + u(k)' R u(k)) / 2`` subject to
    ``x(k+1) = A x(k) + B u(k) + c(k)`` over unconstrained inputs (recursion in the module
    docstring).

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m) (or (n,) for m = 1)
    c : array_like, shape (n,) or (N, n), or None
        Affine term: constant, or ``c[k]`` for the step k -> k + 1 in **time order**
        (k = 0 .. N-1); None means 0 (plain LQR).
    Q, H : array_like, shape (n, n)
        Stage and terminal state weights, symmetric positive semidefinite.
    R : array_like, shape (m, m)
        Input weight, symmetric positive definite.
    N : int
        Horizon in steps, >= 1.

    Returns
    -------
    K : ndarray, shape (N, m, n)
        Feedback gains in **steps-to-go order** (as :func:`gcs.control.loc.finite_horizon_lqr`):
        ``K[j - 1]`` with j steps to go.
    k_ff : ndarray, shape (N, m)
        Feed-forward, same order.  The optimal input at time k is
        ``u(k) = -K[N - k - 1] x(k) - k_ff[N - k - 1]``.
    P : ndarray, shape (N + 1, n, n)
    p : ndarray, shape (N + 1, n)
    s : ndarray, shape (N + 1,)
        Value function with j steps to go, ``V_j(x) = x' P[j] x / 2 + p[j]' x + s[j]``;
        ``P[0] = H``, ``p[0] = 0``, ``s[0] = 0``.  The optimal cost from x(0) is ``V_N(x(0))``.

    Raises
    ------
    gcs.errors.DesignError (a ValueError)
        Wrong shapes, non-finite entries, Q/H not symmetric positive semidefinite,
        R not symmetric positive definite, N not an integer >= 1.
    """
    a, b, cc, q, r, h, N = _check_problem(A, B, c, Q, R, H, N)
    n, m = b.shape
    K = np.empty((N, m, n))
    kff = np.empty((N, m))
    P = np.empty((N + 1, n, n))
    p = np.empty((N + 1, n))
    s = np.empty(N + 1)
    P[0], p[0], s[0] = 0.5 * (h + h.T), 0.0, 0.0
    bt = b.T
    for j in range(1, N + 1):
        Pj, pj = P[j - 1], p[j - 1]
        ck = cc[N - j]
        g = r + bt @ Pj @ b
        w = Pj @ ck + pj
        sol = np.linalg.solve(g, np.column_stack([bt @ Pj @ a, bt @ w]))
        kj, fj = sol[:, :n], sol[:, n]
        acl = a - b @ kj
        dcl = ck - b @ fj
        pn = acl.T @ Pj @ acl + kj.T @ r @ kj + q
        P[j] = 0.5 * (pn + pn.T)
        p[j] = acl.T @ w
        s[j] = s[j - 1] + 0.5 * fj @ r @ fj + 0.5 * dcl @ Pj @ dcl + pj @ dcl
        K[j - 1], kff[j - 1] = kj, fj
    return K, kff, P, p, s


def affine_lqr_cost(P, p, s, x0, steps: int | None = None) -> float:
    """Optimal cost ``V_j(x0) = x0' P[j] x0 / 2 + p[j]' x0 + s[j]`` from :func:`affine_lqr`.

    Parameters
    ----------
    P : array_like, shape (N + 1, n, n)
    p : array_like, shape (N + 1, n)
    s : array_like, shape (N + 1,)
    x0 : array_like, shape (n,)
        Initial error state.
    steps : int or None
        Steps to go j (0 .. N); None = N, the whole horizon.

    Returns
    -------
    float
    """
    P, p, s = np.asarray(P, float), np.asarray(p, float), np.asarray(s, float)
    if P.ndim != 3 or P.shape[1] != P.shape[2]:
        raise DesignError(f"P has shape {P.shape}, expected (N + 1, n, n)")
    N1, n = P.shape[0], P.shape[1]
    if p.shape != (N1, n):
        raise DesignError(f"p has shape {p.shape}, expected {(N1, n)}")
    if s.shape != (N1,):
        raise DesignError(f"s has shape {s.shape}, expected ({N1},)")
    x0 = np.asarray(x0, float)
    if x0.shape != (n,):
        raise DesignError(f"x0 has shape {x0.shape}, expected ({n},)")
    j = N1 - 1 if steps is None else steps
    if isinstance(j, bool) or not isinstance(j, (int, np.integer)) or not 0 <= j < N1:
        raise DesignError(f"steps must be an integer in 0 .. {N1 - 1}, got {steps!r}")
    return float(0.5 * x0 @ P[j] @ x0 + p[j] @ x0 + s[j])


def z_psi_affine_model(ts: float, mass_kg: float, gravity_m_s2: float, *,
                       gravity_compensated: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 16 with theta = phi = 0: ``s(k+1) = A s(k) + B v(k) + d``, s = [z, vz, yaw, yaw_rate].

    Parameters
    ----------
    ts : float
        Sampling period [s].
    mass_kg, gravity_m_s2 : float
    gravity_compensated : bool
        True: ``v = [thrust - m g, tau_psi]`` and ``d = 0``.  False (literal):
        ``v = [thrust, tau_psi]`` and ``d = [0, -g Ts, 0, 0]``.

    Returns
    -------
    A : ndarray, shape (4, 4)
    B : ndarray, shape (4, 2)
        Units: [m/s per N] in row 2 (Ts / m), [rad/s per rad/s^2] in row 4 (Ts).
    d : ndarray, shape (4,)
    """
    for name, v in (("ts", ts), ("mass_kg", mass_kg), ("gravity_m_s2", gravity_m_s2)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise DesignError(f"{name} must be a finite number > 0, got {v!r}")
    a = np.array([[1.0, ts, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, ts], [0.0, 0.0, 0.0, 1.0]])
    b = np.array([[0.0, 0.0], [ts / mass_kg, 0.0], [0.0, 0.0], [0.0, ts]])
    d = np.zeros(4) if gravity_compensated else np.array([0.0, -gravity_m_s2 * ts, 0.0, 0.0])
    return a, b, d


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


# --------------------------------------------------------------------------- the altitude problem

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
        """Initial error state ``s(0) - r(0)`` for the absolute start [z, vz, yaw, yaw_rate] (default: at rest on the ground)."""
        return np.asarray(start, float) - self.refs[0, _Z_PSI]

    def solve(self):
        """:func:`affine_lqr` of this problem: ``K, k_ff, P, p, s``."""
        return affine_lqr(self.A, self.B, self.c, self.Q, self.R, self.H, self.horizon_steps)


def _check_convention(convention: str) -> None:
    if convention not in COST_CONVENTIONS:
        raise ValueError(f"convention must be one of {', '.join(COST_CONVENTIONS)}, got {convention!r}")


def _horizon_steps(config: Config, horizon_s: float) -> int:
    ts = config.experiment.ts_s
    if not (isinstance(horizon_s, (int, float)) and math.isfinite(horizon_s) and horizon_s >= ts):
        raise ValueError(f"horizon_s must be a number >= one step ({ts:g} s), got {horizon_s!r}")
    steps = horizon_s / ts
    if abs(steps - round(steps)) > 1e-6 * max(1.0, steps):
        raise ValueError(f"horizon {horizon_s:g} s is not a whole number of steps of {ts:g} s")
    return int(round(steps))


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
    _check_convention(convention)
    e, v = config.experiment, config.vehicle
    N = _horizon_steps(config, horizon_s)
    a, b, d = z_psi_affine_model(e.ts_s, v.mass_kg, v.gravity_m_s2, gravity_compensated=(convention == "compensated"))
    mission = Mission(config.mission, zero_velocity=e.zero_velocity_reference)
    refs = np.array([mission.reference(k * e.ts_s) for k in range(N + 1)], float)
    c = reference_offsets(a, refs[:, _Z_PSI], d)
    q, r, h = config.nlsoc["z_psi"].resolved(e.matrices)
    return AltitudeProblem(e.name, convention, e.ts_s, N, v.mass_kg, v.gravity_m_s2, a, b, d, c, q, r, h, refs)


def unconstrained_config(config: Config, horizon_s: float) -> Config:
    """A copy of ``config`` with horizon ``horizon_s`` and limits raised to :data:`UNCONSTRAINED`.

    ``after_horizon`` is irrelevant (the comparison never goes past the horizon).  The
    ``raw`` TOML of the copy is the original's: do not re-parse it.
    """
    _horizon_steps(config, horizon_s)
    e = dataclasses.replace(config.experiment, horizon_s=float(horizon_s))
    v = dataclasses.replace(config.vehicle, max_thrust_n=UNCONSTRAINED, max_angular_accel_rad_s2=UNCONSTRAINED)
    return dataclasses.replace(config, experiment=e, vehicle=v)


class OptimalAffinePolicy(Controller):
    """The optimal policy of an :class:`AltitudeProblem` behind the controller interface.

    ``u = -K x - k_ff`` on the z-psi error; the thrust is ``u_1`` plus the problem's hover
    offset; roll and pitch demands are 0.  Valid for k = 0 .. N-1.
    """

    name = "optimal"

    def __init__(self, problem: AltitudeProblem, K: np.ndarray, k_ff: np.ndarray) -> None:
        self.problem = problem
        self.K, self.k_ff = K, k_ff

    def step(self, k: int, state: State, ref: State) -> Command:
        N = self.problem.horizon_steps
        if not 0 <= k < N:
            raise ValueError(f"k must be in 0 .. {N - 1}, got {k}")
        x = np.asarray(state, float)[_Z_PSI] - np.asarray(ref, float)[_Z_PSI]
        u = -self.K[N - k - 1] @ x - self.k_ff[N - k - 1]
        return Command(float(u[0]) + self.problem.hover_offset_n, 0.0, 0.0, float(u[1]))


@dataclass(frozen=True)
class Rollout:
    """A policy flown on the affine model over the horizon.

    Attributes
    ----------
    x : ndarray, shape (N + 1, 4)
        Error state [e_z, e_vz, e_yaw, e_yaw_rate] at k = 0 .. N.
    z_ref : ndarray, shape (N + 1,)
        Altitude reference [m] at k = 0 .. N.
    command : ndarray, shape (N, 4)
        Commands as returned by the policy (thrust [N], angular accelerations [rad/s^2]).
    cost : dict {convention: float}
        Eq. 17 cost under each input convention of :data:`COST_CONVENTIONS`.
    thrust_floor_steps : int
        Steps where the thrust was exactly 0 (the floor of :class:`gcs.control.Limits`,
        a constraint the LQ optimum does not have).
    """

    x: np.ndarray
    z_ref: np.ndarray
    command: np.ndarray
    cost: dict
    thrust_floor_steps: int

    @property
    def min_z_m(self) -> float:
        """Lowest altitude reached [m] (negative: through the ground, which the affine model lacks)."""
        return float(np.min(self.x[:, 0] + self.z_ref))


def eq17_cost(problem: AltitudeProblem, x: np.ndarray, thrust: np.ndarray, tau_psi: np.ndarray,
              convention: str | None = None) -> float:
    """Eq. 17 of an error trajectory ``x`` (N + 1, 4) and inputs (N,) under ``convention``
    (default: the problem's), with the problem's Q, R, H."""
    conv = problem.convention if convention is None else convention
    _check_convention(conv)
    N = problem.horizon_steps
    if x.shape != (N + 1, 4) or thrust.shape != (N,) or tau_psi.shape != (N,):
        raise ValueError(f"trajectory shapes {x.shape}, {thrust.shape}, {tau_psi.shape}; "
                         f"expected ({N + 1}, 4), ({N},), ({N},)")
    hover = problem.mass_kg * problem.gravity_m_s2 if conv == "compensated" else 0.0
    u = np.column_stack([thrust - hover, tau_psi])
    xs = x[:N]
    stage = np.einsum("ki,ij,kj->", xs, problem.Q, xs) + np.einsum("ki,ij,kj->", u, problem.R, u)
    return float(0.5 * stage + 0.5 * x[N] @ problem.H @ x[N])


def simulate_policy(problem: AltitudeProblem, policy: Controller,
                    start: Sequence[float] = (0.0, 0.0, 0.0, 0.0)) -> Rollout:
    """Fly ``policy`` on the affine z-psi model of ``problem`` for N steps.

    The policy gets ``policy.step(k, state, ref)`` with a :class:`gcs.model.State` whose z,
    vz, yaw and yaw rate are the model's and everything else (lateral axes, roll, pitch)
    0, and the mission reference row k.  Its thrust and yaw demand drive eq. 16 with
    theta = phi = 0 (``s+ = A s + B [thrust, tau_psi] - [0, g Ts, 0, 0]``, the same physics
    for both conventions); roll and pitch demands are ignored.  The model has no ground.

    Parameters
    ----------
    problem : AltitudeProblem
    policy : Controller
        Reset before the flight.
    start : sequence of 4 floats
        Absolute initial [z, vz, yaw, yaw_rate]; default at rest on the ground.

    Returns
    -------
    Rollout
        With the eq. 17 cost under both conventions.
    """
    N = problem.horizon_steps
    a, b = problem.A, problem.B
    g_ts = problem.gravity_m_s2 * problem.ts_s
    s = np.asarray(start, float)
    if s.shape != (4,):
        raise ValueError(f"start has shape {s.shape}, expected (4,)")
    policy.reset()
    refs = problem.refs
    states = np.empty((N + 1, 4))
    cmds = np.empty((N, 4))
    full = [0.0] * 12
    for k in range(N):
        states[k] = s
        full[2], full[5], full[8], full[11] = (float(v) for v in s)
        cmd = policy.step(k, State(*full), State(*refs[k]))
        cmds[k] = cmd
        u = np.array([cmd[0], cmd[3]])
        s = a @ s + b @ u
        s[1] -= g_ts
    states[N] = s
    x = states - refs[:, _Z_PSI]
    x[:, 2] = (x[:, 2] + np.pi) % (2 * np.pi) - np.pi  # as gcs.control.base.wrap_angle
    costs = {conv: eq17_cost(problem, x, cmds[:, 0], cmds[:, 3], conv) for conv in COST_CONVENTIONS}
    floor = int(np.count_nonzero(cmds[:, 0] == 0.0))
    return Rollout(x, refs[:, 2].copy(), cmds, costs, floor)


# --------------------------------------------------------------------------- the table

@dataclass(frozen=True)
class GapRow:
    """One line of :func:`optimality_table` (costs are eq. 17 with the NLSOC z-psi weights).

    Attributes
    ----------
    experiment : str
    horizon_s : float
    convention : {"compensated", "literal"}
    controller : str
    J_controller, J_optimal : float
    ratio : float
        ``J_controller / J_optimal``.
    excess : float
        ``J_controller - J_optimal``.
    thrust_floor_steps : int
        Steps where the controller's thrust sat on the floor 0 N.
    min_z_m : float
        Lowest altitude of the controller's flight on the affine model.
    optimal_min_thrust_n : float
        Lowest thrust of the optimal (unconstrained) input sequence [N].
    optimal_min_z_m : float
        Lowest altitude of the optimal flight [m] (negative: the optimum dives through the
        ground, which the affine model lacks).
    """

    experiment: str
    horizon_s: float
    convention: str
    controller: str
    J_controller: float
    J_optimal: float
    ratio: float
    excess: float
    thrust_floor_steps: int
    min_z_m: float
    optimal_min_thrust_n: float
    optimal_min_z_m: float


def optimality_table(config: Config, horizons_s: Iterable[float] = (1, 5, 20, 60),
                     controllers: Sequence[str] = CONTROLLERS,
                     conventions: Sequence[str] = COST_CONVENTIONS) -> list[GapRow]:
    """``J_controller / J_optimal`` of the altitude subproblem per horizon, convention and controller.

    Parameters
    ----------
    config : Config
    horizons_s : iterable of float
        Horizons [s]; each controller is designed for that horizon (see
        :func:`unconstrained_config`) and flown over it.
    controllers : sequence of str
        Names for :func:`gcs.control.make_controller`.
    conventions : sequence of {"compensated", "literal"}

    Returns
    -------
    list of GapRow
        Ordered by horizon, convention, controller.
    """
    for conv in conventions:
        _check_convention(conv)
    rows: list[GapRow] = []
    for h in horizons_s:
        cfg = unconstrained_config(config, h)
        problems = {conv: altitude_problem(config, h, conv) for conv in conventions}
        rollouts = {name: simulate_policy(problems[conventions[0]], make_controller(name, cfg)) for name in controllers}
        for conv in conventions:
            prob = problems[conv]
            K, kff, P, p, s = prob.solve()
            j_opt = affine_lqr_cost(P, p, s, prob.x0())
            opt = simulate_policy(prob, OptimalAffinePolicy(prob, K, kff))
            for name in controllers:
                ro = rollouts[name]
                jc = ro.cost[conv]
                rows.append(GapRow(prob.experiment, float(h), conv, name, jc, j_opt, jc / j_opt, jc - j_opt,
                                   ro.thrust_floor_steps, ro.min_z_m, float(opt.command[:, 0].min()),
                                   opt.min_z_m))
    return rows


def format_table(rows: Iterable[GapRow]) -> str:
    """The rows as a fixed-width text table (one block per experiment and convention)."""
    rows = list(rows)
    out: list[str] = []
    keys: list[tuple[str, str]] = []
    for r in rows:
        if (r.experiment, r.convention) not in keys:
            keys.append((r.experiment, r.convention))
    what = {"compensated": "u = thrust - m g", "literal": "u = thrust"}
    for exp, conv in keys:
        sel = [r for r in rows if r.experiment == exp and r.convention == conv]
        out.append(f"{exp}: eq. 17 with {what[conv]} ({conv})")
        out.append(f"{'T [s]':>6} {'controller':<14} {'J_controller':>14} {'J_optimal':>14} {'ratio':>10} "
                   f"{'excess':>12} {'floor':>5} {'min z [m]':>10} {'opt min u [N]':>13} {'opt min z [m]':>13}")
        for r in sel:
            out.append(f"{r.horizon_s:>6g} {r.controller:<14} {r.J_controller:>14.6g} {r.J_optimal:>14.6g} "
                       f"{r.ratio:>10.5g} {r.excess:>12.5g} {r.thrust_floor_steps:>5d} {r.min_z_m:>10.4g} "
                       f"{r.optimal_min_thrust_n:>13.4g} {r.optimal_min_z_m:>13.4g}")
        out.append("")
    return "\n".join(out).rstrip("\n")
