"""Telemetry validation: what the vehicle sends is checked before the estimator sees it.

A message is used only if every number in it is finite, within the range the
physics allows (a quadrotor's attitude, rates, position and speed), and its
vehicle time stamp does not go backwards nor leap implausibly far ahead.
Anything else is rejected and counted per ``"<MESSAGE>: <reason>"``; the count
goes to the summary and the log, the first rejection of each kind is an event.
This stands between a hostile or broken link and the controller: one NaN that
reached the estimator would poison every later command.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from collections.abc import Callable

__all__ = ["TelemetryLimits", "TelemetryValidator"]


@dataclass(frozen=True)
class TelemetryLimits:
    """Ranges outside which telemetry is physically implausible for a small multirotor (SI units)."""

    #: |roll|, |pitch| [rad] (MAVLink reports -pi..pi).
    max_tilt_rad: float = math.pi + 1e-3
    #: |yaw| [rad] (some autopilots report 0..2 pi).
    max_yaw_rad: float = 2.0 * math.pi + 1e-3
    #: Body rates [rad/s]: beyond a MEMS gyro's 2000 deg/s range.
    max_rate_rad_s: float = 35.0
    #: Local position from the origin [m].
    max_position_m: float = 100_000.0
    #: Speed per axis [m/s].
    max_speed_m_s: float = 100.0
    #: Battery voltage [V].
    max_voltage_v: float = 100.0
    #: A vehicle time stamp may move ahead of the previous one by at most this much plus
    #: ``max_time_speedup`` times the wall time in between [s] (lockstep simulators run fast).
    max_time_leap_s: float = 5.0
    max_time_speedup: float = 200.0


@dataclass
class TelemetryValidator:
    """Checks messages and counts the rejected ones.

    Parameters
    ----------
    limits : TelemetryLimits
    on_first : callable (reason) or None
        Told the first time each reason occurs (an event for the pilot and the log).
    wall_ns : callable () -> int
        Wall clock for the time-leap check (injected for tests).
    """

    limits: TelemetryLimits = field(default_factory=TelemetryLimits)
    on_first: Callable[[str], None] | None = None
    wall_ns: Callable[[], int] = time.monotonic_ns
    rejected: dict[str, int] = field(default_factory=dict)
    _last_time: dict[str, tuple[int, int]] = field(default_factory=dict)

    def reject(self, message: str, reason: str) -> bool:
        """Count a rejection (always returns False, for ``return v.reject(...)``)."""
        key = f"{message}: {reason}"
        n = self.rejected.get(key, 0)
        self.rejected[key] = n + 1
        if n == 0 and self.on_first is not None:
            self.on_first(key)
        return False

    @property
    def total(self) -> int:
        return sum(self.rejected.values())

    def time_ok(self, message: str, time_ms: int) -> bool:
        """``time_ms`` (the vehicle's clock) neither goes back nor leaps ahead for this message type."""
        now = self.wall_ns()
        last = self._last_time.get(message)
        if last is not None:
            t_last, wall_last = last
            if time_ms < t_last:
                return self.reject(message, "time stamp went backwards")
            if time_ms == t_last:
                return self.reject(message, "duplicate time stamp")
            lim = self.limits
            allowed_ms = 1000.0 * (lim.max_time_leap_s + lim.max_time_speedup * (now - wall_last) / 1e9)
            if time_ms - t_last > allowed_ms:
                return self.reject(message, "time stamp leapt ahead")
        self._last_time[message] = (time_ms, now)
        return True

    @staticmethod
    def _finite(*values: float) -> bool:
        return all(math.isfinite(v) for v in values)

    def attitude(self, roll: float, pitch: float, yaw: float, p: float, q: float, r: float, time_ms: int | None,
                 message: str = "ATTITUDE") -> bool:
        """Attitude [rad] and body rates [rad/s] with their time stamp [ms] (None: the caller checks time)."""
        if not self._finite(roll, pitch, yaw, p, q, r):
            return self.reject(message, "non-finite value")
        lim = self.limits
        if abs(roll) > lim.max_tilt_rad or abs(pitch) > lim.max_tilt_rad or abs(yaw) > lim.max_yaw_rad:
            return self.reject(message, "angle out of range")
        if abs(p) > lim.max_rate_rad_s or abs(q) > lim.max_rate_rad_s or abs(r) > lim.max_rate_rad_s:
            return self.reject(message, "rate out of range")
        return True if time_ms is None else self.time_ok(message, time_ms)

    def position(self, x: float, y: float, z: float, vx: float, vy: float, vz: float, time_ms: int | None,
                 message: str = "LOCAL_POSITION_NED") -> bool:
        """Local position [m] and velocity [m/s] with their time stamp [ms]."""
        if not self._finite(x, y, z, vx, vy, vz):
            return self.reject(message, "non-finite value")
        lim = self.limits
        if max(abs(x), abs(y), abs(z)) > lim.max_position_m:
            return self.reject(message, "position out of range")
        if max(abs(vx), abs(vy), abs(vz)) > lim.max_speed_m_s:
            return self.reject(message, "velocity out of range")
        return True if time_ms is None else self.time_ok(message, time_ms)

    def voltage(self, volts: float, message: str = "SYS_STATUS") -> bool:
        if not self._finite(volts) or not 0.0 <= volts <= self.limits.max_voltage_v:
            return self.reject(message, "battery voltage out of range")
        return True
