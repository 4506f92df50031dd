"""Mixer: collective thrust and body torques to the four rotor thrusts, with saturation.

The exact inverse of the X layout (see :mod:`sitl.copter.vehicle`) with
``d = L / sqrt(2)``::

    T1 = F/4 + (-tau_x + tau_y) / (4 d) + tau_z / (4 k)
    T2 = F/4 + ( tau_x - tau_y) / (4 d) + tau_z / (4 k)
    T3 = F/4 + ( tau_x + tau_y) / (4 d) - tau_z / (4 k)
    T4 = F/4 + (-tau_x - tau_y) / (4 d) - tau_z / (4 k)

Saturation keeps every rotor within ``[T_min, T_max]`` with ArduPilot's
priorities (``AP_MotorsMatrix``): roll/pitch first, then yaw, then the
collective thrust.  The roll/pitch part is scaled down only if its spread
alone exceeds the range; the yaw part is scaled down until roll/pitch/yaw fit;
the collective is then shifted into the remaining room (so a thrust demand
below what attitude control needs is raised, and one above is lowered).
"""

from __future__ import annotations

from typing import NamedTuple

from sitl.copter.vehicle import VehicleParams

__all__ = ["Mixer", "MixResult"]

_new = tuple.__new__


class MixResult(NamedTuple):
    """Rotor thrusts [N] of motors 1..4 and what saturated."""

    t1: float
    t2: float
    t3: float
    t4: float
    rp_limited: bool
    yaw_limited: bool
    thrust_limited: bool

    @property
    def thrusts(self) -> tuple[float, float, float, float]:
        """``(t1, t2, t3, t4)``."""
        return (self.t1, self.t2, self.t3, self.t4)



class Mixer:
    """Mixer for one vehicle.

    Every rotor stays within ``[rotors.min_thrust_n, rotors.max_thrust_n]``.
    """

    def __init__(self, vehicle: VehicleParams) -> None:
        r = vehicle.rotors
        d = r.arm_length_m / 2.0 ** 0.5
        self.t_max = r.max_thrust_n
        self.t_min = r.min_thrust_n
        self._kd = 1.0 / (4.0 * d)
        self._kk = 1.0 / (4.0 * r.yaw_moment_m)

    def mix(self, thrust_n: float, tau_x: float, tau_y: float, tau_z: float) -> MixResult:
        """Rotor thrusts for a collective thrust [N] and body torques [N m]."""
        lo, hi = self.t_min, self.t_max
        span = hi - lo
        a = self._kd * (tau_y - tau_x)   # motor 1 roll/pitch share; motor 2 = -a
        b = self._kd * (tau_x + tau_y)   # motor 3 share; motor 4 = -b
        yw = self._kk * tau_z            # + for motors 1, 2; - for 3, 4
        c = 0.25 * thrust_n
        m1, m2, m3, m4 = c + a + yw, c - a + yw, c + b - yw, c - b - yw
        if (lo <= m1 <= hi and lo <= m2 <= hi and lo <= m3 <= hi and lo <= m4 <= hi):
            return _new(MixResult, (m1, m2, m3, m4, False, False, False))
        rp1, rp2, rp3, rp4 = a, -a, b, -b
        rp_lim = yaw_lim = False
        rp_hi = max(rp1, rp2, rp3, rp4)
        rp_lo = min(rp1, rp2, rp3, rp4)
        if rp_hi - rp_lo > span:
            scale = span / (rp_hi - rp_lo)
            rp1, rp2, rp3, rp4 = rp1 * scale, rp2 * scale, rp3 * scale, rp4 * scale
            rp_lim = True
            yw = 0.0
            yaw_lim = tau_z != 0.0
        elif yw != 0.0:
            # Largest s in [0, 1] such that the spread of rp_i + s y_i fits the range.
            y1 = y2 = yw
            y3 = y4 = -yw
            s = 1.0
            vals = ((rp1, y1), (rp2, y2), (rp3, y3), (rp4, y4))
            for ri, yi in vals:
                for rj, yj in vals:
                    dy = yi - yj
                    if dy > 0.0:
                        lim = (span - (ri - rj)) / dy
                        if lim < s:
                            s = lim
            if s < 1.0:
                yw *= max(s, 0.0)
                yaw_lim = True
        m1, m2, m3, m4 = rp1 + yw, rp2 + yw, rp3 - yw, rp4 - yw
        top = max(m1, m2, m3, m4)
        bot = min(m1, m2, m3, m4)
        c = 0.25 * thrust_n
        thr_lim = False
        if c + top > hi:
            c = hi - top
            thr_lim = True
        if c + bot < lo:
            c = lo - bot
            thr_lim = True
        return MixResult(c + m1, c + m2, c + m3, c + m4, rp_lim, yaw_lim, thr_lim)
