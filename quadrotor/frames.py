"""Frames, quaternions and the conversions between MAVLink (NED / FRD) and the paper's frame — the one place.

Conventions
-----------
* World frame: NED (north, east, down), as in MAVLink ``LOCAL_POSITION_NED``.
* Body frame: FRD (forward, right, down).
* Attitude: unit quaternion ``(w, x, y, z)`` rotating body vectors into NED
  (MAVLink ``SET_ATTITUDE_TARGET.q``); Euler angles are the aerospace Z-Y-X
  sequence (yaw, then pitch, then roll) of MAVLink ``ATTITUDE``.
* Paper frame: x north, y east, **z up**; the same Euler angles; *Euler-angle*
  rates (phi_dot, and the controllers' tau = phi_ddot) instead of body rates.
  So ``z_paper = -z_ned`` and ``vz_paper = -vz_ned``.

The ground station converts its telemetry and setpoints here, the simulator its
plant state (:func:`ned_from_paper`); everything works on plain floats (it runs in
the 400 Hz and 100 Hz loops).
"""

from __future__ import annotations

import math
from typing import NamedTuple
from collections.abc import Sequence

__all__ = [
    "ned_to_paper_position", "ned_to_paper_velocity", "paper_to_ned_position",
    "body_rates_to_euler_rates", "euler_rates_to_body_rates", "euler_accel_to_body_accel",
    "euler_to_quaternion", "quaternion_to_euler", "rotation_vector",
    "Kinematics", "quat_multiply", "quat_conjugate", "quat_norm", "quat_is_unit", "quat_rotate", "quat_yaw",
    "ned_from_paper", "paper_from_ned", "ned_wind_from_paper",
]


class Kinematics(NamedTuple):
    """Rigid-body kinematics in NED/FRD (SI units).

    Positions ``n, e, d`` [m] relative to home, velocity ``vn, ve, vd`` [m/s],
    attitude quaternion ``qw, qx, qy, qz`` (body to NED), body rates
    ``p, q, r`` [rad/s] (roll, pitch, yaw rate about FRD axes).
    """

    n: float
    e: float
    d: float
    vn: float
    ve: float
    vd: float
    qw: float
    qx: float
    qy: float
    qz: float
    p: float
    q: float
    r: float


def ned_to_paper_position(x_n: float, y_e: float, z_d: float) -> tuple[float, float, float]:
    """(north, east, down) [m] -> paper (x, y, z up) [m]."""
    return (x_n, y_e, -z_d)


def paper_to_ned_position(x: float, y: float, z_up: float) -> tuple[float, float, float]:
    """Paper (x, y, z up) [m] -> (north, east, down) [m]."""
    return (x, y, -z_up)


def ned_to_paper_velocity(vx_n: float, vy_e: float, vz_d: float) -> tuple[float, float, float]:
    """NED velocity [m/s] -> paper velocity (vz up) [m/s]."""
    return (vx_n, vy_e, -vz_d)


def body_rates_to_euler_rates(roll: float, pitch: float, p: float, q: float, r: float) -> tuple[float, float, float]:
    """FRD body rates (p, q, r) [rad/s] -> ZYX Euler-angle rates (roll, pitch, yaw rates) [rad/s].

    Singular at pitch = +-90 deg; cos(pitch) is floored at 1e-6 in magnitude.
    """
    sr, cr = math.sin(roll), math.cos(roll)
    cp = math.cos(pitch)
    if abs(cp) < 1e-6:
        cp = math.copysign(1e-6, cp)
    tp = math.sin(pitch) / cp
    return (p + (q * sr + r * cr) * tp, q * cr - r * sr, (q * sr + r * cr) / cp)


def euler_rates_to_body_rates(roll: float, pitch: float, droll: float, dpitch: float,
                              dyaw: float) -> tuple[float, float, float]:
    """ZYX Euler-angle rates [rad/s] -> FRD body rates (p, q, r) [rad/s]."""
    sr, cr = math.sin(roll), math.cos(roll)
    sp, cp = math.sin(pitch), math.cos(pitch)
    return (droll - dyaw * sp, dpitch * cr + dyaw * cp * sr, -dpitch * sr + dyaw * cp * cr)


def euler_accel_to_body_accel(angles: Sequence[float], rates: Sequence[float],
                              accels: Sequence[float]) -> tuple[float, float, float]:
    """Euler-angle accelerations (the paper's tau) -> FRD body angular accelerations [rad/s^2].

    Parameters
    ----------
    angles : (roll, pitch, yaw) [rad]
    rates : Euler-angle rates (roll_rate, pitch_rate, yaw_rate) [rad/s]
    accels : Euler-angle accelerations (tau_phi, tau_theta, tau_psi) [rad/s^2]

    The time derivative of :func:`euler_rates_to_body_rates`; for small angles and
    rates it is the identity.
    """
    phi, th = angles[0], angles[1]
    dphi, dth, dpsi = rates
    aphi, ath, apsi = accels
    sr, cr = math.sin(phi), math.cos(phi)
    sp, cp = math.sin(th), math.cos(th)
    dp = aphi - apsi * sp - dpsi * dth * cp
    dq = ath * cr - dth * dphi * sr + apsi * cp * sr - dpsi * dth * sp * sr + dpsi * dphi * cp * cr
    dr = -ath * sr - dth * dphi * cr + apsi * cp * cr - dpsi * dth * sp * cr - dpsi * dphi * cp * sr
    return (dp, dq, dr)


def euler_to_quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """ZYX Euler angles [rad] -> unit quaternion (w, x, y, z), MAVLink's order and convention."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy)


def quaternion_to_euler(q: Sequence[float]) -> tuple[float, float, float]:
    """Unit quaternion (w, x, y, z) -> ZYX Euler angles (roll, pitch, yaw) [rad]."""
    w, x, y, z = q
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    s = 2 * (w * y - z * x)
    pitch = math.asin(max(-1.0, min(1.0, s)))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return (roll, pitch, yaw)


def rotation_vector(q_from: Sequence[float], q_to: Sequence[float]) -> tuple[float, float, float]:
    """Body-frame rotation vector [rad] taking attitude ``q_from`` to ``q_to`` (shortest way)."""
    w0, x0, y0, z0 = q_from[0], -q_from[1], -q_from[2], -q_from[3]
    w1, x1, y1, z1 = q_to
    w = w0 * w1 - x0 * x1 - y0 * y1 - z0 * z1
    x = w0 * x1 + x0 * w1 + y0 * z1 - z0 * y1
    y = w0 * y1 - x0 * z1 + y0 * w1 + z0 * x1
    z = w0 * z1 + x0 * y1 - y0 * x1 + z0 * w1
    if w < 0:
        w, x, y, z = -w, -x, -y, -z
    s = math.sqrt(x * x + y * y + z * z)
    k = 2.0 * math.atan2(s, w) / s if s > 1e-12 else 2.0
    return (k * x, k * y, k * z)


def quat_yaw(w: float, x: float, y: float, z: float) -> float:
    """Yaw angle [rad] of a quaternion (heading of the body x axis)."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quat_multiply(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, float, float]:
    """Hamilton product ``a * b``."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def quat_conjugate(q: Sequence[float]) -> tuple[float, float, float, float]:
    """Conjugate (the inverse of a unit quaternion)."""
    return (q[0], -q[1], -q[2], -q[3])


def quat_norm(q: Sequence[float]) -> float:
    """Euclidean norm of a quaternion."""
    return math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])


def quat_is_unit(q: Sequence[float], tol: float = 1e-3) -> bool:
    """ArduPilot's ``Quaternion::is_unit_length``: ``|1 - |q|^2| < tol``, all finite."""
    n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]
    return math.isfinite(n2) and abs(n2 - 1.0) < tol


def quat_rotate(q: Sequence[float], v: Sequence[float]) -> tuple[float, float, float]:
    """Rotate body vector ``v`` into NED with unit quaternion ``q``."""
    w, x, y, z = q
    vx, vy, vz = v
    # t = 2 (q_vec x v); v' = v + w t + q_vec x t
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (
        vx + w * tx + (y * tz - z * ty),
        vy + w * ty + (z * tx - x * tz),
        vz + w * tz + (x * ty - y * tx),
    )


def ned_from_paper(state: Sequence[float]) -> Kinematics:
    """NED kinematics of a reduced-model state (:class:`~quadrotor.state.State` order).

    ``z`` up becomes ``d = -z``; the Euler angles are shared; Euler-angle rates
    become body rates.
    """
    x, y, z, vx, vy, vz, roll, pitch, yaw, droll, dpitch, dyaw = (float(s) for s in state[:12])
    qw, qx, qy, qz = euler_to_quaternion(roll, pitch, yaw)
    p, q, r = euler_rates_to_body_rates(roll, pitch, droll, dpitch, dyaw)
    return Kinematics(x, y, -z, vx, vy, -vz, qw, qx, qy, qz, p, q, r)


def paper_from_ned(k: Kinematics) -> tuple[float, ...]:
    """Inverse of :func:`ned_from_paper` (reduced-model state tuple)."""
    roll, pitch, yaw = quaternion_to_euler((k.qw, k.qx, k.qy, k.qz))
    droll, dpitch, dyaw = body_rates_to_euler_rates(roll, pitch, k.p, k.q, k.r)
    return (k.n, k.e, -k.d, k.vn, k.ve, -k.vd, roll, pitch, yaw, droll, dpitch, dyaw)


def ned_wind_from_paper(wind: Sequence[float]) -> tuple[float, float, float]:
    """Wind velocity from the paper frame (:mod:`quadrotor.wind`, z up) to NED."""
    return (float(wind[0]), float(wind[1]), -float(wind[2]))
