"""6-DOF rigid-body quadrotor in NED/FRD with first-order motors and ground contact.

The plant step is pure: ``step(state, rotor_cmd_n, dt, model, wind_ned) -> state``.
It is written with plain floats (no numpy): numpy's per-call overhead on
3-vectors costs more than the arithmetic itself.

Dynamics
--------
* Motors: ``T_i' = (s_i clip(T_cmd_i, 0, T_max) - T_i) / tau``, integrated exactly over ``dt``,
  with ``s_i`` the ``faults.motor_scale`` of motor i (1 for a nominal vehicle): ``T_i`` is the thrust
  the rotor actually produces.
* Forces (NED): gravity ``m g e_d``, thrust ``-sum(T_i)`` along body z, drag
  ``-(c_lin + c_quad |v_air|) v_air`` per axis with ``v_air = v - wind``.
* Torques (body): rotor arms and reaction torques (layout in
  :mod:`sitl.copter.vehicle`), the arms taken about the centre of mass moved by
  ``faults.com_offset_m = (cx, cy, cz)`` (``tau_x += cy F``, ``tau_y -= cx F``), rotational damping
  ``-c_rot omega``, and ``J omega' = tau - omega x (J omega)`` with the full inertia matrix.
* The mass and inertia are the vehicle file's times ``faults.mass_scale`` / ``faults.inertia_scale``
  (:mod:`sitl.copter.faults`); the autopilot knows only the nominal values.
* Integration: semi-implicit Euler (rates and velocities first, then
  positions), attitude by the exact quaternion exponential of the new body
  rates, renormalised every step.

Ground contact (flat ground at ``d = 0``)
-----------------------------------------
* **Landed** (``on_ground``): the vehicle rests on its legs: position,
  attitude fixed, velocities and rates zero, while the vertical thrust
  ``F * R[2][2]`` does not exceed the weight.
* **Taking off**: when it does, the vehicle is released and integrated.
* **Touching down**: a step that ends below the ground puts the vehicle on
  the ground (``d = 0``), stops it and levels it keeping its heading.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

from quadrotor.frames import Kinematics, euler_to_quaternion
from sitl.copter.faults import true_inertia, true_mass_kg
from sitl.copter.vehicle import VehicleParams

__all__ = ["RigidBodyState", "RigidBodyModel", "step", "rotor_wrench", "initial_state"]

_CALM = (0.0, 0.0, 0.0)
_new = tuple.__new__


class RigidBodyState(NamedTuple):
    """State of the 6-DOF plant (NED/FRD, SI units).

    ``n, e, d`` [m], ``vn, ve, vd`` [m/s], quaternion ``qw..qz`` (body to NED),
    body rates ``p, q, r`` [rad/s], rotor thrusts ``t1..t4`` [N] (motor states),
    ``on_ground`` (resting on the ground).
    """

    n: float = 0.0
    e: float = 0.0
    d: float = 0.0
    vn: float = 0.0
    ve: float = 0.0
    vd: float = 0.0
    qw: float = 1.0
    qx: float = 0.0
    qy: float = 0.0
    qz: float = 0.0
    p: float = 0.0
    q: float = 0.0
    r: float = 0.0
    t1: float = 0.0
    t2: float = 0.0
    t3: float = 0.0
    t4: float = 0.0
    on_ground: bool = True

    def kinematics(self) -> Kinematics:
        """The rigid-body part as :class:`quadrotor.frames.Kinematics`."""
        return Kinematics(*self[:13])


def initial_state(altitude_m: float = 0.0, roll: float = 0.0, pitch: float = 0.0,
                  yaw: float = 0.0) -> RigidBodyState:
    """A vehicle at rest at ``altitude_m`` above home with the given attitude [rad].

    At altitude 0 it is on the ground (possibly tilted: resting on a slope).
    """
    qw, qx, qy, qz = euler_to_quaternion(roll, pitch, yaw)
    return RigidBodyState(0.0, 0.0, -altitude_m, 0.0, 0.0, 0.0, qw, qx, qy, qz,
                          on_ground=altitude_m <= 0.0)


class RigidBodyModel:
    """Constants of :func:`step`, precomputed from :class:`VehicleParams` (with its ``faults``).

    Parameters
    ----------
    vehicle : VehicleParams

    Attributes
    ----------
    mass_kg : float
        The true mass (``mass_kg * faults.mass_scale``).
    max_thrust_n : float
        Largest thrust command of one rotor [N] (before its motor scale).
    """

    __slots__ = ("vehicle", "mass_kg", "gravity_m_s2", "max_thrust_n", "tau_s", "_c", "_alpha_dt", "_alpha")

    def __init__(self, vehicle: VehicleParams) -> None:
        self.vehicle = vehicle
        r = vehicle.rotors
        dr = vehicle.drag
        j = true_inertia(vehicle)
        jinv = _inv3(j)
        f = vehicle.faults
        self.mass_kg = true_mass_kg(vehicle)
        self.gravity_m_s2 = vehicle.gravity_m_s2
        self.max_thrust_n = r.max_thrust_n
        self.tau_s = r.time_constant_s
        arm = r.arm_length_m / math.sqrt(2.0)
        self._c = (
            1.0 / self.mass_kg, vehicle.gravity_m_s2, r.max_thrust_n, arm, r.yaw_moment_m,
            dr.linear_n_per_m_s, dr.vertical_n_per_m_s, dr.quadratic_n_per_m2_s2, dr.rotational_n_m_s,
            *j[0], *j[1], *j[2], *jinv[0], *jinv[1], *jinv[2], *f.motor_scale, *f.com_offset_m[:2],
        )
        self._alpha_dt = -1.0
        self._alpha = 0.0

    def motor_alpha(self, dt: float) -> float:
        """``1 - exp(-dt / tau)``, cached for the last ``dt``."""
        if dt != self._alpha_dt:
            self._alpha = 1.0 - math.exp(-dt / self.tau_s)
            self._alpha_dt = dt
        return self._alpha


def _inv3(m: Sequence[Sequence[float]]) -> tuple[tuple[float, ...], ...]:
    (a, b, c), (d, e, f), (g, h, i) = m
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    return (
        ((e * i - f * h) / det, (c * h - b * i) / det, (b * f - c * e) / det),
        ((f * g - d * i) / det, (a * i - c * g) / det, (c * d - a * f) / det),
        ((d * h - e * g) / det, (b * g - a * h) / det, (a * e - b * d) / det),
    )


def rotor_wrench(thrusts: Sequence[float], vehicle: VehicleParams) -> tuple[float, float, float, float]:
    """Total thrust [N] and body torques [N m] about the true centre of mass of the thrusts ``t1..t4``
    [N] the rotors produce (``faults.com_offset_m`` moves the centre of mass; the motor scales are
    already in the thrusts)."""
    t1, t2, t3, t4 = thrusts
    arm = vehicle.rotors.arm_length_m / math.sqrt(2.0)
    k = vehicle.rotors.yaw_moment_m
    cx, cy, _ = vehicle.faults.com_offset_m
    f = t1 + t2 + t3 + t4
    return (f, arm * (-t1 + t2 + t3 - t4) + cy * f, arm * (t1 - t2 + t3 - t4) - cx * f, k * (t1 + t2 - t3 - t4))


def step(state: Sequence, rotor_cmd_n: Sequence[float], dt: float, model: RigidBodyModel,
         wind_ned: Sequence[float] = _CALM) -> RigidBodyState:
    """Advance the plant by ``dt`` seconds with the rotor commands held.

    Parameters
    ----------
    state : RigidBodyState
    rotor_cmd_n : sequence of 4 floats
        Commanded thrust of motors 1..4 [N], clipped to ``[0, max_thrust_n]`` (then times the motor scales).
    dt : float
        Step [s], > 0 (use about 1 ms).
    model : RigidBodyModel
    wind_ned : sequence of 3 floats
        Wind velocity [m/s] in NED.

    Returns
    -------
    RigidBodyState
    """
    (n, e, d, vn, ve, vd, qw, qx, qy, qz, p, q, r, t1, t2, t3, t4, grounded) = state
    (inv_m, g, tmax, arm, kyaw, cl, cv, cq, crot,
     j00, j01, j02, j10, j11, j12, j20, j21, j22,
     i00, i01, i02, i10, i11, i12, i20, i21, i22, s1, s2, s3, s4, cx, cy) = model._c
    a = model.motor_alpha(dt)
    c1, c2, c3, c4 = rotor_cmd_n
    c1 = s1 * (0.0 if c1 < 0.0 else tmax if c1 > tmax else c1)
    c2 = s2 * (0.0 if c2 < 0.0 else tmax if c2 > tmax else c2)
    c3 = s3 * (0.0 if c3 < 0.0 else tmax if c3 > tmax else c3)
    c4 = s4 * (0.0 if c4 < 0.0 else tmax if c4 > tmax else c4)
    t1 += a * (c1 - t1)
    t2 += a * (c2 - t2)
    t3 += a * (c3 - t3)
    t4 += a * (c4 - t4)
    f = t1 + t2 + t3 + t4
    # Third column of the body-to-NED rotation: the body z axis in NED.
    r02 = 2.0 * (qx * qz + qw * qy)
    r12 = 2.0 * (qy * qz - qw * qx)
    r22 = 1.0 - 2.0 * (qx * qx + qy * qy)

    if grounded:
        if f * r22 * inv_m <= g:
            return _new(RigidBodyState, (n, e, d, 0.0, 0.0, 0.0, qw, qx, qy, qz, 0.0, 0.0, 0.0, t1, t2, t3, t4, True))
        grounded = False

    tx = arm * (-t1 + t2 + t3 - t4) + cy * f
    ty = arm * (t1 - t2 + t3 - t4) - cx * f
    tz = kyaw * (t1 + t2 - t3 - t4)

    un = vn - wind_ned[0]
    ue = ve - wind_ned[1]
    ud = vd - wind_ned[2]
    if cq > 0.0:
        sp = cq * math.sqrt(un * un + ue * ue + ud * ud)
        kh = cl + sp
        kv = cv + sp
    else:
        kh = cl
        kv = cv
    an = (-f * r02 - kh * un) * inv_m
    ae = (-f * r12 - kh * ue) * inv_m
    ad = (-f * r22 - kv * ud) * inv_m + g

    # Euler's equations: J w' = tau - w x (J w) - c_rot w
    hx = j00 * p + j01 * q + j02 * r
    hy = j10 * p + j11 * q + j12 * r
    hz = j20 * p + j21 * q + j22 * r
    mx = tx - (q * hz - r * hy) - crot * p
    my = ty - (r * hx - p * hz) - crot * q
    mz = tz - (p * hy - q * hx) - crot * r
    p += dt * (i00 * mx + i01 * my + i02 * mz)
    q += dt * (i10 * mx + i11 * my + i12 * mz)
    r += dt * (i20 * mx + i21 * my + i22 * mz)

    vn += an * dt
    ve += ae * dt
    vd += ad * dt
    n += vn * dt
    e += ve * dt
    d += vd * dt

    # q <- q * exp(0.5 w dt)
    wx = p * dt
    wy = q * dt
    wz = r * dt
    angle = math.sqrt(wx * wx + wy * wy + wz * wz)
    if angle > 1e-9:
        half = 0.5 * angle
        s = math.sin(half) / angle
        c = math.cos(half)
    else:
        s = 0.5
        c = 1.0
    dx = wx * s
    dy = wy * s
    dz = wz * s
    nw = qw * c - qx * dx - qy * dy - qz * dz
    nx = qw * dx + qx * c + qy * dz - qz * dy
    ny = qw * dy - qx * dz + qy * c + qz * dx
    nz = qw * dz + qx * dy - qy * dx + qz * c
    inv = 1.0 / math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
    qw = nw * inv
    qx = nx * inv
    qy = ny * inv
    qz = nz * inv

    if d > 0.0:
        # Touchdown: the legs stop the vehicle and level it, keeping the heading.
        yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        half = 0.5 * yaw
        return _new(RigidBodyState, (n, e, 0.0, 0.0, 0.0, 0.0, math.cos(half), 0.0, 0.0, math.sin(half),
                                     0.0, 0.0, 0.0, t1, t2, t3, t4, True))
    return _new(RigidBodyState, (n, e, d, vn, ve, vd, qw, qx, qy, qz, p, q, r, t1, t2, t3, t4, False))
