"""ArduCopter's custom flight modes (HEARTBEAT ``custom_mode``, MAV_CMD_DO_SET_MODE param2): one table.

The emulated autopilot implements some of them (``sitl``); the ground station names every
mode it sees and commands GUIDED_NOGPS and LAND.
"""

from __future__ import annotations

__all__ = ["COPTER_MODES", "COPTER_MODE_NAMES", "copter_mode_name"]

#: ArduCopter ``Mode::Number`` (ArduCopter/mode.h).
COPTER_MODES = {
    "STABILIZE": 0, "ACRO": 1, "ALT_HOLD": 2, "AUTO": 3, "GUIDED": 4, "LOITER": 5, "RTL": 6, "CIRCLE": 7,
    "LAND": 9, "DRIFT": 11, "SPORT": 13, "FLIP": 14, "AUTOTUNE": 15, "POSHOLD": 16, "BRAKE": 17,
    "THROW": 18, "AVOID_ADSB": 19, "GUIDED_NOGPS": 20, "SMART_RTL": 21, "FLOWHOLD": 22, "FOLLOW": 23,
    "ZIGZAG": 24, "SYSTEMID": 25, "AUTOROTATE": 26, "AUTO_RTL": 27, "TURTLE": 28,
}
COPTER_MODE_NAMES = {v: k for k, v in COPTER_MODES.items()}


def copter_mode_name(custom_mode: int) -> str:
    """The mode's name, or its number for one ArduCopter does not have."""
    return COPTER_MODE_NAMES.get(custom_mode, str(custom_mode))
