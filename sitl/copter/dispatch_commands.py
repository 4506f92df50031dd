"""COMMAND_LONG / COMMAND_INT of the emulated ArduCopter (a part of :class:`~sitl.copter.dispatch.Dispatcher`).

=====================================  ==========================================================
navigation commands of h2's module     :mod:`sitl.copter.dispatch_nav` ``NAV_COMMANDS`` (its result)
DO_SET_MODE (176)                      custom mode (``Autopilot.set_mode``)
NAV_LAND (21)                          LAND (unless the navigation module takes it)
COMPONENT_ARM_DISARM (400)             arm / disarm (21196: forced)
SET/GET_MESSAGE_INTERVAL (511/510)     this link's streams
REQUEST_MESSAGE (512)                  the message now (ACK first, as ArduPilot); FAILED if not had
REQUEST_AUTOPILOT_CAPABILITIES (520)   AUTOPILOT_VERSION
GET_HOME_POSITION (410)                HOME_POSITION + GPS_GLOBAL_ORIGIN, then ACK; FAILED before home
DO_SET_HOME (179)                      param1 1 (or lat = lon = 0): current position; 0: the location
                                       (COMMAND_LONG: param5/6 deg, param7 AMSL; COMMAND_INT: x/y degE7,
                                       frame GLOBAL(_INT) or GLOBAL_RELATIVE_ALT(_INT)); locks home
DO_SET_MISSION_CURRENT (224)           current mission item (FAILED if not in the mission)
anything else                          UNSUPPORTED
=====================================  ==========================================================

Until h2's ``dispatch_nav`` exists the navigation sets are empty (import guarded).
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sitl.copter.autopilot import FORCE_MAGIC
from sitl.copter.telemetry import autopilot_version, build
from sitl.copter.telemetry_nav import current_location, home_position, set_home

try:
    from sitl.copter import dispatch_nav
    NAV_COMMANDS: frozenset[int] = frozenset(dispatch_nav.NAV_COMMANDS)
    NAV_MESSAGES: frozenset[str] = frozenset(dispatch_nav.NAV_MESSAGES)
except ImportError:  # h2's navigation module not written yet: no navigation commands
    dispatch_nav = None  # type: ignore[assignment]
    NAV_COMMANDS = frozenset()
    NAV_MESSAGES = frozenset()

__all__ = ["CommandsMixin", "NAV_COMMANDS", "NAV_MESSAGES", "nav_capabilities"]

M = mavlink
# How many leading parameters each handled command uses (all must be finite).
_COMMAND_PARAMS = {M.MAV_CMD_DO_SET_MODE: 2, M.MAV_CMD_COMPONENT_ARM_DISARM: 2, M.MAV_CMD_SET_MESSAGE_INTERVAL: 2,
                   M.MAV_CMD_GET_MESSAGE_INTERVAL: 1, M.MAV_CMD_REQUEST_MESSAGE: 1, M.MAV_CMD_DO_SET_HOME: 1,
                   M.MAV_CMD_DO_SET_MISSION_CURRENT: 1}
_ACCEPTED, _DENIED, _FAILED, _UNSUPPORTED = (M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_DENIED, M.MAV_RESULT_FAILED,
                                            M.MAV_RESULT_UNSUPPORTED)


def nav_capabilities() -> int:
    """AUTOPILOT_VERSION bits of the position targets the navigation module takes."""
    bits = 0
    if "SET_POSITION_TARGET_LOCAL_NED" in NAV_MESSAGES:
        bits |= M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    if "SET_POSITION_TARGET_GLOBAL_INT" in NAV_MESSAGES:
        bits |= M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    return bits


class CommandsMixin:
    """The command handlers of :class:`~sitl.copter.dispatch.Dispatcher` (which provides the attributes used)."""

    def _ack(self, msg, command: int, result: int, replies) -> None:
        replies.append(M.MAVLink_command_ack_message(command, result, 0, 0, msg.get_srcSystem(),
                                                     msg.get_srcComponent()))

    def _command_long(self, msg, replies) -> None:
        p = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
        self._command(msg, int(msg.command), p, None, replies)

    def _command_int(self, msg, replies) -> None:
        p = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z)
        self._command(msg, int(msg.command), p, int(msg.frame), replies)

    def _command(self, msg, cmd: int, p, frame: int | None, replies) -> None:
        now = self._now
        if cmd in NAV_COMMANDS:
            result, _reason = dispatch_nav.nav_command(self.sim, cmd, tuple(float(v) for v in p), frame, now)
            self._ack(msg, cmd, int(result), replies)
            return
        needed = _COMMAND_PARAMS.get(cmd, 0)
        if needed and self._non_finite(*p[:needed]):
            self._ack(msg, cmd, _DENIED, replies)
            return
        handler = self._commands.get(cmd)
        result = handler(msg, p, frame, replies) if handler is not None else _UNSUPPORTED
        if result is not None:
            self._ack(msg, cmd, result, replies)

    def _command_table(self) -> dict:
        """Command id -> handler ``(msg, params, frame, replies) -> MAV_RESULT or None (ACK sent already)``."""
        return {
            M.MAV_CMD_DO_SET_MODE: self._cmd_set_mode, M.MAV_CMD_NAV_LAND: self._cmd_land,
            M.MAV_CMD_COMPONENT_ARM_DISARM: self._cmd_arm, M.MAV_CMD_SET_MESSAGE_INTERVAL: self._cmd_set_interval,
            M.MAV_CMD_GET_MESSAGE_INTERVAL: self._cmd_get_interval, M.MAV_CMD_REQUEST_MESSAGE: self._cmd_request,
            M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self._cmd_capabilities,
            M.MAV_CMD_GET_HOME_POSITION: self._cmd_get_home, M.MAV_CMD_DO_SET_HOME: self._cmd_set_home,
            M.MAV_CMD_DO_SET_MISSION_CURRENT: self._cmd_mission_current,
        }

    def _cmd_set_mode(self, msg, p, frame, replies) -> int:
        if not int(p[0]) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return _FAILED
        return _ACCEPTED if self.sim.autopilot.set_mode(int(p[1]), self._now)[0] else _FAILED

    def _cmd_land(self, msg, p, frame, replies) -> int:
        return _ACCEPTED if self.sim.autopilot.set_mode(9, self._now)[0] else _FAILED

    def _cmd_arm(self, msg, p, frame, replies) -> int:
        ap = self.sim.autopilot
        force = int(p[1]) == FORCE_MAGIC
        if p[0] == 1.0:
            ok = ap.arm(self._now, force)[0]
        elif p[0] == 0.0:
            ok = ap.disarm(self._now, force)[0]
        else:
            ok = False
        if ok:
            self.poll_vehicle()  # a home re-set at arming is announced at once
        return _ACCEPTED if ok else _FAILED

    def _streams_now(self):
        return self._link if self._link is not None else self.streams

    def _cmd_set_interval(self, msg, p, frame, replies) -> int:
        return _ACCEPTED if self._streams_now().set_interval_us(int(p[0]), p[1], self._now) else _FAILED

    def _cmd_get_interval(self, msg, p, frame, replies) -> int:
        # The field is int32: an interval set beyond it (a hostile request) reads back clamped.
        interval = max(-1, min(int(self._streams_now().interval_us(int(p[0]))), 2**31 - 1))
        replies.append(M.MAVLink_message_interval_message(int(p[0]) & 0xFFFF, interval))
        return _ACCEPTED

    def _cmd_request(self, msg, p, frame, replies) -> int | None:
        mid = int(p[0])
        if mid == M.MAVLINK_MSG_ID_SYS_STATUS:
            self.sync_counters()  # as the streamed one: the link counters of now
        if mid == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            m = autopilot_version(self.sim, nav_capabilities())
        else:
            m = build(mid, self.sim, self.tcounters)
        if m is None:
            return _FAILED
        self._ack(msg, M.MAV_CMD_REQUEST_MESSAGE, _ACCEPTED, replies)
        replies.append(m)
        return None

    def _cmd_capabilities(self, msg, p, frame, replies) -> None:
        self._ack(msg, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, _ACCEPTED, replies)
        replies.append(autopilot_version(self.sim, nav_capabilities()))

    def _cmd_get_home(self, msg, p, frame, replies) -> int:
        self.poll_vehicle()
        hp = home_position(self.sim)
        if hp is None:
            return _FAILED
        replies.append(hp)
        origin = build(M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, self.sim, self.tcounters)
        if origin is not None:
            replies.append(origin)
        return _ACCEPTED

    def _cmd_set_home(self, msg, p, frame, replies) -> int:
        sim = self.sim
        if not sim.autopilot.position_ready(sim.time_ns):
            return _FAILED  # no EKF origin yet
        if p[0] == 1.0 or (p[4] == 0 and p[5] == 0):
            ok = set_home(sim, *current_location(sim), lock=True)
        elif p[0] != 0.0:
            return _FAILED
        else:
            loc = self._location(p, frame)
            if loc is None:
                return _DENIED
            ok = set_home(sim, *loc, lock=True)
        self.poll_vehicle()
        return _ACCEPTED if ok else _FAILED

    def _location(self, p, frame: int | None) -> tuple[float, float, float] | None:
        """Latitude, longitude [deg] and altitude AMSL [m] of a command's params 5-7 (None: frame not taken)."""
        if not all(math.isfinite(v) for v in p[4:7]):
            return None
        if frame is None:  # COMMAND_LONG: degrees, altitude AMSL (ArduPilot converts it as MAV_FRAME_GLOBAL)
            return float(p[4]), float(p[5]), float(p[6])
        lat, lon = p[4] * 1e-7, p[5] * 1e-7
        if frame in (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT):
            return lat, lon, float(p[6])
        if frame in (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT):
            return lat, lon, self.sim.home.alt_m + float(p[6])
        return None

    def _cmd_mission_current(self, msg, p, frame, replies) -> int:
        ok = self.sim.missions.set_current(int(p[0]))
        if ok:
            self.poll_vehicle()
        return _ACCEPTED if ok else _FAILED
