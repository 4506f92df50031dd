"""What ArduCopter says about itself: EKF readiness, HEARTBEAT status, AUTOPILOT_VERSION.

Measured on the firmware's SITL (4.8.0-dev at 64a9c787, default arming checks): its EKF sets the
origin ~20 s after boot, says "EKF3 IMU0 is using GPS" at ~38 s and sends the first
LOCAL_POSITION_NED at ~41.6 s; arming is refused with "PreArm: ..." texts until then.  Here the
ready time is ``ekf_ready_s`` (``sitl --ekf-ready-s``, default :data:`EKF_READY_S`), the origin
and GPS messages at the same fractions of it.  HEARTBEAT: ``base_mode`` 81 disarmed
(CUSTOM_MODE | STABILIZE | MANUAL_INPUT), 209 armed (+ SAFETY_ARMED), whatever the mode;
``system_status`` BOOT (1) for the first 3 s, then STANDBY (3) while landed -- armed on the
ground and in LAND until disarmed included -- and ACTIVE (4) in flight, CRITICAL (5) in a failsafe.
"""

from __future__ import annotations

__all__ = ["Readiness", "EKF_READY_S", "BOOT_S", "IDENTITY", "BASE_MODE_DISARMED", "BASE_MODE_ARMED"]

EKF_READY_S = 41.6
BOOT_S = 3.0
_ORIGIN_FRACTION = 20.0 / 41.6
_GPS_FRACTION = 38.0 / 41.6
BASE_MODE_DISARMED = 81
BASE_MODE_ARMED = 209
#: AUTOPILOT_VERSION (capabilities, flight_sw_version, flight_custom_version) of the firmware's SITL.
IDENTITY = (0xFBEF, 0x04080000, list(b"64a9c787"))


class Readiness:
    """The emulated EKF's start-up, in simulated time.

    Parameters
    ----------
    ready_s : float
        Time after boot [s] from which the position estimate exists and arming is allowed.
    """

    def __init__(self, ready_s: float) -> None:
        self.ready_s = ready_s
        self.boot_s = min(BOOT_S, ready_s)
        self._said: set[str] = set()

    def ready(self, now_s: float) -> bool:
        """The position estimate exists (LOCAL_POSITION_NED is sent, arming allowed)."""
        return now_s >= self.ready_s

    def booting(self, now_s: float) -> bool:
        """HEARTBEAT still says MAV_STATE_BOOT."""
        return now_s < self.boot_s

    def prearm_reason(self, now_s: float) -> str:
        """Why arming is refused now ("" once ready), the firmware's words."""
        if self.ready(now_s):
            return ""
        if now_s < self.ready_s * _ORIGIN_FRACTION:
            return "AHRS: waiting for home"
        return "Need Position Estimate"

    def news(self, now_s: float) -> list[str]:
        """STATUSTEXTs that fall due now (each once)."""
        out = []
        for at, text in ((self.ready_s * _ORIGIN_FRACTION, "EKF3 IMU0 origin set"),
                         (self.ready_s * _GPS_FRACTION, "EKF3 IMU0 is using GPS")):
            if now_s >= at and text not in self._said:
                self._said.add(text)
                out.append(text)
        return out
