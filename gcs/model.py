"""The controllers' models of the quadrotor: eq. 1 discretised, and the paper's subsystem models.

Eq. 1 itself is :mod:`quadrotor.dynamics` (shared with the plant); here are its Euler
discretisation and every subsystem model a design or a law uses, each written once:

=========  =====================================  ===========================================
eq.        model                                   here
=========  =====================================  ===========================================
2          Euler step of eq. 1                    :func:`euler_step`
4          z after the exact linearisation eq. 3  :func:`linear_z` (and yaw: :func:`linear_psi`)
8          small-angle y-phi (erratum 2)          :func:`linear_y_phi`, :func:`linear_x_theta`
16         NLSOC z-psi, affine in the input       :class:`ZPsiModel` (matrices at theta = phi = 0:
                                                  :func:`z_psi_affine_model`)
20         NLSOC y-phi with the applied thrust    :class:`YPhiModel`, :class:`XThetaModel`
=========  =====================================  ===========================================

The eq. 16 / eq. 20 models are ``x(k+1) = f0(x, ctx) + f1(x, ctx) u`` (eq. 9), in plain Python
(lists) because the NLSOC law evaluates them at every control step; ``ctx`` is an
:class:`AffineContext` (the attitude and the thrust applied this step).

A steady disturbance acceleration ``d`` (estimated, :class:`gcs.estimate.DisturbanceObserver`)
enters these models as gravity does: ``g - d_z`` where eq. 16 has g, ``+ Ts d`` in the velocity
rows of eq. 20 (``AffineContext.accel_*``), and the attitude at which eq. 1 balances it
(:func:`disturbance_tilt`) is the lateral subsystems' zero, as hover is the thrust's.

Subsystems (the paper's splits), as index tuples into :class:`State`:

* ``z``      [z, vz]                 (LOC, exact linearisation eq. 3)
* ``psi``    [yaw, yaw_rate]         (LOC)
* ``z_psi``  [z, vz, yaw, yaw_rate]  (NLSOC, eq. 16)
* ``y_phi``  [y, vy, roll, roll_rate]
* ``x_theta`` [x, vx, pitch, pitch_rate]
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gcs.errors import DesignError
from quadrotor.dynamics import eq1_acceleration
from quadrotor.state import Command, State

__all__ = [
    "State", "Command", "ModelParams", "SUBSYSTEMS",
    "continuous_dynamics", "euler_step", "subsystem_state",
    "linear_z", "linear_psi", "linear_y_phi", "linear_x_theta", "MIN_TILT_COS", "tilt_cos",
    "AffineContext", "ZPsiModel", "YPhiModel", "XThetaModel", "z_psi_affine_model", "disturbance_tilt",
    "MAX_DISTURBANCE_TILT_SIN",
]

#: Smallest cos(theta) cos(phi) used when dividing by it (|tilt| about 78 deg).
MIN_TILT_COS = 0.2


def tilt_cos(roll: float, pitch: float) -> float:
    """cos(pitch) cos(roll), floored at :data:`MIN_TILT_COS` (for thrust compensation)."""
    cc = math.cos(pitch) * math.cos(roll)
    return cc if cc > MIN_TILT_COS else MIN_TILT_COS


#: The largest sine of the tilt that :func:`disturbance_tilt` gives (30 deg).
MAX_DISTURBANCE_TILT_SIN = 0.5


def disturbance_tilt(thrust_n: float, mass_kg: float, gravity_m_s2: float, accel_x_m_s2: float,
                     accel_y_m_s2: float) -> tuple[float, float]:
    """Roll and pitch [rad] at which eq. 1's thrust cancels a horizontal disturbance acceleration.

    With ``m x'' = -u sin(theta) + m d_x`` and ``m y'' = u cos(theta) sin(phi) + m d_y``::

        sin(theta_d) = m d_x / u,   sin(phi_d) = -m d_y / (u cos(theta_d))

    ``u`` is floored at half the hover thrust and the sines are clipped to
    +-:data:`MAX_DISTURBANCE_TILT_SIN`.  Zero disturbance: exactly (0, 0).
    """
    if accel_x_m_s2 == 0.0 and accel_y_m_s2 == 0.0:
        return 0.0, 0.0
    u = max(thrust_n, 0.5 * mass_kg * gravity_m_s2)
    lim = MAX_DISTURBANCE_TILT_SIN
    st = mass_kg * accel_x_m_s2 / u
    pitch = math.asin(lim if st > lim else -lim if st < -lim else st)
    sr = -mass_kg * accel_y_m_s2 / (u * math.cos(pitch))
    return math.asin(lim if sr > lim else -lim if sr < -lim else sr), pitch


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
    """One step of the Euler discretisation ``x(k+1) = x(k) + Ts f(x(k), u(k))`` (eq. 2 for z)."""
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
    """Eq. 4: A, B of the z subsystem after the exact linearisation eq. 3, state [z, vz].

    ``A = [[1, T], [0, 1]]`` (shape (2, 2)), ``B = [0, T]'`` (shape (2, 1)); input u1 [m/s^2].
    """
    return _double_integrator(ts)


def linear_psi(ts: float) -> tuple[np.ndarray, np.ndarray]:
    """A, B of the yaw subsystem (section 2.2: eq. 4's matrices), state [yaw, yaw_rate]; input tau_psi [rad/s^2]."""
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
    """Eq. 8: A (4, 4), B (4, 1) of the small-angle y-phi subsystem, state [y, vy, roll, roll_rate].

    ``A(2,3) = g T``; A(4,4) = 1 (erratum 2: printed T).  Input tau_phi [rad/s^2].
    """
    return _lateral(ts, +1.0, gravity_m_s2)


def linear_x_theta(ts: float, gravity_m_s2: float = 9.81) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 8's x-theta twin (not printed, erratum 2): as y-phi with A(2,3) = -g T (m x'' = -u sin theta)."""
    return _lateral(ts, -1.0, gravity_m_s2)


# --------------------------------------------------------------------------- NLSOC's affine models

@dataclass
class AffineContext:
    """What the eq. 16 / eq. 20 models need beyond their own state, at one control step.

    Attributes
    ----------
    cos_roll, sin_roll, cos_pitch, sin_pitch : float
        Of the attitude estimate [rad] (not floored).
    thrust_n : float
        The thrust applied this step [N] (eq. 20's ``u_z*``; set after the z-psi law).
    accel_x, accel_y, accel_z : float
        A disturbance acceleration the models add where eq. 1 has gravity [m/s^2] (z up;
        eq. 16 uses ``accel_z`` only where it keeps ``-g Ts`` in f0).
    """

    cos_roll: float = 1.0
    sin_roll: float = 0.0
    cos_pitch: float = 1.0
    sin_pitch: float = 0.0
    thrust_n: float = 0.0
    accel_x: float = 0.0
    accel_y: float = 0.0
    accel_z: float = 0.0

    def set_attitude(self, roll: float, pitch: float) -> None:
        """Cosines and sines of ``roll`` and ``pitch`` [rad]."""
        self.cos_roll, self.sin_roll = math.cos(roll), math.sin(roll)
        self.cos_pitch, self.sin_pitch = math.cos(pitch), math.sin(pitch)


def _check_positive(**values: float) -> None:
    for name, v in values.items():
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise DesignError(f"{name} must be a finite number > 0, got {v!r}")


class ZPsiModel:
    """Eq. 16: the NLSOC z-psi subsystem ``x(k+1) = f0(x) + f1(theta, phi) u``.

    State ``x = [z, vz, yaw, yaw_rate]`` (or their errors from a reference), input
    ``u = [thrust [N], tau_psi [rad/s^2]]``::

        f0(x) = [z + Ts vz, vz - g Ts, yaw + Ts yaw_rate, yaw_rate]
        f1    = [[0, 0], [Ts cos(theta) cos(phi) / m, 0], [0, 0], [0, Ts]]

    With ``gravity_in_f0=False`` the ``-g Ts`` term is dropped: the input is then the thrust
    beyond what holds the vehicle up (erratum 8).  A disturbance ``ctx.accel_z`` enters as gravity
    does: ``-(g - d_z) Ts`` in f0, or (without the term) in the hover thrust the law adds.

    Parameters
    ----------
    ts_s : float
        Sampling period Ts [s].
    mass_kg, gravity_m_s2 : float
    gravity_in_f0 : bool
    """

    n, m = 4, 2
    __slots__ = ("_gts", "_ts_m", "gravity_in_f0", "gravity_m_s2", "mass_kg", "ts_s")

    def __init__(self, ts_s: float, mass_kg: float, gravity_m_s2: float, *, gravity_in_f0: bool = True) -> None:
        self.ts_s, self.mass_kg, self.gravity_m_s2 = ts_s, mass_kg, gravity_m_s2
        self.gravity_in_f0 = gravity_in_f0
        self._gts = gravity_m_s2 * ts_s if gravity_in_f0 else 0.0
        self._ts_m = ts_s / mass_kg

    def f0(self, x: Sequence[float], ctx: AffineContext | None = None) -> list[float]:
        """Drift f0(x), 4 floats."""
        ts = self.ts_s
        gts = self._gts
        if ctx is not None and self.gravity_in_f0:
            gts -= ts * ctx.accel_z
        return [x[0] + ts * x[1], x[1] - gts, x[2] + ts * x[3], x[3]]

    def f1(self, x: Sequence[float] | None, ctx: AffineContext) -> list[list[float]]:
        """Input matrix f1(theta, phi), 4 rows of 2 (depends on the attitude only)."""
        return [[0.0, 0.0], [self._ts_m * ctx.cos_pitch * ctx.cos_roll, 0.0], [0.0, 0.0], [0.0, self.ts_s]]


def z_psi_affine_model(ts: float, mass_kg: float, gravity_m_s2: float, *,
                       gravity_compensated: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 16 at theta = phi = 0 as matrices: ``s(k+1) = A s(k) + B v(k) + d``, s = [z, vz, yaw, yaw_rate].

    Evaluated from :class:`ZPsiModel` (f0 is affine in x: ``A e_i = f0(e_i)`` without gravity,
    ``d = f0(0)``), so the matrices and the flying model cannot disagree.

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

    Raises
    ------
    gcs.errors.DesignError
        A non-positive or non-finite ``ts``, ``mass_kg`` or ``gravity_m_s2``.
    """
    _check_positive(ts=ts, mass_kg=mass_kg, gravity_m_s2=gravity_m_s2)
    linear = ZPsiModel(ts, mass_kg, gravity_m_s2, gravity_in_f0=False)
    a = np.array([linear.f0(e) for e in np.eye(4).tolist()]).T
    d = np.array(ZPsiModel(ts, mass_kg, gravity_m_s2, gravity_in_f0=not gravity_compensated).f0([0.0] * 4))
    return a, np.array(linear.f1(None, AffineContext())), d


class _LateralModel:
    """Eq. 20 and its x-theta twin: state ``[pos, vel, angle, rate]``, input tau [rad/s^2]."""

    n, m = 4, 1
    __slots__ = ("_f1", "_ts_m", "mass_kg", "ts_s")

    def __init__(self, ts_s: float, mass_kg: float) -> None:
        self.ts_s, self.mass_kg = ts_s, mass_kg
        self._ts_m = ts_s / mass_kg
        self._f1 = ((0.0,), (0.0,), (0.0,), (ts_s,))

    def f1(self, x: Sequence[float] | None = None, ctx: AffineContext | None = None) -> tuple:
        """Input matrix ``f1 = [0, 0, 0, Ts]'``, 4 rows of 1 (constant)."""
        return self._f1


class YPhiModel(_LateralModel):
    """Eq. 20: ``f0 = [y + Ts vy, vy + Ts u cos(theta) sin(phi) / m, phi + Ts phi_rate, phi_rate]``,
    u the thrust applied this step (``ctx.thrust_n``); ``+ Ts d_y`` in the velocity row with a
    disturbance (``ctx.accel_y``)."""

    __slots__ = ()

    def f0(self, x: Sequence[float], ctx: AffineContext) -> list[float]:
        """Drift f0(x, u), 4 floats."""
        ts = self.ts_s
        v = x[1] + self._ts_m * ctx.thrust_n * ctx.cos_pitch * ctx.sin_roll
        if ctx.accel_y:
            v += ts * ctx.accel_y
        return [x[0] + ts * x[1], v, x[2] + ts * x[3], x[3]]


class XThetaModel(_LateralModel):
    """Eq. 20 for x-theta (not printed): as :class:`YPhiModel` with ``vx - Ts u sin(theta) / m``
    (m x'' = -u sin theta, eq. 1), ``+ Ts d_x`` with a disturbance (``ctx.accel_x``)."""

    __slots__ = ()

    def f0(self, x: Sequence[float], ctx: AffineContext) -> list[float]:
        """Drift f0(x, u), 4 floats."""
        ts = self.ts_s
        v = x[1] - self._ts_m * ctx.thrust_n * ctx.sin_pitch
        if ctx.accel_x:
            v += ts * ctx.accel_x
        return [x[0] + ts * x[1], v, x[2] + ts * x[3], x[3]]
