"""Frame conversions between MAVLink (NED / FRD) and the paper's frame (z up) — the one place.

Paper frame: x north, y east (as MAVLink LOCAL_POSITION_NED), z **up** (altitude);
roll, pitch, yaw as MAVLink ATTITUDE (ZYX Euler angles of FRD body w.r.t. NED).
So ``z_paper = -z_ned`` and ``vz_paper = -vz_ned``; angles are shared.

The paper's model uses Euler-angle rates and accelerations (phi_dot, tau_phi = phi_ddot);
MAVLink carries body rates (p, q, r) and a body-frame torque/rate target.  The exact
kinematic maps are here, both ways.
"""

from __future__ import annotations

import math
from typing import Sequence

__all__ = [
    "ned_to_paper_position", "ned_to_paper_velocity", "paper_to_ned_position",
    "body_rates_to_euler_rates", "euler_rates_to_body_rates", "euler_accel_to_body_accel",
    "euler_to_quaternion", "quaternion_to_euler",
]


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


def euler_rates_to_body_rates(roll: float, pitch: float, droll: float, dpitch: float, dyaw: float) -> tuple[float, float, float]:
    """ZYX Euler-angle rates [rad/s] -> FRD body rates (p, q, r) [rad/s]."""
    sr, cr = math.sin(roll), math.cos(roll)
    sp, cp = math.sin(pitch), math.cos(pitch)
    return (droll - dyaw * sp, dpitch * cr + dyaw * cp * sr, -dpitch * sr + dyaw * cp * cr)


def euler_accel_to_body_accel(angles: Sequence[float], rates: Sequence[float], accels: Sequence[float]) -> tuple[float, float, float]:
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
