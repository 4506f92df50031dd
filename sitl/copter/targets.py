"""Guided targets as ArduCopter takes them (``handle_message_set_attitude_target``).

SET_ATTITUDE_TARGET: THROTTLE_IGNORE (64) and non-unit quaternions (``|1 - |q|^2| >= 1e-3``) are
rejected; body rates are used only when all three rate-ignore bits (1, 2, 4) are clear (a partial
set is rejected), as feed-forward with an attitude or alone with ATTITUDE_IGNORE (128).  With
``GUID_OPTIONS`` bit 3 (8) the thrust field is throttle (0..1 of full thrust, angle-boosted by the
autopilot while ``ATC_ANGLE_BOOST = 1``, as ArduPilot does); otherwise it is a climb-rate demand:
0.5 holds, 1.0 climbs at ``WP_SPD_UP``, 0.0 descends at ``WP_SPD_DN``.

SET_ACTUATOR_CONTROL_TARGET (group 0) bypasses the attitude and rate loops: ``controls[0..2]`` in
[-1, 1] times :attr:`VehicleParams.max_torque_nm` are the body torques, ``controls[3]`` in [0, 1]
times the full thrust is the collective thrust (no angle boost); the mixer saturates them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

from quadrotor.frames import quat_is_unit
from sitl.copter.params import ParamStore

__all__ = ["Target", "attitude_target", "actuator_target"]

# SET_ATTITUDE_TARGET type_mask bits
_RATES_IGNORE = 7
_THROTTLE_IGNORE = 64
_ATTITUDE_IGNORE = 128
_GUID_OPTION_THRUST = 8


class Target(NamedTuple):
    """An accepted guided target.

    ``kind``: ``"attitude"`` (quaternion, rates as feed-forward), ``"rates"``
    (body rates only) or ``"actuator"`` (normalised torques).  ``use_thrust``:
    ``value`` is throttle 0..1, else a climb rate [m/s, up].
    """

    kind: str
    q: tuple[float, float, float, float]
    rates: tuple[float, float, float]
    use_thrust: bool
    value: float
    torques: tuple[float, float, float]
    time_ns: int


def _climb_rate(thrust: float, params: ParamStore) -> float:
    t = min(1.0, max(0.0, thrust))
    if t == 0.5:
        return 0.0
    if t > 0.5:
        return (t - 0.5) * 2.0 * params["WP_SPD_UP"]
    return (0.5 - t) * 2.0 * -params["WP_SPD_DN"]


def attitude_target(type_mask: int, q: Sequence[float], rates: Sequence[float], thrust: float, now_ns: int,
                    params: ParamStore) -> tuple[Target | None, str]:
    """A SET_ATTITUDE_TARGET's fields as a target, or ``(None, why it is refused)``."""
    if type_mask & _THROTTLE_IGNORE:
        return None, "THROTTLE_IGNORE"
    quat = (1.0, 0.0, 0.0, 0.0)
    if not type_mask & _ATTITUDE_IGNORE:
        quat = tuple(float(v) for v in q)  # type: ignore[assignment]
        if not quat_is_unit(quat):
            return None, "attitude quaternion not unit length"
        n = math.sqrt(sum(v * v for v in quat))
        quat = tuple(v / n for v in quat)  # type: ignore[assignment]
    rates_used = (type_mask & _RATES_IGNORE) == 0
    if not rates_used and (type_mask & _RATES_IGNORE) != _RATES_IGNORE:
        return None, "body rates partly ignored"
    rr = tuple(float(v) for v in rates) if rates_used else (0.0, 0.0, 0.0)
    if not all(math.isfinite(v) for v in rr) or not math.isfinite(thrust):
        return None, "not finite"
    use_thrust = bool(int(params["GUID_OPTIONS"]) & _GUID_OPTION_THRUST)
    value = min(1.0, max(-1.0, thrust)) if use_thrust else _climb_rate(thrust, params)
    kind = "rates" if type_mask & _ATTITUDE_IGNORE else "attitude"
    return Target(kind, quat, rr, use_thrust, value, (0.0, 0.0, 0.0), now_ns), ""  # type: ignore[arg-type]


def actuator_target(controls: Sequence[float], now_ns: int) -> tuple[Target | None, str]:
    """SET_ACTUATOR_CONTROL_TARGET group 0 controls as a target, or ``(None, why it is refused)``."""
    if len(controls) < 4 or not all(math.isfinite(float(v)) for v in controls[:4]):
        return None, "not finite"
    c = [float(v) for v in controls[:4]]
    tq = tuple(min(1.0, max(-1.0, v)) for v in c[:3])
    thr = min(1.0, max(0.0, c[3]))
    return Target("actuator", (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), True, thr, tq, now_ns), ""  # type: ignore[arg-type]
