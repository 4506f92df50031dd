"""The navigation commands and position targets of the emulated ArduCopter (its MAVLink side; the
modes themselves are :mod:`sitl.copter.navigation`).

==============================================  =====================================================
NAV_TAKEOFF (22)                                GUIDED, armed and landed: climb to ``param7`` m above
                                                home (FAILED otherwise, as ArduCopter)
NAV_RETURN_TO_LAUNCH (20)                       RTL
MISSION_START (300)                             AUTO, from the current item
DO_CHANGE_SPEED (178)                           ``param2`` m/s (GUIDED, AUTO, RTL)
DO_REPOSITION (192)                             flying: GUIDED to ``param5..7`` (frame of COMMAND_INT;
                                                COMMAND_LONG: degrees, AMSL); ``param2`` bit 0 changes to
                                                GUIDED, else the vehicle must be in GUIDED already
SET_POSITION_TARGET_LOCAL_NED                   GUIDED: position (LOCAL_NED, LOCAL_OFFSET_NED,
                                                BODY_OFFSET_NED, BODY_NED) or velocity (NED; body frames
                                                rotated by the heading), optional yaw
SET_POSITION_TARGET_GLOBAL_INT                  GUIDED: position (GLOBAL(_INT), GLOBAL_RELATIVE_ALT(_INT),
                                                GLOBAL_TERRAIN_ALT(_INT) as relative) or velocity
==============================================  =====================================================

Position targets outside GUIDED, non-finite, or with neither position nor velocity are ignored (counted
as rejected targets), as ArduCopter ignores them.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from quadrotor.geodesy import local_from_geodetic
from sitl.copter.modes import Mode

__all__ = ["NAV_COMMANDS", "NAV_MESSAGES", "nav_command", "nav_message"]

M = mavlink
NAV_COMMANDS = (M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_RETURN_TO_LAUNCH, M.MAV_CMD_MISSION_START,
                M.MAV_CMD_DO_CHANGE_SPEED, M.MAV_CMD_DO_REPOSITION)
NAV_MESSAGES = ("SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT")
_ACCEPTED, _DENIED, _FAILED = M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_DENIED, M.MAV_RESULT_FAILED
_POS_IGNORE, _VEL_IGNORE, _YAW_IGNORE = 0b111, 0b111 << 3, 1 << 10
_GLOBAL_AMSL = (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT)
_GLOBAL_REL = (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_FRAME_GLOBAL_TERRAIN_ALT,
               M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT)


def _global_ned(sim, lat_deg: float, lon_deg: float, alt_m: float, frame: int) -> tuple[float, float, float] | None:
    """A global position as NED [m] from the origin (None: a frame not taken)."""
    nav_ctl = sim.autopilot.navigator
    lat0, lon0, alt0 = nav_ctl.origin
    if frame in _GLOBAL_AMSL:
        d = alt0 - alt_m
    elif frame in _GLOBAL_REL:
        d = nav_ctl.home_ned()[2] - alt_m
    else:
        return None
    n, e = local_from_geodetic(lat0, lon0, lat_deg, lon_deg)
    return n, e, d


def nav_command(sim, cmd: int, p: tuple[float, ...], frame: int | None, now_ns: int) -> tuple[int, str]:
    """A navigation COMMAND_LONG / COMMAND_INT (``p``: params 1-7, x/y as given); ``(MAV_RESULT, reason)``."""
    ap = sim.autopilot
    nav_ctl = ap.navigator
    if nav_ctl is None:
        return M.MAV_RESULT_UNSUPPORTED, "no navigation"
    if cmd == M.MAV_CMD_NAV_TAKEOFF:
        alt = p[6]
        if not math.isfinite(alt) or alt <= 0.0:
            return _DENIED, "bad altitude"
        if ap.mode != Mode.GUIDED or not ap.armed or not ap.land_complete:
            return _FAILED, "takeoff needs GUIDED, armed, landed"
        ap.position_control(now_ns)
        nav_ctl.takeoff(alt, sim.nav)
        return _ACCEPTED, ""
    if cmd == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
        ok, why = ap.set_mode(Mode.RTL, now_ns)
        return (_ACCEPTED if ok else _FAILED), why
    if cmd == M.MAV_CMD_MISSION_START:
        if ap.mode == Mode.AUTO:
            nav_ctl.enter(Mode.AUTO, sim.nav, sim.imu.yaw, ap.land_complete, now_ns)
            return _ACCEPTED, ""
        ok, why = ap.set_mode(Mode.AUTO, now_ns)
        return (_ACCEPTED if ok else _FAILED), why
    if cmd == M.MAV_CMD_DO_CHANGE_SPEED:
        if not math.isfinite(p[1]) or p[1] <= 0.0:
            return _DENIED, "bad speed"
        nav_ctl.set_speed(p[1])
        return _ACCEPTED, ""
    if cmd == M.MAV_CMD_DO_REPOSITION:
        return _reposition(sim, p, frame, now_ns)
    return M.MAV_RESULT_UNSUPPORTED, "not a navigation command"


def _reposition(sim, p, frame: int | None, now_ns: int) -> tuple[int, str]:
    ap = sim.autopilot
    if not all(math.isfinite(v) for v in p[4:7]) or ap.land_complete or not ap.armed:
        return _FAILED, "reposition needs a location and a flying vehicle"
    if frame is None:
        pos = _global_ned(sim, p[4], p[5], p[6], M.MAV_FRAME_GLOBAL)
    else:
        pos = _global_ned(sim, p[4] * 1e-7, p[5] * 1e-7, p[6], frame)
    if pos is None:
        return _DENIED, "frame not taken"
    if ap.mode != Mode.GUIDED:
        if not int(p[1]) & 1:
            return _FAILED, "not in GUIDED"
        ok, why = ap.set_mode(Mode.GUIDED, now_ns)
        if not ok:
            return _FAILED, why
    ap.position_control(now_ns)
    if math.isfinite(p[0]) and p[0] > 0:
        ap.navigator.set_speed(p[0])
    yaw = math.radians(p[3]) if math.isfinite(p[3]) else None
    ap.navigator.goto(*pos, yaw)
    return _ACCEPTED, ""


def _local_target(sim, msg, mask: int):
    """(position NED or None, velocity NED or None) of a SET_POSITION_TARGET_LOCAL_NED."""
    nav = sim.nav
    frame = int(msg.coordinate_frame)
    yaw = sim.imu.yaw
    body = frame in (M.MAV_FRAME_BODY_NED, M.MAV_FRAME_BODY_OFFSET_NED, M.MAV_FRAME_BODY_FRD)
    if frame not in (M.MAV_FRAME_LOCAL_NED, M.MAV_FRAME_LOCAL_OFFSET_NED) and not body:
        return None, None

    def rotate(x: float, y: float) -> tuple[float, float]:
        if not body:
            return x, y
        c, s = math.cos(yaw), math.sin(yaw)
        return c * x - s * y, s * x + c * y

    pos = vel = None
    if not mask & _POS_IGNORE:
        x, y = rotate(msg.x, msg.y)
        pos = (x, y, msg.z) if frame == M.MAV_FRAME_LOCAL_NED else (nav.n + x, nav.e + y, nav.d + msg.z)
    if not mask & _VEL_IGNORE:
        vel = (*rotate(msg.vx, msg.vy), msg.vz)
    return pos, vel


def nav_message(sim, msg, now_ns: int) -> bool:
    """A SET_POSITION_TARGET_* message; True when taken (GUIDED only, as ArduCopter)."""
    ap = sim.autopilot
    nav_ctl = ap.navigator
    mask = int(msg.type_mask)
    fields = (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz, msg.yaw)
    if nav_ctl is None or ap.mode != Mode.GUIDED or not all(math.isfinite(float(v)) for v in fields):
        ap.targets_rejected += 1
        return False
    if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
        pos, vel = _local_target(sim, msg, mask)
    else:
        pos = None if mask & _POS_IGNORE else _global_ned(sim, msg.lat_int * 1e-7, msg.lon_int * 1e-7, msg.alt,
                                                          int(msg.coordinate_frame))
        vel = None if mask & _VEL_IGNORE else (msg.vx, msg.vy, msg.vz)
    if pos is None and vel is None:
        ap.targets_rejected += 1
        return False
    yaw = None if mask & _YAW_IGNORE else float(msg.yaw)
    ap.position_control(now_ns)
    if vel is not None and pos is None:
        nav_ctl.set_velocity(*vel, yaw, sim.nav, now_ns)
    else:
        nav_ctl.goto(*pos, yaw)
    ap.targets_accepted += 1
    return True
