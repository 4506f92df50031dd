"""The last guard before the wire: no non-finite or out-of-limit command is ever sent.

Whatever the estimator, the controller, the envelope or an output adapter
produced, the link hands every outgoing message to :meth:`OutputGuard.check`
before it is encoded.  A setpoint with a NaN, an infinity, a non-unit
quaternion, a thrust outside 0..1 (MAVLink) or the vehicle's thrust range (the
rig), or angular rates/accelerations beyond the vehicle's limits is not sent:
the link raises :class:`UnsafeCommand`, the flight sends a safe level command
instead and fails safe (exit ``unsafe_command``).  Non-setpoint messages
(commands, parameters) must be finite too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from gcs.errors import GcsError

__all__ = ["GuardLimits", "OutputGuard", "UnsafeCommand"]


class UnsafeCommand(GcsError):
    """An outgoing message was blocked by the output guard (it never reached the wire)."""

    exit_code = 10


@dataclass(frozen=True)
class GuardLimits:
    """What may reach the wire (SI units).

    Attributes
    ----------
    max_body_rate_rad_s : float
        |body rate| in SET_ATTITUDE_TARGET.
    quaternion_tolerance : float
        | |q| - 1 | allowed.
    max_thrust_n, max_angular_accel_rad_s2 : float
        The rig's CONTROL frames: thrust in [0, max_thrust_n], |tau| <= max_angular_accel_rad_s2.
    """

    max_body_rate_rad_s: float = 35.0
    quaternion_tolerance: float = 1e-3
    max_thrust_n: float = math.inf
    max_angular_accel_rad_s2: float = math.inf


def _finite(values) -> bool:
    return all(math.isfinite(v) for v in values)


@dataclass
class OutputGuard:
    """Checks outgoing messages; counts what it blocked (``blocked``, per reason)."""

    limits: GuardLimits = field(default_factory=GuardLimits)
    blocked: dict[str, int] = field(default_factory=dict)

    def _block(self, what: str, reason: str) -> str:
        key = f"{what}: {reason}"
        self.blocked[key] = self.blocked.get(key, 0) + 1
        return key

    def check(self, msg) -> str | None:
        """None when ``msg`` (a pymavlink message or a rig message) may be sent, else the reason."""
        name = msg.get_type() if hasattr(msg, "get_type") else type(msg).__name__
        check = _CHECKS.get(name)
        if check is not None:
            reason = check(self.limits, msg)
            if reason is not None:
                return self._block(name, reason)
        return None

    @property
    def total(self) -> int:
        return sum(self.blocked.values())


def _attitude_target(lim: GuardLimits, m) -> str | None:
    q = list(m.q)
    rates = (m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate)
    if not _finite(q) or not _finite(rates) or not math.isfinite(m.thrust):
        return "non-finite field"
    if abs(math.sqrt(sum(v * v for v in q)) - 1.0) > lim.quaternion_tolerance:
        return "quaternion not unit"
    if not 0.0 <= m.thrust <= 1.0:
        return "thrust outside 0..1"
    if max(abs(r) for r in rates) > lim.max_body_rate_rad_s:
        return "body rate beyond limit"
    return None


def _actuator_target(lim: GuardLimits, m) -> str | None:
    c = list(m.controls)
    if not _finite(c):
        return "non-finite field"
    if max(abs(v) for v in c) > 1.0:
        return "control outside -1..1"
    return None


def _command_long(lim: GuardLimits, m) -> str | None:
    if not _finite((m.param1, m.param2, m.param3, m.param4, m.param5, m.param6, m.param7)):
        return "non-finite parameter"
    return None


#: MAV_PARAM_TYPE UINT8..INT32: the value may travel bytewise (PX4), a negative integer as a NaN pattern.
_INT_PARAM_TYPES = frozenset(range(1, 7))


def _param_set(lim: GuardLimits, m) -> str | None:
    if m.param_type in _INT_PARAM_TYPES:
        return None
    return None if math.isfinite(m.param_value) else "non-finite value"


def _rig_control(lim: GuardLimits, m) -> str | None:
    acc = (m.roll_accel_rad_s2, m.pitch_accel_rad_s2, m.yaw_accel_rad_s2)
    if not math.isfinite(m.thrust_n) or not _finite(acc):
        return "non-finite field"
    if not 0.0 <= m.thrust_n <= lim.max_thrust_n:
        return "thrust outside the vehicle's range"
    if max(abs(a) for a in acc) > lim.max_angular_accel_rad_s2:
        return "angular acceleration beyond limit"
    return None


_CHECKS = {
    "SET_ATTITUDE_TARGET": _attitude_target,
    "SET_ACTUATOR_CONTROL_TARGET": _actuator_target,
    "COMMAND_LONG": _command_long,
    "PARAM_SET": _param_set,
    "Control": _rig_control,
}
