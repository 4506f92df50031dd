"""The ArduPilot (ArduCopter) autopilot profile: what is ArduPilot's own in flying it off-board.

A :class:`~gcs.vehicles.mavlink.MavlinkSession` does the generic MAVLink flight (heartbeat,
streams, telemetry, setpoints, failsafes); everything that depends on the firmware family is
here, so that another family (PX4) is another profile:

* modes: GUIDED_NOGPS to fly in (GUIDED accepted too), LAND to land, by
  MAV_CMD_DO_SET_MODE with ArduCopter's custom mode numbers, names from
  :mod:`quadrotor.mavlink.modes`;
* parameters set for the flight and restored after it: GUID_OPTIONS bit 3 (the
  SET_ATTITUDE_TARGET thrust field is thrust, not a climb rate) and ATC_ANGLE_BOOST = 0
  (the controllers divide by cos(roll) cos(pitch) themselves); read: MOT_THST_HOVER (the
  throttle that holds the vehicle) and ATC_ANG_RLL/PIT/YAW_P (the angle gains);
* the meaning of the thrust field: ``u / (m g) * MOT_THST_HOVER``, clipped to 0..1;
* landing: LAND mode, then the vehicle lands and disarms itself;
* arming refusals: the reason comes as a "PreArm:"/"Arm:" STATUSTEXT.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.errors import PreflightRefused
from quadrotor.mavlink.modes import COPTER_MODES, copter_mode_name

__all__ = ["ArduPilotProfile", "OutputParams"]


@dataclass(frozen=True)
class OutputParams:
    """What the output adapter needs from the autopilot: hover throttle and angle gains [1/s]."""

    hover_throttle: float
    angle_gain_1_s: tuple[float, float, float]


class ArduPilotProfile:
    """ArduCopter's conventions (see the module docstring)."""

    name = "ArduPilot"
    control_name = "guided control"
    flight_mode = COPTER_MODES["GUIDED_NOGPS"]
    land_mode = COPTER_MODES["LAND"]
    #: Modes in which our setpoints steer the vehicle.
    control_modes = (COPTER_MODES["GUIDED_NOGPS"], COPTER_MODES["GUIDED"])

    @staticmethod
    def mode_name(custom_mode: int) -> str:
        return copter_mode_name(custom_mode)

    def set_mode_message(self, link, custom_mode: int):
        """MAV_CMD_DO_SET_MODE for an ArduCopter custom mode (sent without waiting)."""
        return link.mav.command_long_encode(link.target_system, link.target_component, mavlink.MAV_CMD_DO_SET_MODE, 0,
                                            mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode, 0, 0, 0, 0, 0)

    def request_mode(self, link, custom_mode: int, *, on_message, timeout_s: float = 3.0, retries: int = 2) -> int:
        """MAV_CMD_DO_SET_MODE, waiting for its acknowledgement; the MAV_RESULT."""
        return link.command_long(mavlink.MAV_CMD_DO_SET_MODE, [mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode],
                                 timeout_s=timeout_s, retries=retries, on_message=on_message)

    def configure(self, params) -> OutputParams:
        """Set what the flight needs (restored afterwards by ``params``) and read what the adapters need.

        Parameters
        ----------
        params : gcs.vehicles.params.VehicleParams
            Reads, sets and remembers parameters on the vehicle.
        """
        guid = params.get("GUID_OPTIONS", 0.0)
        if not int(guid) & 8:
            new = params.set("GUID_OPTIONS", float(int(guid) | 8), guid)
            if not int(new) & 8:
                raise PreflightRefused("the vehicle did not accept GUID_OPTIONS bit 3 (thrust as thrust)")
            params.said(f"GUID_OPTIONS {int(guid)} -> {int(new)} (thrust field is thrust)")
        boost = params.get("ATC_ANGLE_BOOST", None)
        if boost:
            new = params.set("ATC_ANGLE_BOOST", 0.0, boost)
            if new:
                raise PreflightRefused("the vehicle did not accept ATC_ANGLE_BOOST = 0 (thrust tilt compensation "
                                       "is done by the controller)")
            params.said("ATC_ANGLE_BOOST 1 -> 0 (the controller compensates tilt)")
        hover = params.get("MOT_THST_HOVER", None)
        if not 0.05 <= hover <= 0.95:
            raise PreflightRefused(f"MOT_THST_HOVER = {hover:g} is not a plausible hover throttle (0.05..0.95)")
        gains = tuple(params.get(f"ATC_ANG_{ax}_P", 4.5) for ax in ("RLL", "PIT", "YAW"))
        if not all(0.1 <= g <= 50.0 for g in gains):
            raise PreflightRefused(f"ATC_ANG_RLL/PIT/YAW_P = {gains} are not plausible angle gains (0.1..50)")
        return OutputParams(hover, gains)  # type: ignore[arg-type]

    def control_lost(self, status) -> str | None:
        """Why the vehicle no longer takes our setpoints, or None."""
        if not status.armed:
            return "disarmed"
        if status.custom_mode not in self.control_modes:
            return f"mode {self.mode_name(status.custom_mode)}"
        return None

    @staticmethod
    def arming_refusal(statustexts, result: int) -> str:
        """The reason of a refused arming: the last "Arm"/"PreArm" STATUSTEXT, else the MAV_RESULT."""
        texts = [t for t in statustexts if "arm" in t.lower()]
        return texts[-1] if texts else f"MAV_RESULT {result}"
