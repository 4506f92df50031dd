"""Telemetry stream scheduling in simulated time (MAV_CMD_SET_MESSAGE_INTERVAL, REQUEST_DATA_STREAM).

Like ArduCopter, nothing but HEARTBEAT (1 Hz) is sent until a stream is
requested.  A request at time ``t`` for interval ``T`` sends the message at
``t + T, t + 2T, ...`` (checked every inner-loop tick, so the fastest rate is
the loop rate); repeating a request for the interval already set keeps the
schedule (MAVProxy repeats its REQUEST_DATA_STREAM every 15 s).  In lockstep
with a 10 ms control period, an interval of 10 ms therefore gives exactly one
message per step, at its end.  The server keeps one scheduler per link.

REQUEST_DATA_STREAM groups, as ArduCopter's (``libraries/GCS_MAVLink/GCS_MAVLink_Parameters.cpp``;
what this SITL has of each)::

    1 RAW_SENSORS      RAW_IMU, SCALED_IMU2, SCALED_PRESSURE
    2 EXTENDED_STATUS  SYS_STATUS, POWER_STATUS, MEMINFO, MISSION_CURRENT, GPS_RAW_INT,
                       NAV_CONTROLLER_OUTPUT
    3 RC_CHANNELS      SERVO_OUTPUT_RAW, RC_CHANNELS
    6 POSITION         GLOBAL_POSITION_INT, LOCAL_POSITION_NED
    10 EXTRA1          ATTITUDE, AHRS2
    11 EXTRA2          VFR_HUD
    12 EXTRA3          AHRS, DISTANCE_SENSOR, SYSTEM_TIME, BATTERY_STATUS, EKF_STATUS_REPORT, VIBRATION
    0 ALL              all of the above

ALTITUDE, ATTITUDE_QUATERNION, ATTITUDE_TARGET, EXTENDED_SYS_STATE, HOME_POSITION and
GPS_GLOBAL_ORIGIN are in no group (SET_MESSAGE_INTERVAL / REQUEST_MESSAGE only; ArduPilot sends
EXTENDED_SYS_STATE with SYS_STATUS: so does this SITL, in EXTENDED_STATUS).
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sitl.copter.telemetry import BUILDERS

__all__ = ["StreamScheduler", "STREAM_GROUPS", "SUPPORTED_MESSAGES", "DEFAULT_INTERVAL_US"]

M = mavlink
STREAM_GROUPS: dict[int, tuple[int, ...]] = {
    M.MAV_DATA_STREAM_RAW_SENSORS: (M.MAVLINK_MSG_ID_RAW_IMU, M.MAVLINK_MSG_ID_SCALED_IMU2,
                                    M.MAVLINK_MSG_ID_SCALED_PRESSURE),
    M.MAV_DATA_STREAM_EXTENDED_STATUS: (M.MAVLINK_MSG_ID_SYS_STATUS, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                                        M.MAVLINK_MSG_ID_POWER_STATUS, M.MAVLINK_MSG_ID_MEMINFO,
                                        M.MAVLINK_MSG_ID_MISSION_CURRENT, M.MAVLINK_MSG_ID_GPS_RAW_INT,
                                        M.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT),
    M.MAV_DATA_STREAM_RC_CHANNELS: (M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, M.MAVLINK_MSG_ID_RC_CHANNELS),
    M.MAV_DATA_STREAM_POSITION: (M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED),
    M.MAV_DATA_STREAM_EXTRA1: (M.MAVLINK_MSG_ID_ATTITUDE, M.MAVLINK_MSG_ID_AHRS2),
    M.MAV_DATA_STREAM_EXTRA2: (M.MAVLINK_MSG_ID_VFR_HUD,),
    M.MAV_DATA_STREAM_EXTRA3: (M.MAVLINK_MSG_ID_AHRS, M.MAVLINK_MSG_ID_DISTANCE_SENSOR, M.MAVLINK_MSG_ID_SYSTEM_TIME,
                               M.MAVLINK_MSG_ID_BATTERY_STATUS, M.MAVLINK_MSG_ID_EKF_STATUS_REPORT,
                               M.MAVLINK_MSG_ID_VIBRATION),
}
SUPPORTED_MESSAGES = frozenset(BUILDERS)
DEFAULT_INTERVAL_US = 250_000  # SET_MESSAGE_INTERVAL param2 = 0: "default rate" = 4 Hz
HEARTBEAT_INTERVAL_US = 1_000_000


class StreamScheduler:
    """Per-message intervals and due times (integer nanoseconds)."""

    def __init__(self) -> None:
        self._interval_ns: dict[int, int] = {M.MAVLINK_MSG_ID_HEARTBEAT: HEARTBEAT_INTERVAL_US * 1000}
        self._due_ns: dict[int, int] = {M.MAVLINK_MSG_ID_HEARTBEAT: HEARTBEAT_INTERVAL_US * 1000}
        self._order: list[int] = [M.MAVLINK_MSG_ID_HEARTBEAT]

    def set_interval_us(self, msg_id: int, interval_us: float, now_ns: int) -> bool:
        """Set the interval of ``msg_id``: > 0 us, 0 = default rate, -1 (any < 0) = stop.

        Returns False for messages this SITL cannot stream and for a NaN or
        infinite interval.  The interval already set keeps its due time.
        """
        if msg_id not in SUPPORTED_MESSAGES or not math.isfinite(interval_us):
            return False
        if interval_us < 0:
            self._interval_ns.pop(msg_id, None)
            self._due_ns.pop(msg_id, None)
        else:
            iv = int(interval_us * 1000) if interval_us > 0 else (
                HEARTBEAT_INTERVAL_US * 1000 if msg_id == M.MAVLINK_MSG_ID_HEARTBEAT else DEFAULT_INTERVAL_US * 1000)
            iv = max(iv, 1)
            if self._interval_ns.get(msg_id) == iv:
                return True
            self._interval_ns[msg_id] = iv
            self._due_ns[msg_id] = now_ns + iv
        self._order = sorted(self._interval_ns)
        return True

    def interval_us(self, msg_id: int) -> int:
        """Current interval [us]; -1 = not streamed, 0 for unsupported messages."""
        if msg_id not in SUPPORTED_MESSAGES:
            return 0
        iv = self._interval_ns.get(msg_id)
        return -1 if iv is None else iv // 1000

    def set_group_rate(self, stream_id: int, rate_hz: float, now_ns: int) -> bool:
        """REQUEST_DATA_STREAM: every message of the group at ``rate_hz`` (0 = stop); False if unknown or not finite."""
        if not math.isfinite(rate_hz):
            return False
        if stream_id == M.MAV_DATA_STREAM_ALL:
            groups = list(STREAM_GROUPS)
        elif stream_id in STREAM_GROUPS:
            groups = [stream_id]
        else:
            return False
        for g in groups:
            for msg_id in STREAM_GROUPS[g]:
                self.set_interval_us(msg_id, 1e6 / rate_hz if rate_hz > 0 else -1, now_ns)
        return True

    def due(self, now_ns: int) -> list[int]:
        """Messages due at ``now_ns`` (ascending id); advances their due times."""
        out = []
        due = self._due_ns
        for msg_id in self._order:
            t = due[msg_id]
            if now_ns >= t:
                out.append(msg_id)
                iv = self._interval_ns[msg_id]
                t += iv
                due[msg_id] = t if t > now_ns else now_ns + iv
        return out
