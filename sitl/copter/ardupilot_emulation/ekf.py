"""The emulated EKF's height estimate: late and a few millimetres low, as ArduCopter's EKF3 is.

Measured on the firmware's SITL (4.8.0-dev at 64a9c787, ``gcs fly --sitl arducopter``, its dataflash
log: ``SIM.Alt`` beside ``XKF1.PD`` the EKF's down position, 10 Hz).  ``SIM.Alt`` was taken for the
truth; it is the simulator's smoothed altitude, what its sensors read (:mod:`.ground`), so the lag is
applied to that, after :class:`~sitl.copter.ardupilot_emulation.ground.SmoothedSensors`.  On the
ground the estimate sits 6 mm below it; after liftoff it follows it about 0.1 s late
(0.012-0.024 m behind at a 0.18 m/s climb) while its vertical velocity is not late.  So the estimate
is emulated as a first-order lag of the sensed down position (time constant :data:`HEIGHT_LAG_S`) plus
:data:`GROUND_OFFSET_M` plus the sensor model's noise (the lag delays the motion, it does not filter
the noise: filtering it too took a fifth off the flight's J_u_hover), the velocity left as measured
(docs/FIDELITY.md).
"""

from __future__ import annotations

import math

from sitl.copter.sensors import NavReading

__all__ = ["EkfHeight", "HEIGHT_LAG_S", "GROUND_OFFSET_M"]

HEIGHT_LAG_S = 0.1
GROUND_OFFSET_M = 0.006  # the estimate's down position minus the truth's [m] (+ = estimate lower)


class EkfHeight:
    """First-order lag of the down position, with the firmware's ground offset.

    Parameters
    ----------
    d0_m : float
        True down position at boot [m].
    lag_s : float
        Time constant [s]; 0 = no lag.
    offset_m : float
        Added to the down position [m].
    """

    def __init__(self, d0_m: float, lag_s: float = HEIGHT_LAG_S, offset_m: float = GROUND_OFFSET_M) -> None:
        if not (math.isfinite(lag_s) and lag_s >= 0.0 and math.isfinite(offset_m)):
            raise ValueError(f"lag_s must be >= 0 and offset_m finite, got {lag_s!r}, {offset_m!r}")
        self.lag_s = lag_s
        self.offset_m = offset_m
        self._d = d0_m

    def apply(self, nav: NavReading, true_d_m: float, dt_s: float) -> NavReading:
        """``nav`` (measured at the true down position ``true_d_m``) with its down position late and offset.

        The lag is advanced by ``dt_s`` [s]; ``nav.d - true_d_m`` (the sensor noise) is kept.
        """
        if self.lag_s > 0.0:
            self._d += (true_d_m - self._d) * (1.0 - math.exp(-dt_s / self.lag_s))
        else:
            self._d = true_d_m
        return nav._replace(d=self._d + self.offset_m + (nav.d - true_d_m))
