"""The autopilot families flown, by HEARTBEAT ``autopilot``: :func:`profile_for`."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.errors import PreflightRefused
from gcs.vehicles.ardupilot import ArduPilotProfile
from gcs.vehicles.px4 import Px4Profile

__all__ = ["profile_for", "FAMILIES"]

#: MAV_AUTOPILOT -> family name.
FAMILIES = {mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA: "ArduPilot", mavlink.MAV_AUTOPILOT_PX4: "PX4"}


def profile_for(autopilot: int, *, events=None) -> ArduPilotProfile | Px4Profile:
    """The profile of a HEARTBEAT ``autopilot`` (MAV_AUTOPILOT).

    Parameters
    ----------
    autopilot : int
        3 ArduPilot, 12 PX4.
    events : gcs.vehicles.px4_events.EventMetadata or None
        PX4's event metadata (arming refusals in words).

    Raises
    ------
    PreflightRefused
        An autopilot family this ground station does not know how to fly.
    """
    if autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA:
        return ArduPilotProfile()
    if autopilot == mavlink.MAV_AUTOPILOT_PX4:
        return Px4Profile(events)
    raise PreflightRefused(f"autopilot {autopilot} (HEARTBEAT MAV_AUTOPILOT) is neither ArduPilot (3) nor PX4 (12): "
                           "its modes and parameters are not known; not flown")
