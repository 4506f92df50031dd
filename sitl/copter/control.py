"""Inner loops of the emulated autopilot: attitude, body rate, climb rate.

* Attitude: the error rotation ``q_err = conj(q) * q_target`` (body frame) as a
  rotation vector, times the angle gains ``ATC_ANG_*_P`` [1/s], plus the
  target's body-rate feed-forward, gives the body-rate demand (limited by
  ``ATC_RATE_*_MAX`` when set).
* Rate: angular-acceleration demand ``alpha = Kp (w_d - w) + Ki int(w_d - w)``
  ([control] gains of the vehicle file), torque ``J alpha + w x (J w)``.
* Climb rate: the target is shaped by an acceleration limit (``WP_ACC_Z``),
  then vertical acceleration ``a = Kp e + Ki int e`` becomes throttle
  ``MOT_THST_HOVER (1 + a / g)`` (ArduPilot's hover-throttle scaling).
* LAND's drift damping: horizontal acceleration ``-k v`` (at most ``g tan 10 deg``) as a lean.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from quadrotor.frames import euler_to_quaternion

__all__ = ["attitude_rate_demand", "RateController", "ClimbRateController", "angle_boost", "land_attitude",
           "land_speed"]


def attitude_rate_demand(q_target: Sequence[float], q_meas: Sequence[float], gains: Sequence[float],
                         ff: Sequence[float] = (0.0, 0.0, 0.0),
                         limits: Sequence[float] = (0.0, 0.0, 0.0)) -> tuple[float, float, float]:
    """Body-rate demand [rad/s] to turn attitude ``q_meas`` into ``q_target``.

    Parameters
    ----------
    q_target, q_meas : (w, x, y, z)
        Unit quaternions, body to NED.
    gains : (3,) float
        Angle P gains [1/s] (roll, pitch, yaw).
    ff : (3,) float
        Body-rate feed-forward [rad/s].
    limits : (3,) float
        Rate limits [rad/s]; 0 = none.
    """
    bw, bx, by, bz = q_target
    aw, ax, ay, az = q_meas
    # q_err = conj(q_meas) * q_target
    w = aw * bw + ax * bx + ay * by + az * bz
    x = aw * bx - ax * bw - ay * bz + az * by
    y = aw * by + ax * bz - ay * bw - az * bx
    z = aw * bz - ax * by + ay * bx - az * bw
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    s = math.sqrt(x * x + y * y + z * z)
    k = 2.0 * math.atan2(s, w) / s if s > 1e-12 else 2.0
    ex = gains[0] * k * x + ff[0]
    ey = gains[1] * k * y + ff[1]
    ez = gains[2] * k * z + ff[2]
    lx, ly, lz = limits
    if lx > 0.0:
        ex = lx if ex > lx else -lx if ex < -lx else ex
    if ly > 0.0:
        ey = ly if ey > ly else -ly if ey < -ly else ey
    if lz > 0.0:
        ez = lz if ez > lz else -lz if ez < -lz else ez
    return (ex, ey, ez)


class RateController:
    """Body-rate PI loop producing torques.

    Parameters
    ----------
    inertia : 3x3 sequence
        Inertia matrix [kg m^2].
    kp : (3,) float
        [1/s]; angular acceleration per rate error.
    ki : (3,) float
        [1/s^2].
    imax : float
        Integrator clamp [rad/s^2].
    """

    def __init__(self, inertia: Sequence[Sequence[float]], kp: Sequence[float], ki: Sequence[float],
                 imax: float) -> None:
        self.j = tuple(tuple(float(v) for v in row) for row in inertia)
        self.kp = tuple(kp)
        self.ki = tuple(ki)
        self.imax = imax
        self.integ = [0.0, 0.0, 0.0]

    def reset(self) -> None:
        """Clear the integrators."""
        self.integ = [0.0, 0.0, 0.0]

    def update(self, target: Sequence[float], rates: Sequence[float], dt: float,
               freeze: bool = False) -> tuple[float, float, float]:
        """Torque demand [N m] for rate ``target`` given measured ``rates`` [rad/s].

        ``freeze`` holds the integrators (anti-windup while the mixer saturates).
        """
        p, q, r = rates
        ex = target[0] - p
        ey = target[1] - q
        ez = target[2] - r
        kpx, kpy, kpz = self.kp
        integ = self.integ
        if not freeze:
            kix, kiy, kiz = self.ki
            lim = self.imax
            v = integ[0] + kix * ex * dt
            integ[0] = lim if v > lim else -lim if v < -lim else v
            v = integ[1] + kiy * ey * dt
            integ[1] = lim if v > lim else -lim if v < -lim else v
            v = integ[2] + kiz * ez * dt
            integ[2] = lim if v > lim else -lim if v < -lim else v
        ax = kpx * ex + integ[0]
        ay = kpy * ey + integ[1]
        az = kpz * ez + integ[2]
        (j00, j01, j02), (j10, j11, j12), (j20, j21, j22) = self.j
        hx = j00 * p + j01 * q + j02 * r
        hy = j10 * p + j11 * q + j12 * r
        hz = j20 * p + j21 * q + j22 * r
        return (
            j00 * ax + j01 * ay + j02 * az + (q * hz - r * hy),
            j10 * ax + j11 * ay + j12 * az + (r * hx - p * hz),
            j20 * ax + j21 * ay + j22 * az + (p * hy - q * hx),
        )


def angle_boost(throttle: float, cos_tilt: float) -> float:
    """ArduPilot's angle boost: ``throttle / cos(tilt)``, faded out when inverted."""
    inverted = 10.0 * cos_tilt
    inverted = 0.0 if inverted < 0.0 else 1.0 if inverted > 1.0 else inverted
    c = 0.1 if cos_tilt < 0.1 else 1.0 if cos_tilt > 1.0 else cos_tilt
    return throttle * inverted / c


class ClimbRateController:
    """Climb-rate loop producing a throttle (0..1 of full thrust, before angle boost).

    Parameters
    ----------
    kp : float
        [1/s]; vertical acceleration per climb-rate error.
    ki : float
        [1/s^2].
    gravity_m_s2 : float
    """

    def __init__(self, kp: float, ki: float, gravity_m_s2: float) -> None:
        self.kp = kp
        self.ki = ki
        self.g = gravity_m_s2
        self.integ = 0.0
        self.shaped = 0.0

    def reset(self, climb_m_s: float = 0.0) -> None:
        """Clear the integrator; start the shaped target at ``climb_m_s``."""
        self.integ = 0.0
        self.shaped = climb_m_s

    def update(self, target_m_s: float, climb_m_s: float, dt: float, hover: float,
               accel_limit_m_s2: float) -> float:
        """Throttle for climb rate ``target_m_s`` (up positive) given the measured climb rate."""
        step = accel_limit_m_s2 * dt
        diff = target_m_s - self.shaped
        self.shaped += step if diff > step else -step if diff < -step else diff
        err = self.shaped - climb_m_s
        accel = self.kp * err + self.integ
        lim = 0.9 * self.g
        accel = lim if accel > lim else -lim if accel < -lim else accel
        thr = hover * (1.0 + accel / self.g)
        if 0.0 < thr < 1.0:  # anti-windup: integrate only while unsaturated
            v = self.integ + self.ki * err * dt
            self.integ = lim if v > lim else -lim if v < -lim else v
        return 0.0 if thr < 0.0 else 1.0 if thr > 1.0 else thr


def land_attitude(vn: float, ve: float, yaw: float, damping_1_s: float,
                  gravity_m_s2: float) -> tuple[float, float, float, float]:
    """Attitude (body to NED quaternion) that damps the horizontal velocity ``(vn, ve)`` at heading ``yaw``."""
    g = gravity_m_s2
    amax = g * math.tan(math.radians(10.0))
    an, ae = -damping_1_s * vn, -damping_1_s * ve
    norm = math.hypot(an, ae)
    if norm > amax:
        an, ae = an * amax / norm, ae * amax / norm
    cy, sy = math.cos(yaw), math.sin(yaw)
    fwd = cy * an + sy * ae
    right = -sy * an + cy * ae
    return euler_to_quaternion(math.atan(right / g), -math.atan(fwd / g), yaw)


def land_speed(params, altitude_m: float) -> float:
    """LAND's descent speed [m/s] at ``altitude_m`` above home (``LAND_SPD_HIGH_MS`` or ``WP_SPD_DN`` high up)."""
    if altitude_m > params["LAND_ALT_LOW_M"]:
        high = params["LAND_SPD_HIGH_MS"]
        return high if high > 0 else params["WP_SPD_DN"]
    return params["LAND_SPD_MS"]
