"""The ArduCopter flight modes this autopilot flies (numbers from :data:`quadrotor.mavlink.modes.COPTER_MODES`).

The navigation modes (ALT_HOLD, LOITER, POSHOLD, BRAKE, RTL, AUTO) are :mod:`sitl.copter.navigation`.

STABILIZE has no RC here, so its throttle is zero: it levels the vehicle and idles on the ground
(and falls if selected in flight, like a real copter without RC).
"""

from __future__ import annotations

from enum import IntEnum

from quadrotor.mavlink.modes import COPTER_MODES

__all__ = ["Mode", "GUIDED_MODES", "ARMABLE_MODES", "GUIDED_ENABLED_MODES"]


class Mode(IntEnum):
    """The emulated custom modes."""

    STABILIZE = COPTER_MODES["STABILIZE"]
    ALT_HOLD = COPTER_MODES["ALT_HOLD"]
    AUTO = COPTER_MODES["AUTO"]
    GUIDED = COPTER_MODES["GUIDED"]
    LOITER = COPTER_MODES["LOITER"]
    RTL = COPTER_MODES["RTL"]
    LAND = COPTER_MODES["LAND"]
    POSHOLD = COPTER_MODES["POSHOLD"]
    BRAKE = COPTER_MODES["BRAKE"]
    GUIDED_NOGPS = COPTER_MODES["GUIDED_NOGPS"]


GUIDED_MODES = (Mode.GUIDED, Mode.GUIDED_NOGPS)
#: ArduCopter arms in these (not in AUTO, RTL, LAND, BRAKE).
ARMABLE_MODES = (Mode.STABILIZE, Mode.ALT_HOLD, Mode.LOITER, Mode.POSHOLD, Mode.GUIDED, Mode.GUIDED_NOGPS)
#: HEARTBEAT base_mode has GUIDED_ENABLED in these (ArduCopter's GCS_MAVLINK_Copter::base_mode).
GUIDED_ENABLED_MODES = (Mode.AUTO, Mode.GUIDED, Mode.LOITER, Mode.RTL, Mode.POSHOLD, Mode.BRAKE)
