"""Foxglove's well-known messages of a flight: frames, poses, the reference path, the map track, log lines.

Every ``gcs fly`` / ``gcs sim`` log carries, beside its own channels (:mod:`gcs.log.topics`, unchanged),
channels of Foxglove's well-known types, so that Foxglove's 3D panel shows the vehicle and its reference
path, its Map panel the track and its Log panel the events (the layout in ``docs/foxglove-layout.json``).
JSON messages, ``jsonschema`` schemas vendored verbatim from Foxglove (``gcs/log/foxglove_schemas/``).
:class:`gcs.log.foxglove_encoder.FoxgloveEncoder` writes them from the log's records; this module knows
the frames and formats the messages.

Frames (Foxglove's 3D panel is right-handed, z up; the paper's frame is x north, y east, z up — not
right-handed — and shares its ZYX Euler angles with MAVLink's NED / FRD, :mod:`quadrotor.frames`)
------------------------------------------------------------------------------------------------------
``world`` (:data:`WORLD_FRAME`)
    East-north-up (ENU, ROS REP 103), origin the origin of the log's positions (the vehicle's local
    origin): ``(x, y, z)_world = (y, x, z)_paper`` = (east, north, up) [m].
``vehicle`` (:data:`VEHICLE_FRAME`)
    The vehicle's body, forward-left-up (FLU): ``q_world<-vehicle = q_ENU<-NED * q_NED<-FRD * q_FRD<-FLU``,
    ``q_NED<-FRD`` the attitude of the roll, pitch, yaw logged (:func:`quadrotor.frames.euler_to_quaternion`).
    Closed form (:func:`enu_flu_quaternion`): with ``(w, x, y, z) = q_NED<-FRD`` and ``s = 1/sqrt(2)``,
    ``(x, y, z, w)_foxglove = s * (x + y, x - y, w - z, w + z)``.  Yaw 0 (north) points the vehicle's x
    axis along the world's +y.

Topics (:data:`gcs.log.topics.FOXGLOVE_TOPICS`)
------------------------------------------------
``/foxglove/tf`` — ``foxglove.FrameTransform`` ``world`` -> ``vehicle``, every state sample;
``/foxglove/vehicle_pose``, ``/foxglove/reference_pose`` — ``foxglove.PoseInFrame`` in ``world``,
every tick: the vehicle (the true state in a simulation, the estimate in flight) and the reference;
``/foxglove/reference_path`` — ``foxglove.PosesInFrame``: the whole planned reference of a flight
(its mission, every :data:`PATH_STEP_S`, at most :data:`MAX_PATH_POSES` poses), once at its start;
``/foxglove/location`` — ``foxglove.LocationFix``: each GLOBAL_POSITION_INT the vehicle sent
(``frame_id`` ``gps``; none while it reports 0, 0: no fix); in a simulation the true position
placed around :data:`SIM_ORIGIN` with :mod:`quadrotor.geodesy`, at :data:`SIM_FIX_PERIOD_S`
(``frame_id`` ``sim``; the SITL's default home, so ``gcs sim`` and ``gcs fly --sitl`` tracks lie on
the same map); a flight with no GLOBAL_POSITION_INT (the 4-DOF rig) has no map track;
``/foxglove/log`` — ``foxglove.Log``: every ``/events`` event (``name`` ``gcs.<kind>``; failsafe ->
ERROR, warning and interrupt -> WARNING, the others INFO) and every STATUSTEXT received (``name``
``vehicle``, level from its MAV_SEVERITY, :data:`SEVERITY_LEVEL`; the ``statustext`` events that
repeat them are not written twice).

Times: every message's ``timestamp`` is its log time (``log_time_ns``: the loop's clock in flight, the
simulated time line in a simulation), so the 3D panel finds each transform at the time of the poses.
Nothing non-finite is written: a sample with a non-finite position or attitude is left out.  Poses are
written to 10 um and quaternions to 1e-6 (a picture's precision; the doubles are on our own channels).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence

import numpy as np

from quadrotor.frames import euler_to_quaternion
from quadrotor.geodesy import geodetic_from_local

__all__ = [
    "LEVEL_ERROR",
    "LEVEL_INFO",
    "LEVEL_WARNING",
    "MAX_PATH_POSES",
    "PATH_STEP_S",
    "POSE_TEMPLATE",
    "SEVERITY_LEVEL",
    "SIM_FIX_PERIOD_S",
    "SIM_ORIGIN",
    "TF_TEMPLATE",
    "VEHICLE_FRAME",
    "WORLD_FRAME",
    "enu_flu_quaternion",
    "enu_flu_quaternions",
    "event_level",
    "finite_pose",
    "location_fix",
    "log_line",
    "pose_json",
    "pose_texts",
    "poses_in_frame",
    "sim_fix",
    "statustext_line",
    "stamp",
    "transform_json",
]

WORLD_FRAME = "world"
VEHICLE_FRAME = "vehicle"
#: Spacing of the planned reference path's poses [s], and the most poses it has (longer missions: wider).
PATH_STEP_S = 0.1
MAX_PATH_POSES = 5000
#: Where a simulation's map track is placed: the SITL's default home (ArduPilot's CMAC field), lat [deg],
#: lon [deg], altitude above mean sea level [m] of z = 0 (``sitl.copter.vehicle.HomeParams``).
SIM_ORIGIN = (-35.363261, 149.165230, 584.0)
#: Period of a simulation's derived fixes [s] (a GPS-like 10 Hz).
SIM_FIX_PERIOD_S = 0.1

#: foxglove.LogLevel values.
LEVEL_UNKNOWN, LEVEL_DEBUG, LEVEL_INFO, LEVEL_WARNING, LEVEL_ERROR, LEVEL_FATAL = range(6)
#: MAV_SEVERITY (0 EMERGENCY .. 7 DEBUG) -> foxglove.LogLevel.
SEVERITY_LEVEL = {0: LEVEL_FATAL, 1: LEVEL_FATAL, 2: LEVEL_FATAL, 3: LEVEL_ERROR, 4: LEVEL_WARNING,
                  5: LEVEL_INFO, 6: LEVEL_INFO, 7: LEVEL_DEBUG}
_EVENT_LEVEL = {"failsafe": LEVEL_ERROR, "warning": LEVEL_WARNING, "interrupt": LEVEL_WARNING}

_S = 1.0 / math.sqrt(2.0)
# Positions to 10 um, quaternion components to 1e-6 (fixed point: no exponent, short texts): a picture's
# precision; the full doubles are on /control/state, /control/reference and /sim/truth.
_POS, _ROT = b"%.5f", b"%.6f"
_STAMP = b'{"timestamp":{"sec":%d,"nsec":%d},'
_XYZ = b'{"x":' + _POS + b',"y":' + _POS + b',"z":' + _POS + b"}"
_QUAT = b'{"x":' + _ROT + b',"y":' + _ROT + b',"z":' + _ROT + b',"w":' + _ROT + b"}"
_POSE = b'{"position":' + _XYZ + b',"orientation":' + _QUAT + b"}"
#: ``foxglove.PoseInFrame`` / ``foxglove.FrameTransform`` of (sec, nsec, x, y, z, qx, qy, qz, qw) (ENU, FLU).
POSE_TEMPLATE = _STAMP + b'"frame_id":"' + WORLD_FRAME.encode() + b'","pose":' + _POSE + b"}"
TF_TEMPLATE = (_STAMP + b'"parent_frame_id":"' + WORLD_FRAME.encode() + b'","child_frame_id":"'
               + VEHICLE_FRAME.encode() + b'","translation":' + _XYZ + b',"rotation":' + _QUAT + b"}")


def stamp(t_ns: int) -> tuple[int, int]:
    """``(sec, nsec)`` of a log time [ns] (foxglove ``time``: both >= 0; earlier times clamp to 0)."""
    t = max(0, int(t_ns))
    return t // 1_000_000_000, t % 1_000_000_000


def enu_flu_quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """``(x, y, z, w)`` of the body (FLU) in the ``world`` frame (ENU) for ZYX Euler angles [rad] of the paper."""
    w, x, y, z = euler_to_quaternion(roll, pitch, yaw)
    return (_S * (x + y), _S * (x - y), _S * (w - z), _S * (w + z))


def enu_flu_quaternions(angles: np.ndarray) -> np.ndarray:
    """:func:`enu_flu_quaternion` of an (n, 3) array of (roll, pitch, yaw) [rad]: (n, 4) of (x, y, z, w)."""
    half = 0.5 * np.asarray(angles, float)
    with np.errstate(invalid="ignore"):  # a non-finite angle gives NaN, left out by the caller
        cr, cp, cy = np.cos(half).T
        sr, sp, sy = np.sin(half).T
    w = cr * cp * cy + sr * sp * sy
    x = sr * cp * cy - cr * sp * sy
    y = cr * sp * cy + sr * cp * sy
    z = cr * cp * sy - sr * sp * cy
    return _S * np.stack([x + y, x - y, w - z, w + z], axis=1)


def finite_pose(state: Sequence[float]) -> bool:
    """Position (x, y, z) and attitude (roll, pitch, yaw) of a state all finite."""
    return all(math.isfinite(state[i]) for i in (0, 1, 2, 6, 7, 8))


def _pose_values(state: Sequence[float]) -> tuple[float, ...]:
    """ENU position and FLU-in-ENU quaternion of a paper-frame state: (x, y, z, qx, qy, qz, qw)."""
    return (state[1], state[0], state[2], *enu_flu_quaternion(state[6], state[7], state[8]))


def pose_json(t_ns: int, state: Sequence[float]) -> bytes:
    """A ``foxglove.PoseInFrame`` in ``world`` of a paper-frame state (12 values; its pose must be finite)."""
    return POSE_TEMPLATE % (*stamp(t_ns), *_pose_values(state))


def transform_json(t_ns: int, state: Sequence[float]) -> bytes:
    """The ``foxglove.FrameTransform`` ``world`` -> ``vehicle`` of a paper-frame state."""
    return TF_TEMPLATE % (*stamp(t_ns), *_pose_values(state))


def pose_texts(t_ns: int, state: Sequence[float]) -> tuple[bytes, bytes]:
    """``(FrameTransform, PoseInFrame)`` of the vehicle in one go (the pose computed once)."""
    values = (*stamp(t_ns), *_pose_values(state))
    return TF_TEMPLATE % values, POSE_TEMPLATE % values


def poses_in_frame(t_ns: int, states: Sequence[Sequence[float]]) -> bytes:
    """A ``foxglove.PosesInFrame`` in ``world`` of paper-frame states (non-finite poses left out)."""
    poses = b",".join(_POSE % _pose_values(s) for s in states if finite_pose(s))
    sec, nsec = stamp(t_ns)
    return b'{"timestamp":{"sec":%d,"nsec":%d},"frame_id":"%s","poses":[%s]}' % (
        sec, nsec, WORLD_FRAME.encode(), poses)


def _fix(t_ns: int, frame_id: str, lat_deg: float, lon_deg: float, alt_m: float, heading_rad: float | None,
         velocity_enu: tuple[float, float, float]) -> bytes:
    sec, nsec = stamp(t_ns)
    doc = {"timestamp": {"sec": sec, "nsec": nsec}, "frame_id": frame_id, "latitude": lat_deg,
           "longitude": lon_deg, "altitude": alt_m, "position_covariance": [0.0] * 9, "position_covariance_type": 0}
    if heading_rad is not None:
        doc["heading"] = heading_rad
    doc["velocity"] = dict(zip("xyz", velocity_enu, strict=True))
    return json.dumps(doc, separators=(",", ":"), allow_nan=False).encode()


def location_fix(t_ns: int, msg: dict) -> bytes | None:
    """The ``foxglove.LocationFix`` of a decoded GLOBAL_POSITION_INT (pymavlink fields), None without a fix.

    Latitude, longitude [deg] from degE7, altitude above mean sea level [m] from mm, velocity ENU [m/s]
    from the NED cm/s, heading [rad, clockwise from north] from cdeg (none for UINT16_MAX, unknown).
    """
    try:
        lat, lon = int(msg["lat"]), int(msg["lon"])
        alt_m = float(msg["alt"]) / 1000.0
        vn, ve, vd = (float(msg[k]) / 100.0 for k in ("vx", "vy", "vz"))
        hdg = int(msg.get("hdg", 65535))
    except (KeyError, TypeError, ValueError):
        return None
    if lat == 0 and lon == 0:
        return None
    heading = None if hdg == 65535 else math.radians(hdg / 100.0)
    return _fix(t_ns, "gps", lat * 1e-7, lon * 1e-7, alt_m, heading, (ve, vn, -vd))


def sim_fix(t_ns: int, state: Sequence[float], origin: tuple[float, float, float] = SIM_ORIGIN) -> bytes | None:
    """The ``foxglove.LocationFix`` of a simulated (paper-frame) state placed around ``origin`` (lat, lon, alt)."""
    x, y, z, vx, vy, vz, yaw = (float(state[i]) for i in (0, 1, 2, 3, 4, 5, 8))
    if not all(map(math.isfinite, (x, y, z, vx, vy, vz, yaw))):
        return None
    lat, lon = geodetic_from_local(origin[0], origin[1], x, y)
    return _fix(t_ns, "sim", lat, lon, origin[2] + z, yaw % (2.0 * math.pi), (vy, vx, vz))


def log_line(t_ns: int, level: int, message: str, name: str) -> bytes:
    """A ``foxglove.Log`` line (no file, line 0)."""
    sec, nsec = stamp(t_ns)
    return json.dumps({"timestamp": {"sec": sec, "nsec": nsec}, "level": int(level), "message": str(message),
                       "name": str(name), "file": "", "line": 0}, separators=(",", ":")).encode()


def event_level(kind: str) -> int:
    """The foxglove.LogLevel of an ``/events`` kind."""
    return _EVENT_LEVEL.get(kind, LEVEL_INFO)


def statustext_line(t_ns: int, msg: dict) -> bytes | None:
    """The ``foxglove.Log`` line of a decoded STATUSTEXT (level from MAV_SEVERITY), None for a malformed one."""
    text = msg.get("text")
    if isinstance(text, bytes):
        text = text.decode(errors="replace")
    if not isinstance(text, str):
        return None
    try:
        severity = int(msg.get("severity", -1))
    except (TypeError, ValueError):
        severity = -1
    return log_line(t_ns, SEVERITY_LEVEL.get(severity, LEVEL_UNKNOWN), text.rstrip("\x00"), "vehicle")
