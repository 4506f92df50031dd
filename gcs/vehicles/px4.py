"""The PX4 autopilot profile: what is PX4's own in flying it off-board (OFFBOARD mode).

The generic MAVLink flight is :class:`~gcs.vehicles.mavlink.MavlinkSession`'s; this profile
holds PX4's conventions, as :mod:`gcs.vehicles.ardupilot` holds ArduCopter's (nothing of one
is sent to the other):

* modes (:mod:`gcs.vehicles.px4_modes`): OFFBOARD to fly in, entered by MAV_CMD_DO_SET_MODE
  (1, main 6) only after setpoints have streamed (the preflight streams level idle setpoints
  before it asks for the mode: PX4 refuses OFFBOARD without an offboard signal above 2 Hz);
  landing by MAV_CMD_NAV_LAND (AUTO.LAND, then "Landing detected" and PX4 disarms itself
  after COM_DISARM_LAND); the landed state from EXTENDED_SYS_STATE;
* parameters, with their own types (INT32 ones are sent bytewise, as PX4 encodes them, see
  :func:`gcs.link.mavlink.encode_param`), set for the flight and restored after it:

  - COM_OBL_RC_ACT = 4 (Land): when our setpoints stop for COM_OF_LOSS_T the vehicle lands;
  - COM_OF_LOSS_T = 0.5 s (:data:`OFFBOARD_LOSS_S`; never raised): how long the last attitude
    setpoint may hold before that failsafe;
  - COM_DISARM_LAND = 2 s where it was disabled (<= 0): a landed vehicle disarms itself;

  and read for the output adapters: MPC_THR_HOVER (the thrust that holds the vehicle),
  MC_ROLL_P/MC_PITCH_P/MC_YAW_P (the angle loop is linear: ``omega = P e``, no square-root
  limit), MC_ROLLRATE_MAX/MC_PITCHRATE_MAX/MC_YAWRATE_MAX (rate limits, deg/s), and where PX4
  simulates the vehicle itself (SIH running, not merely built in) its drag SIH_KDV / SIH_MASS for the
  disturbance observer;
* where PX4 simulates the vehicle itself (SIH running: :meth:`Px4Profile.simulates_itself`), its
  horizontal velocity estimate is not fused
  (:data:`SIH_HORIZONTAL_VELOCITY_STD_M_S`): with SIH's sensor noise (accelerometer 0.5/1.7/1.4
  m/s^2, GPS 0.2 m) EKF2's LOCAL_POSITION_NED velocity lags its own position by about 1 s on the
  circle (measured: 0.10 m/s of radial velocity on a 0.31 m/s circle, and 0.2-0.3 m/s RMS from SIH's
  true velocity against 0.1 m/s for the derivative of its position).  Fused, the mismatch became
  a false disturbance and the vehicle flew the circle 0.10-0.14 m too wide; our estimator then
  takes the velocity from the positions;
* SET_ATTITUDE_TARGET: type_mask 7 makes an attitude setpoint (the rates are not a
  feed-forward: with them PX4 publishes a separate rates setpoint), type_mask 128 a rates
  setpoint; the thrust field is the normalised collective thrust, ``u / (m g) * MPC_THR_HOVER``;
* ``actuator`` is refused where AUTOPILOT_VERSION lacks the capability (PX4 main has no
  SET_ACTUATOR_CONTROL_TARGET handler since its control allocation);
* arming refusals: the specific reason comes as an EVENT (:mod:`gcs.vehicles.px4_events`),
  decoded with the firmware's event metadata when it can be had.
"""

from __future__ import annotations

import dataclasses
import math

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.errors import PreflightRefused
from gcs.vehicles.profile import OutputParams, control_lost, optional_param, refuse_untaken_actuator
from gcs.vehicles.px4_modes import HOLD, LAND, OFFBOARD, px4_mode_name, split_mode

__all__ = ["Px4Profile", "OFFBOARD_LOSS_S", "OBL_LAND"]

#: COM_OF_LOSS_T for the flight [s]: a stalled ground station's last setpoint holds this long at most.
OFFBOARD_LOSS_S = 0.5
#: COM_OBL_RC_ACT for the flight: 4 = Land mode.
OBL_LAND = 4
_DEG = math.pi / 180.0


class Px4Profile:
    """PX4's conventions (see the module docstring).

    Parameters
    ----------
    events : gcs.vehicles.px4_events.EventMetadata or None
        The firmware's event metadata, to put arming refusals in words (None: reported as events).
    """

    name = "PX4"
    control_name = "offboard control"
    #: The parameter behind :attr:`setpoint_loss_s` (for messages).
    setpoint_loss_param = "COM_OF_LOSS_T"
    flight_mode = OFFBOARD
    land_mode = LAND
    control_modes = (OFFBOARD,)
    #: The setpoint stream must run before the flight mode is asked for.
    stream_before_mode = True
    #: A vehicle that left our control for one of these is hovering by itself (a failsafe): land it.
    hover_modes = (HOLD,)
    #: Streams asked for the log only (message id -> Hz): ATTITUDE_TARGET, which PX4 fills with its rate
    #: setpoint (what its inner loop was asked).
    log_streams_hz = {mavlink.MAVLINK_MSG_ID_ATTITUDE_TARGET: 50.0,  # noqa: RUF012  read only
                      mavlink.MAVLINK_MSG_ID_HIL_STATE_QUATERNION: 50.0}

    #: The horizontal velocity noise [m/s] assumed where SIH simulates the vehicle: not fused in effect.
    SIH_HORIZONTAL_VELOCITY_STD_M_S = 10.0

    def __init__(self, events=None) -> None:
        self.events = events
        #: COM_OF_LOSS_T in effect for the flight [s], once :meth:`configure` has set it: a gap in our
        #: setpoints longer than this has put PX4 in its offboard-loss failsafe (Land), and PX4 would
        #: hand the vehicle back to the first setpoint after it; we do not take it back.
        self.setpoint_loss_s: float | None = None

    @staticmethod
    def mode_name(custom_mode: int) -> str:
        return px4_mode_name(custom_mode)

    def set_mode_message(self, link, custom_mode: int):
        """The command that asks for ``custom_mode`` (NAV_LAND for Land), sent without waiting."""
        command, params = self._mode_command(custom_mode)
        p = params + [0.0] * (7 - len(params))
        return link.mav.command_long_encode(link.target_system, link.target_component, command, 0, *p)

    def request_mode(self, link, custom_mode: int, *, on_message, timeout_s: float = 3.0, retries: int = 2) -> int:
        """Ask for ``custom_mode`` and wait for the acknowledgement; the MAV_RESULT."""
        command, params = self._mode_command(custom_mode)
        return link.command_long(command, params, timeout_s=timeout_s, retries=retries, on_message=on_message)

    @staticmethod
    def _mode_command(custom_mode: int) -> tuple[int, list[float]]:
        if custom_mode == LAND:
            # Commander switches to AUTO.LAND, which lands where the vehicle is (the position fields are
            # not used); zeros, since nothing non-finite goes on the wire.
            return mavlink.MAV_CMD_NAV_LAND, [0.0] * 7
        main, sub = split_mode(custom_mode)
        return mavlink.MAV_CMD_DO_SET_MODE, [float(mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(main), float(sub)]

    def configure(self, params, firmware=None, output: str | None = None) -> OutputParams:
        """Set what the flight needs (restored afterwards by ``params``) and read what the adapters need.

        Raises
        ------
        PreflightRefused
            A parameter the flight needs is missing, implausible or not accepted, or the output
            cannot be flown on this firmware.
        """
        if output is not None:
            self.check_output(output, firmware)
        self.setpoint_loss_s = self._offboard_loss(params)
        hover = params.get("MPC_THR_HOVER", None)
        if not 0.05 <= hover <= 0.95:
            raise PreflightRefused(f"MPC_THR_HOVER = {hover:g} is not a plausible hover thrust (0.05..0.95)")
        gains = tuple(params.get(f"MC_{ax}_P", d) for ax, d in (("ROLL", 6.5), ("PITCH", 6.5), ("YAW", 2.8)))
        if not all(0.1 <= g <= 50.0 for g in gains):
            raise PreflightRefused(f"MC_ROLL_P/MC_PITCH_P/MC_YAW_P = {gains} are not plausible angle gains (0.1..50)")
        rate_max = tuple(params.get(f"MC_{ax}RATE_MAX", d) for ax, d in (("ROLL", 220.0), ("PITCH", 220.0),
                                                                          ("YAW", 200.0)))
        if min(rate_max) < 0:
            raise PreflightRefused(f"MC_ROLLRATE_MAX/MC_PITCHRATE_MAX/MC_YAWRATE_MAX = {rate_max}: negative limits")
        simulated = self.simulates_itself(params)
        out = OutputParams(hover, gains, (0.0, 0.0, 0.0), tuple(r * _DEG for r in rate_max),  # type: ignore[arg-type]
                           drag_1_s=self.simulated_drag(params) if simulated else None,
                           horizontal_velocity_std_m_s=self.SIH_HORIZONTAL_VELOCITY_STD_M_S if simulated else None)
        if simulated:
            params.said("horizontal velocity from the positions (SIH: EKF2's velocity lags its position)")
        return out if output is None else self.configure_output(params, output, firmware, out)

    @staticmethod
    def simulates_itself(params) -> bool:
        """Whether PX4 simulates the vehicle it flies (SIH): the simulator's parameters exist (SIH_MASS)
        *and* it runs, on a flight controller (SYS_HITL = 2) or in SITL (the simulated GPS,
        SENS_EN_GPSSIM = 1, as PX4's sihsim airframes set it).  A Pixhawk whose firmware merely has
        the SIH module built in (SIH_MASS exists, SYS_HITL 0, no simulated GPS) is a real vehicle."""
        if optional_param(params, "SIH_MASS") is None:
            return False
        return optional_param(params, "SYS_HITL") == 2 or optional_param(params, "SENS_EN_GPSSIM") == 1

    @staticmethod
    def simulated_drag(params) -> float | None:
        """SIH_KDV / SIH_MASS [1/s] of a vehicle PX4 simulates (:meth:`simulates_itself`): its linear
        drag per unit mass, the disturbance observer's drag model.  None for implausible values."""
        kdv = optional_param(params, "SIH_KDV")
        mass = optional_param(params, "SIH_MASS") if kdv is not None else None
        if kdv is None or mass is None or not (0.0 <= kdv <= 100.0 and 0.01 <= mass <= 1000.0):
            return None
        drag = kdv / mass
        params.said(f"drag {drag:.3g} 1/s from SIH_KDV / SIH_MASS (PX4 simulates this vehicle)")
        return drag

    def configure_output(self, params, output: str, firmware, out: OutputParams) -> OutputParams:
        """What ``output`` needs: PX4 needs no parameter per output; ``actuator`` refused where not taken."""
        self.check_output(output, firmware)
        return dataclasses.replace(out, output=output)

    @staticmethod
    def check_output(output: str, firmware) -> None:
        refuse_untaken_actuator(output, firmware)

    @staticmethod
    def _offboard_loss(params) -> float:
        """COM_OBL_RC_ACT = Land, COM_OF_LOSS_T down to :data:`OFFBOARD_LOSS_S`, COM_DISARM_LAND on;
        the COM_OF_LOSS_T in effect [s]."""
        act = params.get("COM_OBL_RC_ACT", None)
        if int(act) != OBL_LAND:
            new = params.set("COM_OBL_RC_ACT", float(OBL_LAND), act)
            if int(new) != OBL_LAND:
                raise PreflightRefused(f"the vehicle did not accept COM_OBL_RC_ACT = {OBL_LAND} (Land when the "
                                       "offboard setpoints stop)")
            params.said(f"COM_OBL_RC_ACT {int(act)} -> {OBL_LAND} (offboard lost: land)")
        loss = params.get("COM_OF_LOSS_T", None)
        if loss > OFFBOARD_LOSS_S + 1e-6:
            new = params.set("COM_OF_LOSS_T", OFFBOARD_LOSS_S, loss)
            if abs(new - OFFBOARD_LOSS_S) > 1e-6:
                raise PreflightRefused(f"the vehicle did not accept COM_OF_LOSS_T = {OFFBOARD_LOSS_S:g} s")
            params.said(f"COM_OF_LOSS_T {loss:g} -> {OFFBOARD_LOSS_S:g} s (a stalled link lands the vehicle)")
        disarm = optional_param(params, "COM_DISARM_LAND")
        if disarm is not None and disarm <= 0:
            new = params.set("COM_DISARM_LAND", 2.0, disarm)
            if new <= 0:
                raise PreflightRefused("the vehicle did not accept COM_DISARM_LAND = 2 s (disarm once landed)")
            params.said(f"COM_DISARM_LAND {disarm:g} -> 2 s (a landed vehicle disarms itself)")
        return min(float(loss), OFFBOARD_LOSS_S)

    control_lost = control_lost

    @staticmethod
    def spool_up_s(params, firmware) -> float:
        """COM_SPOOLUP_TIME: PX4 ramps its motors up for that long after arming (default 1 s)."""
        spool = optional_param(params, "COM_SPOOLUP_TIME")
        return spool if spool is not None and 0.0 <= spool <= 30.0 else 1.0

    def arming_refusal(self, status, result: int) -> str:
        """The reason of a refused arming: the EVENTs that came with it (in words with the metadata), else
        the last arming STATUSTEXT, else the MAV_RESULT."""
        events = list(status.events)
        if events:
            if self.events is None:
                ids = ", ".join(f"{e.component}:{e.sub_id}" for e in events[-3:])
                return (f"the reason came as PX4 event(s) {ids}; no event metadata to put it in words "
                        "(set GCS_PX4_EVENTS to the firmware's all_events.json.xz)")
            texts = [self.events.describe(e) for e in events]
            seen = list(dict.fromkeys(t for t in texts if t))
            return "; ".join(seen[-3:])
        texts = [t for t in status.statustext if "arm" in t.lower()]
        return texts[-1] if texts else f"MAV_RESULT {result}"
