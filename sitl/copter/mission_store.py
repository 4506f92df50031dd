"""What the ground station uploaded: missions, fences and rally points, and the vehicle's home.

The data model only; the MAVLink mission protocol that fills it is :mod:`sitl.copter.mission`
and the AUTO mode that flies it is in the autopilot.  Positions are kept as MAVLink sends them
(MISSION_ITEM_INT: ``x``/``y`` latitude/longitude in degE7 or local metres, ``z`` in metres in
``frame``), so a download gives back exactly what was uploaded, as ArduPilot does.

Like ArduCopter, item 0 of the mission is home (written by the vehicle, not by the uploader's
item 0, which ArduPilot overwrites), and the current item starts at 1 once a mission exists.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

__all__ = ["MissionItem", "MissionStore", "Home", "MISSION_TYPES"]

# MAV_MISSION_TYPE: 0 mission, 1 fence, 2 rally (255 ALL is only for MISSION_CLEAR_ALL).
MISSION_TYPES = (0, 1, 2)


@dataclass(frozen=True)
class MissionItem:
    """One MISSION_ITEM_INT as stored (``seq`` is its index in its list)."""

    seq: int
    frame: int
    command: int
    current: int = 0
    autocontinue: int = 1
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: int = 0
    y: int = 0
    z: float = 0.0
    mission_type: int = 0


@dataclass
class Home:
    """Home position: latitude/longitude [deg], altitude AMSL [m]; set at boot and by DO_SET_HOME.

    ``is_set`` becomes True once the estimator is ready (ArduPilot's ``home_is_set``); ``locked`` by
    DO_SET_HOME / SET_HOME_POSITION (arming then no longer moves it, as ArduCopter).
    """

    lat_deg: float
    lon_deg: float
    alt_m: float
    is_set: bool = False
    locked: bool = False


@dataclass
class MissionStore:
    """Mission, fence and rally lists of one vehicle, in memory (lost at reboot, as in SITL with no SD card)."""

    items: dict[int, list[MissionItem]] = field(default_factory=lambda: {t: [] for t in MISSION_TYPES})
    current_seq: int = 0
    #: Items AUTO has reached, oldest first; the MAVLink side drains it into MISSION_ITEM_REACHED.
    reached: list[int] = field(default_factory=list)

    def replace(self, mission_type: int, items: list[MissionItem]) -> None:
        """A completed upload: the list of ``mission_type`` becomes ``items`` (re-numbered 0..n-1)."""
        self.items[mission_type] = [replace(it, seq=i, mission_type=mission_type) for i, it in enumerate(items)]
        if mission_type == 0:
            self.current_seq = 1 if len(self.items[0]) > 1 else 0

    def clear(self, mission_type: int) -> None:
        """MISSION_CLEAR_ALL of one type (255: all types)."""
        for t in (MISSION_TYPES if mission_type == 255 else (mission_type,)):
            self.items[t] = []
        if mission_type in (0, 255):
            self.current_seq = 0

    def count(self, mission_type: int) -> int:
        return len(self.items[mission_type])

    def get(self, mission_type: int, seq: int) -> MissionItem | None:
        lst = self.items[mission_type]
        return lst[seq] if 0 <= seq < len(lst) else None

    def set_current(self, seq: int) -> bool:
        """MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT: False when ``seq`` is not in the mission."""
        if not 0 <= seq < len(self.items[0]):
            return False
        self.current_seq = seq
        return True
