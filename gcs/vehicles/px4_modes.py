"""PX4's flight modes: HEARTBEAT ``custom_mode`` = main mode << 16 | sub mode << 24, one table.

PX4 (``src/modules/commander/px4_custom_mode.h``) packs its mode into the 32-bit
``custom_mode``: byte 2 the main mode, byte 3 the AUTO sub mode.  MAV_CMD_DO_SET_MODE takes
``param1 = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED``, ``param2`` the main mode and ``param3`` the sub
mode.  Names are QGroundControl's, so the pilot sees the same words in both.
"""

from __future__ import annotations

__all__ = ["MAIN_MODES", "AUTO_SUB_MODES", "px4_mode", "px4_mode_name", "split_mode", "OFFBOARD", "HOLD", "LAND",
           "RETURN", "PX4_MODES"]

#: PX4_CUSTOM_MAIN_MODE_*.
MAIN_MODES = {"MANUAL": 1, "ALTCTL": 2, "POSCTL": 3, "AUTO": 4, "ACRO": 5, "OFFBOARD": 6, "STABILIZED": 7,
              "RATTITUDE": 8, "SIMPLE": 9, "TERMINATION": 10}
#: PX4_CUSTOM_SUB_MODE_AUTO_* (main mode AUTO).
AUTO_SUB_MODES = {"READY": 1, "TAKEOFF": 2, "LOITER": 3, "MISSION": 4, "RTL": 5, "LAND": 6, "FOLLOW_TARGET": 8,
                  "PRECLAND": 9, "VTOL_TAKEOFF": 10}
_MAIN_NAMES = {1: "Manual", 2: "Altitude", 3: "Position", 5: "Acro", 6: "Offboard", 7: "Stabilized",
               8: "Rattitude", 9: "Simple", 10: "Termination"}
_AUTO_NAMES = {1: "Ready", 2: "Takeoff", 3: "Hold", 4: "Mission", 5: "Return", 6: "Land", 8: "Follow Me",
               9: "Precision Land", 10: "VTOL Takeoff"}


def px4_mode(main: int, sub: int = 0) -> int:
    """HEARTBEAT ``custom_mode`` of a main mode and (AUTO) sub mode."""
    if not (0 <= main <= 255 and 0 <= sub <= 255):
        raise ValueError(f"PX4 main/sub modes are bytes, got {main!r}/{sub!r}")
    return (main << 16) | (sub << 24)


def split_mode(custom_mode: int) -> tuple[int, int]:
    """(main mode, sub mode) of a ``custom_mode``."""
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


OFFBOARD = px4_mode(MAIN_MODES["OFFBOARD"])
HOLD = px4_mode(MAIN_MODES["AUTO"], AUTO_SUB_MODES["LOITER"])
LAND = px4_mode(MAIN_MODES["AUTO"], AUTO_SUB_MODES["LAND"])
RETURN = px4_mode(MAIN_MODES["AUTO"], AUTO_SUB_MODES["RTL"])
#: The modes by QGroundControl's name.
PX4_MODES = {"Offboard": OFFBOARD, "Hold": HOLD, "Land": LAND, "Return": RETURN,
             "Position": px4_mode(3), "Altitude": px4_mode(2), "Manual": px4_mode(1), "Stabilized": px4_mode(7),
             "Mission": px4_mode(4, 4), "Takeoff": px4_mode(4, 2)}


def px4_mode_name(custom_mode: int) -> str:
    """The pilot's name of a PX4 ``custom_mode`` (its number when PX4 has no such mode; -1: none seen yet)."""
    if custom_mode < 0:
        return "unknown"
    main, sub = split_mode(custom_mode)
    if main == MAIN_MODES["AUTO"]:
        name = _AUTO_NAMES.get(sub)
        return name if name is not None else f"AUTO.{sub}"
    name = _MAIN_NAMES.get(main)
    return name if name is not None and sub == 0 else str(custom_mode)
