"""Pre-arm checks (MAV_CMD_COMPONENT_ARM_DISARM without the force value 21196).

Arming is refused outside STABILIZE / GUIDED / GUIDED_NOGPS; with ``ARMING_CHECK != 0`` also before
the pre-arm delay has passed (an estimator still settling), when leaning more than
``ATC_ANGLE_MAX``, when not landed (altitude above 1 m or speed above 0.5 m/s), and when the
battery's resting voltage is below ``BATT_ARM_VOLT`` or ``BATT_LOW_VOLT`` or less than
``BATT_LOW_MAH`` is left.
"""

from __future__ import annotations

import math

from sitl.copter.battery import BatteryState
from sitl.copter.modes import ARMABLE_MODES, Mode
from sitl.copter.params import ParamStore
from sitl.copter.sensors import ImuReading, NavReading

__all__ = ["arming_failure", "resting_voltage", "battery_low"]


def resting_voltage(b: BatteryState, internal_resistance_ohm: float) -> float:
    """The pack's voltage without the present load [V]."""
    return b.voltage_v + b.current_a * internal_resistance_ohm


def battery_low(b: BatteryState, params: ParamStore, internal_resistance_ohm: float) -> tuple[bool, float]:
    """``(low, resting voltage [V])``: below ``BATT_LOW_VOLT`` or less than ``BATT_LOW_MAH`` left (0 = off)."""
    rest = resting_voltage(b, internal_resistance_ohm)
    low_v, low_mah = params["BATT_LOW_VOLT"], params["BATT_LOW_MAH"]
    low = (low_v > 0 and rest < low_v) or (low_mah > 0 and params["BATT_CAPACITY"] - b.consumed_mah < low_mah)
    return low, rest


def _battery_failure(b: BatteryState, params: ParamStore, internal_resistance_ohm: float) -> str:
    rest = resting_voltage(b, internal_resistance_ohm)
    arm_v = params["BATT_ARM_VOLT"]
    low_v = params["BATT_LOW_VOLT"]
    if arm_v > 0 and rest < arm_v:
        return f"Battery 1 below min arming volt ({rest:.2f} V)"
    if low_v > 0 and rest < low_v:
        return f"Battery 1 low voltage failsafe ({rest:.2f} V)"
    low_mah = params["BATT_LOW_MAH"]
    if low_mah > 0 and params["BATT_CAPACITY"] - b.consumed_mah < low_mah:
        return "Battery 1 low capacity failsafe"
    return ""


def arming_failure(mode: Mode, now_ns: int, prearm_delay_ns: int, params: ParamStore, imu: ImuReading | None,
                   nav: NavReading | None, battery: BatteryState | None, internal_resistance_ohm: float) -> str:
    """Why arming is refused now ("" if it is not), from the latest readings (None: not read yet)."""
    if mode not in ARMABLE_MODES:
        return "Mode not armable"
    if params["ARMING_CHECK"] == 0:
        return ""
    if now_ns < prearm_delay_ns:
        return f"AHRS not ready ({(prearm_delay_ns - now_ns) * 1e-9:.1f} s)"
    if imu is not None:
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, math.cos(imu.roll) * math.cos(imu.pitch)))))
        if tilt > params["ATC_ANGLE_MAX"]:
            return f"Leaning ({tilt:.0f} deg > ATC_ANGLE_MAX)"
    if nav is not None:
        speed = math.sqrt(nav.vn ** 2 + nav.ve ** 2 + nav.vd ** 2)
        if abs(nav.baro_alt_m) > 1.0 or speed > 0.5:
            return f"Not landed (alt {nav.baro_alt_m:.1f} m, {speed:.1f} m/s)"
    if battery is not None:
        return _battery_failure(battery, params, internal_resistance_ohm)
    return ""
