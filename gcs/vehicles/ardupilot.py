"""The ArduPilot (ArduCopter) autopilot profile: what is ArduPilot's own in flying it off-board.

A :class:`~gcs.vehicles.mavlink.MavlinkSession` does the generic MAVLink flight (heartbeat,
streams, telemetry, setpoints, failsafes); everything that depends on the firmware family is
here, so that another family (PX4) is another profile:

* modes: GUIDED_NOGPS to fly in (GUIDED accepted too), LAND to land, by
  MAV_CMD_DO_SET_MODE with ArduCopter's custom mode numbers, names from
  :mod:`quadrotor.mavlink.modes`;
* parameters set for the flight and restored after it (:meth:`ArduPilotProfile.configure`):

  - GUID_OPTIONS bit 3: the SET_ATTITUDE_TARGET thrust field is thrust, not a climb rate;
  - ATC_ANGLE_BOOST = 0: the controllers divide by cos(roll) cos(pitch) themselves;
  - GUID_TIMEOUT = 0.5 s (:data:`GUID_TIMEOUT_S`): with no setpoint for that long ArduCopter
    levels the vehicle and holds its altitude (a stalled ground station must leave it level;
    the default 3 s lets the last setpoint act for 3 s);
  - FS_GCS_ENABLE = 5 (Land) with FS_GCS_TIMEOUT = 3 s (:data:`FS_GCS_TIMEOUT_S`; the firmware
    allows 2 s at least): with no HEARTBEAT from the ground station (MAV_GCS_SYSID, checked
    to be ours) for that long the vehicle lands itself.  The session must then send HEARTBEAT
    at least once a second in every phase, preflight waits included: after a longer gap
    ArduCopter refuses to arm ("Arm: GCS failsafe on") and disarms a vehicle armed on the ground;
  - ATC_RATE_FF_ENAB, by output: 0 for ``attitude`` (the angle loop then flies the
    quaternion unshaped, ``omega = ATC_ANG_*_P e``: :mod:`gcs.vehicles.output`), 1 for
    ``rates`` (the rate path is shaped and tracked; with 0 the rates become slow attitude
    increments);

  and read for the output adapters (:class:`OutputParams`): MOT_THST_HOVER (the throttle that
  holds the vehicle), ATC_ANG_RLL/PIT/YAW_P (angle gains), ATC_ACC_R/P/Y_MAX (the angle loop's
  square-root limit), ATC_RATE_R/P/Y_MAX (rate limits);
* ``actuator`` is refused before arming when AUTOPILOT_VERSION says the firmware does not take
  SET_ACTUATOR_CONTROL_TARGET (ArduCopter has no handler for it);
* the meaning of the thrust field: ``u / (m g) * MOT_THST_HOVER``, clipped to 0..1;
* landing: LAND mode, then the vehicle lands and disarms itself;
* arming refusals: the reason comes as a "PreArm:"/"Arm:" STATUSTEXT.
"""

from __future__ import annotations

import dataclasses
import math

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.errors import PreflightRefused
from gcs.vehicles.profile import OutputParams, control_lost, optional_param, refuse_untaken_actuator
from quadrotor.mavlink.modes import COPTER_MODES, copter_mode_name

__all__ = ["ArduPilotProfile", "OutputParams", "GUID_TIMEOUT_S", "FS_GCS_LAND", "FS_GCS_TIMEOUT_S",
           "angle_accel_limits"]

#: GUID_TIMEOUT for the flight [s]: a stalled link leaves the vehicle level this soon.
GUID_TIMEOUT_S = 0.5
#: FS_GCS_ENABLE for the flight: 5 = Land when the ground station's heartbeats stop.
FS_GCS_LAND = 5
#: FS_GCS_TIMEOUT for the flight [s] (ArduCopter's minimum is 2 s; heartbeats go once a second).
FS_GCS_TIMEOUT_S = 3.0
#: The ATC_RATE_FF_ENAB each output needs (actuator: not touched).
RATE_FF_FOR_OUTPUT = {"attitude": 0, "rates": 1}
_DEG = math.pi / 180.0


def angle_accel_limits(acc_max_deg_s2: tuple[float, float, float]) -> tuple[float, float, float]:
    """The square-root limits [rad/s^2] of ArduCopter's angle loop for ATC_ACC_R/P/Y_MAX [deg/s^2]:
    half of each, clamped to 40-720 deg/s^2 (roll, pitch) and 10-120 deg/s^2 (yaw); 0 (limit
    disabled) makes the loop linear (``AC_AttitudeControl::update_ang_vel_target_from_att_error``)."""
    bounds = ((40.0, 720.0), (40.0, 720.0), (10.0, 120.0))
    return tuple(0.0 if a <= 0 else min(hi, max(lo, a / 2.0)) * _DEG  # type: ignore[return-value]
                 for a, (lo, hi) in zip(acc_max_deg_s2, bounds))


class ArduPilotProfile:
    """ArduCopter's conventions (see the module docstring)."""

    name = "ArduPilot"
    control_name = "guided control"
    flight_mode = COPTER_MODES["GUIDED_NOGPS"]
    land_mode = COPTER_MODES["LAND"]
    #: Modes in which our setpoints steer the vehicle.
    control_modes = (COPTER_MODES["GUIDED_NOGPS"], COPTER_MODES["GUIDED"])
    #: Setpoints need not flow before the flight mode is asked for.
    stream_before_mode = False
    #: ArduCopter's own failsafes land (FS_GCS, GUID_TIMEOUT levels): no mode it takes by itself needs landing.
    hover_modes: tuple[int, ...] = ()
    #: A gap in our setpoints does not change ArduCopter's mode (GUID_TIMEOUT levels it in GUIDED):
    #: the next setpoint steers again.  None = no such limit.
    setpoint_loss_s: float | None = None
    #: Streams asked for the log only (message id -> Hz): none; ArduCopter's link carries enough.
    log_streams_hz: dict[int, float] = {}  # noqa: RUF012  read only

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

    def configure(self, params, firmware=None, output: str | None = None) -> OutputParams:
        """Set what the flight needs (restored afterwards by ``params``) and read what the adapters need.

        Parameters
        ----------
        params : gcs.vehicles.params.VehicleParams
            Reads, sets and remembers parameters on the vehicle.
        firmware : gcs.vehicles.firmware.Firmware or None
            What AUTOPILOT_VERSION said (None: not asked).
        output : {"attitude", "rates", "actuator"} or None
            The setpoint the flight sends; None leaves the output's own parameters to
            :meth:`configure_output` (the returned ``OutputParams.output`` is then None).

        Raises
        ------
        PreflightRefused
            A parameter the flight needs is missing, implausible or not accepted, or the output
            cannot be flown on this firmware.
        """
        if output is not None:
            self.check_output(output, firmware)   # before anything is set
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
        self._guided_timeout(params)
        self._gcs_failsafe(params)
        hover = params.get("MOT_THST_HOVER", None)
        if not 0.05 <= hover <= 0.95:
            raise PreflightRefused(f"MOT_THST_HOVER = {hover:g} is not a plausible hover throttle (0.05..0.95)")
        gains = tuple(params.get(f"ATC_ANG_{ax}_P", 4.5) for ax in ("RLL", "PIT", "YAW"))
        if not all(0.1 <= g <= 50.0 for g in gains):
            raise PreflightRefused(f"ATC_ANG_RLL/PIT/YAW_P = {gains} are not plausible angle gains (0.1..50)")
        acc = tuple(params.get(f"ATC_ACC_{ax}_MAX", d) for ax, d in (("R", 1100.0), ("P", 1100.0), ("Y", 270.0)))
        rate_max = tuple(params.get(f"ATC_RATE_{ax}_MAX", 0.0) for ax in ("R", "P", "Y"))
        if min(acc) < 0 or min(rate_max) < 0:
            raise PreflightRefused(f"ATC_ACC_R/P/Y_MAX = {acc}, ATC_RATE_R/P/Y_MAX = {rate_max}: negative limits")
        out = OutputParams(hover, gains, angle_accel_limits(acc),  # type: ignore[arg-type]
                           tuple(r * _DEG for r in rate_max))  # type: ignore[arg-type]
        return out if output is None else self.configure_output(params, output, firmware, out)

    def configure_output(self, params, output: str, firmware, out: OutputParams) -> OutputParams:
        """What ``output`` needs: refuse ``actuator`` where the firmware does not take it, set
        ATC_RATE_FF_ENAB (:data:`RATE_FF_FOR_OUTPUT`); ``out`` marked as configured for ``output``.

        Raises
        ------
        PreflightRefused
            ``actuator`` on a firmware whose AUTOPILOT_VERSION lacks the capability, or
            ATC_RATE_FF_ENAB missing or not accepted.
        """
        self.check_output(output, firmware)
        want = RATE_FF_FOR_OUTPUT.get(output)
        if want is not None:
            ff = params.get("ATC_RATE_FF_ENAB", None)
            if int(ff) != want:
                new = params.set("ATC_RATE_FF_ENAB", float(want), ff)
                if int(new) != want:
                    raise PreflightRefused(f"the vehicle did not accept ATC_RATE_FF_ENAB = {want} (the {output} "
                                           "output needs it)")
                params.said(f"ATC_RATE_FF_ENAB {int(ff)} -> {want} ({output} output: "
                            + ("the angle loop flies the target unshaped)" if want == 0 else
                               "rate targets are shaped and tracked)"))
        return dataclasses.replace(out, output=output)

    @staticmethod
    def check_output(output: str, firmware) -> None:
        """Refuse ``actuator`` where AUTOPILOT_VERSION says the firmware does not take it (unknown: flown)."""
        refuse_untaken_actuator(output, firmware, "; ArduCopter has no handler for it")

    @staticmethod
    def _guided_timeout(params) -> None:
        """GUID_TIMEOUT down to :data:`GUID_TIMEOUT_S` (never up)."""
        old = optional_param(params, "GUID_TIMEOUT")
        if old is None:
            params.event("warning", "GUID_TIMEOUT not readable: a stalled link may leave the last setpoint acting")
        elif old > GUID_TIMEOUT_S + 1e-6:
            new = params.set("GUID_TIMEOUT", GUID_TIMEOUT_S, old)
            if abs(new - GUID_TIMEOUT_S) > 1e-6:
                raise PreflightRefused(f"the vehicle did not accept GUID_TIMEOUT = {GUID_TIMEOUT_S:g} s")
            params.said(f"GUID_TIMEOUT {old:g} -> {GUID_TIMEOUT_S:g} s (a stalled link levels the vehicle)")

    @staticmethod
    def _gcs_failsafe(params) -> None:
        """FS_GCS_ENABLE = Land and FS_GCS_TIMEOUT, once the vehicle is known to listen to our heartbeats."""
        ours = params.link.source_system
        gcs_id = optional_param(params, "MAV_GCS_SYSID")
        if gcs_id is None:
            gcs_id = optional_param(params, "SYSID_MYGCS")  # before ArduPilot 4.7
        if gcs_id is not None and int(gcs_id) != ours:
            params.event("warning", f"MAV_GCS_SYSID is {int(gcs_id)}, not us ({ours}): the GCS failsafe would follow "
                                    "that ground station's heartbeats, not ours; FS_GCS_ENABLE left as it is")
            return
        enable = optional_param(params, "FS_GCS_ENABLE")
        if enable is None:
            params.event("warning", "FS_GCS_ENABLE not readable: a dead ground station is not landed by the vehicle")
            return
        if int(enable) != FS_GCS_LAND:
            new = params.set("FS_GCS_ENABLE", float(FS_GCS_LAND), enable)
            if int(new) != FS_GCS_LAND:
                raise PreflightRefused(f"the vehicle did not accept FS_GCS_ENABLE = {FS_GCS_LAND} (Land)")
            params.said(f"FS_GCS_ENABLE {int(enable)} -> {FS_GCS_LAND} (no heartbeat from us: land)")
        timeout = optional_param(params, "FS_GCS_TIMEOUT")
        if timeout is not None and timeout > FS_GCS_TIMEOUT_S + 1e-6:
            new = params.set("FS_GCS_TIMEOUT", FS_GCS_TIMEOUT_S, timeout)
            if abs(new - FS_GCS_TIMEOUT_S) > 1e-6:
                raise PreflightRefused(f"the vehicle did not accept FS_GCS_TIMEOUT = {FS_GCS_TIMEOUT_S:g} s")
            params.said(f"FS_GCS_TIMEOUT {timeout:g} -> {FS_GCS_TIMEOUT_S:g} s")

    control_lost = control_lost

    @staticmethod
    def spool_up_s(params, firmware) -> float:
        """Seconds from "armed" until the motors deliver the commanded thrust: ArduCopter's fixed
        2 s arming delay (ARMING_DELAY_SEC in ArduCopter/motors.cpp) plus MOT_SPOOL_TIME; 0 for
        the built-in SITL, which applies thrust at once."""
        if firmware is not None and firmware.builtin_sitl:
            return 0.0
        spool = params.get("MOT_SPOOL_TIME", 0.5)
        return 2.0 + (spool if spool is not None and 0.0 <= spool <= 2.0 else 0.5)

    @staticmethod
    def arming_refusal(status, result: int) -> str:
        """The reason of a refused arming: the last "Arm"/"PreArm" STATUSTEXT, else the MAV_RESULT."""
        texts = [t for t in status.statustext if "arm" in t.lower()]
        return texts[-1] if texts else f"MAV_RESULT {result}"
