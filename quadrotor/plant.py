"""Reduced quadrotor plant of the paper (eq. 1), z up, as a pure step function.

The plant is the "truth" of the in-process simulation (``gcs sim``) and of the
reduced-model option of the networked SITL; it never imports a link.

Dynamics: eq. 1 (:func:`quadrotor.dynamics.eq1_acceleration`) plus the force of the air
``d = c_drag (w - v)`` on the body moving at velocity ``v`` in a wind ``w`` [m/s].

Integration: the inputs are held (zero-order hold) over one call of
:func:`step`, which is split into sub-steps of at most ``max_substep_s``
integrated by classical RK4.  With the inputs held the attitude is a
quadratic polynomial of time, which RK4 integrates exactly, so the attitude
is evaluated in closed form at the RK4 stage times and only the translational
states go through the RK4 stages (identical results, fewer operations).

Ground contact: the ground is the plane z = 0.  A vehicle on the ground whose
net vertical force does not lift it stays put, level, with zero velocity; a
vehicle that reaches z < 0 touches down (z = 0, velocities and attitude rates
zeroed, attitude levelled).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from collections.abc import Sequence

from quadrotor.dynamics import eq1_acceleration
from quadrotor.state import State

__all__ = ["ReducedParams", "step", "hover_thrust_n"]


@dataclass(frozen=True)
class ReducedParams:
    """Parameters of the reduced plant.

    Attributes
    ----------
    mass_kg : float
        Vehicle mass (the paper uses 1 kg).
    gravity_m_s2 : float
        Gravitational acceleration.
    max_thrust_n : float
        Collective thrust saturation; thrust is clipped to ``[0, max_thrust_n]``.
    max_angular_accel_rad_s2 : float
        Saturation of each angular-acceleration input (torque / inertia).
    drag_n_per_m_s : float
        Linear air-drag coefficient c: force = c (wind - velocity) [N/(m/s)].
    max_substep_s : float
        Largest RK4 sub-step.
    """

    mass_kg: float = 1.0
    gravity_m_s2: float = 9.81
    max_thrust_n: float = 24.5
    max_angular_accel_rad_s2: float = 200.0
    drag_n_per_m_s: float = 0.25
    max_substep_s: float = 0.001

    def __post_init__(self) -> None:
        for name in ("mass_kg", "gravity_m_s2", "max_thrust_n", "max_angular_accel_rad_s2", "max_substep_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if self.drag_n_per_m_s < 0:
            raise ValueError(f"drag_n_per_m_s must be >= 0, got {self.drag_n_per_m_s!r}")


def hover_thrust_n(params: ReducedParams) -> float:
    """Thrust that holds a level vehicle in hover [N]."""
    return params.mass_kg * params.gravity_m_s2


def _clip(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else hi if v > hi else v


def step(
    state: Sequence[float],
    command: Sequence[float],
    dt: float,
    params: ReducedParams,
    wind_m_s: Sequence[float] = (0.0, 0.0, 0.0),
) -> State:
    """Advance the plant by ``dt`` seconds with the command held constant.

    Parameters
    ----------
    state : sequence of 12 floats
        Current state in :class:`~quadrotor.state.State` order.
    command : sequence of 4 floats
        ``(thrust_n, tau_roll_rad_s2, tau_pitch_rad_s2, tau_yaw_rad_s2)``;
        saturated as described in :class:`ReducedParams`.
    dt : float
        Duration [s], > 0; split into ``ceil(dt / max_substep_s)`` RK4 steps.
    params : ReducedParams
    wind_m_s : sequence of 3 floats
        Wind velocity in the paper frame, held over ``dt``.

    Returns
    -------
    State
    """
    if not dt > 0:
        raise ValueError(f"dt must be > 0, got {dt!r}")
    x, y, z, vx, vy, vz, phi, th, psi, p, q, r = (float(s) for s in state)
    umax = params.max_thrust_n
    amax = params.max_angular_accel_rad_s2
    u = _clip(float(command[0]), 0.0, umax)
    tp = _clip(float(command[1]), -amax, amax)
    tt = _clip(float(command[2]), -amax, amax)
    tr = _clip(float(command[3]), -amax, amax)
    m = params.mass_kg
    g = params.gravity_m_s2
    c = params.drag_n_per_m_s / m
    wx, wy, wz = (float(w) for w in wind_m_s)
    um = u / m

    n = max(1, math.ceil(dt / params.max_substep_s - 1e-9))
    h = dt / n
    h2 = 0.5 * h
    h6 = h / 6.0
    # Air force terms that do not depend on velocity: c * w.
    cwx, cwy, cwz = c * wx, c * wy, c * wz

    for _ in range(n):
        grounded = z <= 0.0 and vz <= 0.0
        # Sitting on the ground, level: does the net vertical force lift it?
        if grounded and um - g + cwz - c * vz <= 0.0:
            z = vx = vy = vz = 0.0
            phi = th = p = q = r = 0.0
            continue
        # Attitude at the RK4 stage times t = 0, h/2, h (exact under ZOH).
        phi_m = phi + p * h2 + 0.5 * tp * h2 * h2
        th_m = th + q * h2 + 0.5 * tt * h2 * h2
        phi_e = phi + p * h + 0.5 * tp * h * h
        th_e = th + q * h + 0.5 * tt * h * h
        psi_e = psi + r * h + 0.5 * tr * h * h

        ax0, ay0, az0 = eq1_acceleration(um, phi, th, g)
        axm, aym, azm = eq1_acceleration(um, phi_m, th_m, g)
        axe, aye, aze = eq1_acceleration(um, phi_e, th_e, g)
        ax0, ay0, az0 = ax0 + cwx, ay0 + cwy, az0 + cwz
        axm, aym, azm = axm + cwx, aym + cwy, azm + cwz
        axe, aye, aze = axe + cwx, aye + cwy, aze + cwz

        # Translational RK4; acceleration = a_att(t) - c v.
        k1x, k1y, k1z = ax0 - c * vx, ay0 - c * vy, az0 - c * vz
        v2x, v2y, v2z = vx + h2 * k1x, vy + h2 * k1y, vz + h2 * k1z
        k2x, k2y, k2z = axm - c * v2x, aym - c * v2y, azm - c * v2z
        v3x, v3y, v3z = vx + h2 * k2x, vy + h2 * k2y, vz + h2 * k2z
        k3x, k3y, k3z = axm - c * v3x, aym - c * v3y, azm - c * v3z
        v4x, v4y, v4z = vx + h * k3x, vy + h * k3y, vz + h * k3z
        k4x, k4y, k4z = axe - c * v4x, aye - c * v4y, aze - c * v4z

        x += h6 * (vx + 2.0 * v2x + 2.0 * v3x + v4x)
        y += h6 * (vy + 2.0 * v2y + 2.0 * v3y + v4y)
        z += h6 * (vz + 2.0 * v2z + 2.0 * v3z + v4z)
        vx += h6 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
        vy += h6 * (k1y + 2.0 * k2y + 2.0 * k3y + k4y)
        vz += h6 * (k1z + 2.0 * k2z + 2.0 * k3z + k4z)
        phi, th, psi = phi_e, th_e, psi_e
        p += tp * h
        q += tt * h
        r += tr * h

        if z < 0.0:
            # Touchdown: the legs stop the vehicle and level it.
            z = vx = vy = vz = 0.0
            phi = th = p = q = r = 0.0

    return State(x, y, z, vx, vy, vz, phi, th, psi, p, q, r)
