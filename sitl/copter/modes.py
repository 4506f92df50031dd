"""The ArduCopter flight modes this autopilot flies (numbers from :data:`quadrotor.mavlink.modes.COPTER_MODES`).

STABILIZE has no RC here, so its throttle is zero: it levels the vehicle and idles on the ground
(and falls if selected in flight, like a real copter without RC).
"""

from __future__ import annotations

from enum import IntEnum

from quadrotor.mavlink.modes import COPTER_MODES

__all__ = ["Mode", "GUIDED_MODES", "ARMABLE_MODES"]


class Mode(IntEnum):
    """The emulated custom modes."""

    STABILIZE = COPTER_MODES["STABILIZE"]
    GUIDED = COPTER_MODES["GUIDED"]
    LAND = COPTER_MODES["LAND"]
    GUIDED_NOGPS = COPTER_MODES["GUIDED_NOGPS"]


GUIDED_MODES = (Mode.GUIDED, Mode.GUIDED_NOGPS)
ARMABLE_MODES = (Mode.STABILIZE, Mode.GUIDED, Mode.GUIDED_NOGPS)
