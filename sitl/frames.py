"""Frames, quaternions and the one conversion between the paper frame and NED.

Conventions
-----------
* World frame: NED (north, east, down), as in MAVLink ``LOCAL_POSITION_NED``.
* Body frame: FRD (forward, right, down).
* Attitude: unit quaternion ``(w, x, y, z)`` rotating body vectors into NED
  (MAVLink ``SET_ATTITUDE_TARGET.q``, ``ATTITUDE_QUATERNION``); Euler angles are
  the aerospace Z-Y-X sequence (yaw, then pitch, then roll) of MAVLink
  ``ATTITUDE``.
* Paper frame (``sitl.reduced``, ``gcs``): x north, y east, **z up**; the same
  Euler angles; *Euler-angle* rates instead of body rates.

:func:`ned_from_paper` is the single place where a reduced-model state is
turned into NED kinematics; :func:`paper_from_ned` is its inverse (tests).
Everything here works on plain floats: it runs in the 400 Hz loop.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Sequence

__all__ = [
    "Kinematics", "quat_from_euler", "euler_from_quat", "quat_multiply", "quat_conjugate",
    "quat_norm", "quat_is_unit", "quat_rotate", "quat_yaw", "body_from_euler_rates",
    "euler_from_body_rates", "ned_from_paper", "paper_from_ned", "ned_wind_from_paper",
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


def quat_from_euler(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """Quaternion (body to NED) of Z-Y-X Euler angles [rad]."""
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def euler_from_quat(w: float, x: float, y: float, z: float) -> tuple[float, float, float]:
    """Z-Y-X Euler angles ``(roll, pitch, yaw)`` [rad] of a unit quaternion.

    Pitch is clipped to +-pi/2 at the singularity; yaw is in (-pi, pi].
    """
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    s = 2.0 * (w * y - z * x)
    pitch = math.asin(1.0 if s > 1.0 else -1.0 if s < -1.0 else s)
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


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


def body_from_euler_rates(roll: float, pitch: float, droll: float, dpitch: float,
                          dyaw: float) -> tuple[float, float, float]:
    """Body rates ``(p, q, r)`` [rad/s] from Z-Y-X Euler-angle rates."""
    sr, cr = math.sin(roll), math.cos(roll)
    sp, cp = math.sin(pitch), math.cos(pitch)
    return (
        droll - sp * dyaw,
        cr * dpitch + sr * cp * dyaw,
        -sr * dpitch + cr * cp * dyaw,
    )


def euler_from_body_rates(roll: float, pitch: float, p: float, q: float,
                          r: float) -> tuple[float, float, float]:
    """Z-Y-X Euler-angle rates [rad/s] from body rates (singular at pitch = +-90 deg)."""
    sr, cr = math.sin(roll), math.cos(roll)
    cp = math.cos(pitch)
    tp = math.tan(pitch)
    return (
        p + (q * sr + r * cr) * tp,
        q * cr - r * sr,
        (q * sr + r * cr) / cp,
    )


def ned_from_paper(state: Sequence[float]) -> Kinematics:
    """NED kinematics of a reduced-model state (``sitl.reduced.STATE_FIELDS`` order).

    ``z`` up becomes ``d = -z``; the Euler angles are shared; Euler-angle rates
    become body rates.
    """
    x, y, z, vx, vy, vz, roll, pitch, yaw, droll, dpitch, dyaw = (float(s) for s in state[:12])
    qw, qx, qy, qz = quat_from_euler(roll, pitch, yaw)
    p, q, r = body_from_euler_rates(roll, pitch, droll, dpitch, dyaw)
    return Kinematics(x, y, -z, vx, vy, -vz, qw, qx, qy, qz, p, q, r)


def paper_from_ned(k: Kinematics) -> tuple[float, ...]:
    """Inverse of :func:`ned_from_paper` (reduced-model state tuple)."""
    roll, pitch, yaw = euler_from_quat(k.qw, k.qx, k.qy, k.qz)
    droll, dpitch, dyaw = euler_from_body_rates(roll, pitch, k.p, k.q, k.r)
    return (k.n, k.e, -k.d, k.vn, k.ve, -k.vd, roll, pitch, yaw, droll, dpitch, dyaw)


def ned_wind_from_paper(wind: Sequence[float]) -> tuple[float, float, float]:
    """Wind velocity from the paper frame (``sitl.wind``, z up) to NED."""
    return (float(wind[0]), float(wind[1]), -float(wind[2]))
