"""Topic names, message fields and their JSON schemas (one place for writer and readers).

Every message is a JSON object; each topic has a ``jsonschema`` schema with the
fields, their types and units (Foxglove Studio shows the descriptions).  See
:mod:`gcs.log` for what each topic means.

Beside these, the ``/foxglove/*`` topics carry Foxglove's well-known types (for its 3D, Map and Log
panels), with the schemas vendored verbatim from Foxglove's published JSON schemas
(``gcs/log/foxglove_schemas/``, see its SOURCE.md); :mod:`gcs.log.foxglove` says what they hold and in
which frames.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Mapping
from importlib import resources

__all__ = [
    "COMMAND",
    "COMMAND_FIELDS",
    "COMMAND_LIMITED",
    "COST",
    "COST_FIELDS",
    "DISTURBANCE",
    "DISTURBANCE_FIELDS",
    "ERROR",
    "EVENTS",
    "FIXED_FIELDS",
    "FLIGHT",
    "FOXGLOVE_LOCATION",
    "FOXGLOVE_LOG",
    "FOXGLOVE_REFERENCE_PATH",
    "FOXGLOVE_REFERENCE_POSE",
    "FOXGLOVE_SCHEMAS",
    "FOXGLOVE_TF",
    "FOXGLOVE_TOPICS",
    "FOXGLOVE_VEHICLE_POSE",
    "FLIGHT_METRICS",
    "HORIZON",
    "HORIZON_FIELDS",
    "MAVLINK_IN",
    "MAVLINK_OUT",
    "MAVLINK_RAW",
    "REFERENCE",
    "RIG_IN",
    "RIG_OUT",
    "RIG_RAW",
    "RUN_METRICS",
    "SIM_METRICS",
    "STATE",
    "STATE_FIELDS",
    "TIMING",
    "TIMING_FIELDS",
    "TRUTH",
    "foxglove_schema_bytes",
    "mavlink_topic",
    "rig_topic",
    "schema_for",
    "schema_json",
]

STATE = "/control/state"
REFERENCE = "/control/reference"
ERROR = "/control/error"
COMMAND = "/control/command"
COMMAND_LIMITED = "/control/command_limited"
HORIZON = "/control/horizon"
COST = "/control/cost"
DISTURBANCE = "/control/disturbance"
TRUTH = "/sim/truth"
SIM_METRICS = "/sim/metrics"
FLIGHT_METRICS = "/flight/metrics"
#: Topics carrying the metrics computed during the run (simulation or flight).
RUN_METRICS = (SIM_METRICS, FLIGHT_METRICS)
TIMING = "/loop/timing"
EVENTS = "/events"
FLIGHT = "/flight"
MAVLINK_RAW = "/mavlink/raw"
MAVLINK_IN = "/mavlink/in/"
MAVLINK_OUT = "/mavlink/out/"
RIG_RAW = "/rig/raw"
RIG_IN = "/rig/in/"
RIG_OUT = "/rig/out/"

# Foxglove well-known types (gcs.log.foxglove): frames, poses, the map track, the Log panel.
FOXGLOVE_TF = "/foxglove/tf"
FOXGLOVE_VEHICLE_POSE = "/foxglove/vehicle_pose"
FOXGLOVE_REFERENCE_POSE = "/foxglove/reference_pose"
FOXGLOVE_REFERENCE_PATH = "/foxglove/reference_path"
FOXGLOVE_LOCATION = "/foxglove/location"
FOXGLOVE_LOG = "/foxglove/log"
#: The Foxglove schema (file name in gcs/log/foxglove_schemas/, without ``.json``) of each Foxglove topic;
#: the MCAP schema name is ``foxglove.<name>``.
FOXGLOVE_SCHEMAS: dict[str, str] = {
    FOXGLOVE_TF: "FrameTransform", FOXGLOVE_VEHICLE_POSE: "PoseInFrame", FOXGLOVE_REFERENCE_POSE: "PoseInFrame",
    FOXGLOVE_REFERENCE_PATH: "PosesInFrame", FOXGLOVE_LOCATION: "LocationFix", FOXGLOVE_LOG: "Log",
}
FOXGLOVE_TOPICS = tuple(FOXGLOVE_SCHEMAS)

#: State fields in :class:`gcs.model.State` order (paper frame, z up) with units.
STATE_FIELDS = ("x", "y", "z", "vx", "vy", "vz", "roll", "pitch", "yaw", "roll_rate", "pitch_rate", "yaw_rate")
_STATE_UNITS = ("m, north", "m, east", "m, up", "m/s, north", "m/s, east", "m/s, up",
                "rad", "rad", "rad", "rad/s", "rad/s", "rad/s")
#: Command fields in :class:`gcs.model.Command` order.
COMMAND_FIELDS = ("thrust_n", "roll_accel_rad_s2", "pitch_accel_rad_s2", "yaw_accel_rad_s2")
_COMMAND_UNITS = ("collective thrust [N]", "roll angular acceleration [rad/s^2]",
                  "pitch angular acceleration [rad/s^2]", "yaw angular acceleration [rad/s^2]")
HORIZON_FIELDS = ("k", "steps_to_go", "mode")
#: ``/loop/timing`` fields after ``k``, in the order of :class:`gcs.log.records.LoopTiming`.
TIMING_FIELDS = ("jitter_s", "tick_s", "deadline_missed", "decode_s", "estimate_s", "control_s", "send_s",
                 "log_prev_s")
COST_FIELDS = ("state_cost", "input_cost", "stage_cost")
#: ``/control/disturbance``: the disturbance observer's estimate (gcs.estimate.DisturbanceObserver).
DISTURBANCE_FIELDS = ("dx_m_s2", "dy_m_s2", "dz_m_s2", "velocity_bias_x_m_s", "velocity_bias_y_m_s",
                      "velocity_bias_z_m_s")

#: Topics whose messages always carry exactly these numeric fields, in this order
#: (formatted through the templates of :mod:`gcs.log.jsonfmt`).
FIXED_FIELDS: dict[str, tuple[str, ...]] = {
    STATE: STATE_FIELDS, REFERENCE: STATE_FIELDS, ERROR: STATE_FIELDS, TRUTH: STATE_FIELDS,
    COMMAND: COMMAND_FIELDS, COMMAND_LIMITED: COMMAND_FIELDS, COST: COST_FIELDS, DISTURBANCE: DISTURBANCE_FIELDS,
}


def _numbers(fields, descriptions) -> dict:
    return {f: {"type": "number", "description": d} for f, d in zip(fields, descriptions, strict=True)}


def _obj(title: str, description: str, properties: Mapping[str, dict], required=(), extra: bool = False) -> dict:
    return {"$schema": "http://json-schema.org/draft-07/schema#", "title": title, "description": description,
            "type": "object", "properties": dict(properties), "required": list(required),
            "additionalProperties": extra}


_STATE_PROPS = _numbers(STATE_FIELDS, [f"[{u}]" for u in _STATE_UNITS])
_CMD_PROPS = _numbers(COMMAND_FIELDS, _COMMAND_UNITS)

_SCHEMAS: dict[str, tuple[str, dict]] = {
    STATE: ("gcs.State", _obj("State estimate", "Paper frame (x north, y east, z up), SI units", _STATE_PROPS,
                              STATE_FIELDS)),
    REFERENCE: ("gcs.State", _obj("State", "Paper frame (x north, y east, z up), SI units", _STATE_PROPS,
                                  STATE_FIELDS)),
    TRUTH: ("gcs.State", _obj("State", "Paper frame (x north, y east, z up), SI units", _STATE_PROPS, STATE_FIELDS)),
    ERROR: ("gcs.StateError", _obj("Tracking error", "reference - estimate (yaw wrapped to [-pi, pi))",
                                   _STATE_PROPS, STATE_FIELDS)),
    COMMAND: ("gcs.Command", _obj("Command", "Controller output (before the safety envelope)", _CMD_PROPS,
                                  COMMAND_FIELDS)),
    COMMAND_LIMITED: ("gcs.Command", _obj("Command", "Command after the safety envelope (what was sent)",
                                          _CMD_PROPS, COMMAND_FIELDS)),
    HORIZON: ("gcs.Horizon", _obj("Horizon", "Finite-horizon schedule of this tick", {
        "k": {"type": "integer", "description": "control step index since the start of the flight"},
        "steps_to_go": {"type": "integer",
                        "description": "j >= 1 used by the finite-horizon law; 0 when another law flew"},
        "mode": {"type": "string", "description": "horizon | terminal | restart | fallback_pd | pd"},
    }, HORIZON_FIELDS)),
    COST: ("gcs.StageCost", _obj("Stage cost", "Terms of the controller's own cost J at this tick "
                                 "(eq. 5 for LOC, eq. 17 for NLSOC), each with the factor 1/2", _numbers(
                                     COST_FIELDS, ("1/2 x'Qx", "1/2 u'Ru", "state_cost + input_cost")),
                                 COST_FIELDS)),
    DISTURBANCE: ("gcs.Disturbance", _obj(
        "Disturbance estimate", "The disturbance observer's estimate at this tick (paper frame, z up): the "
        "acceleration eq. 1 misses (linear drag at the estimated velocity plus the learnt steady part; the laws "
        "compensate it, less the reference's acceleration) and the offset taken off the velocity readings",
        _numbers(DISTURBANCE_FIELDS, ("[m/s^2, north]", "[m/s^2, east]", "[m/s^2, up]", "[m/s, north]",
                                      "[m/s, east]", "[m/s, up]")), DISTURBANCE_FIELDS)),
    TIMING: ("gcs.LoopTiming", _obj("Loop timing", "One control tick's timing [s]", {
        "k": {"type": "integer"},
        "jitter_s": {"type": "number", "description": "tick start minus its deadline [s]"},
        "tick_s": {"type": "number", "description": "compute time of the tick [s]"},
        "deadline_missed": {"type": "boolean"},
    }, extra=True)),
    EVENTS: ("gcs.Event", _obj("Event", "Mode changes, arming, failsafes, warnings, phase changes", {
        "kind": {"type": "string"}, "text": {"type": "string"},
    }, ("kind", "text"), extra=True)),
    FLIGHT: ("gcs.Flight", _obj("Flight", "Start of a flight: every message from here to the next /flight "
                                "message belongs to it", {
        "flight": {"type": "integer", "description": "flight index in this file"},
        "controller": {"type": "string"}, "experiment": {"type": "string"},
        "run": {"type": "integer"}, "seed": {"type": ["integer", "null"]},
        "ts_s": {"type": "number", "description": "control period [s]"},
        "steps": {"type": ["integer", "null"], "description": "planned control steps"},
        "source": {"type": "string", "description": "sim | flight"},
    }, ("flight", "controller"), extra=True)),
    SIM_METRICS: ("gcs.Metrics", _obj("Metrics", "The metrics gcs sim computed in the run (see gcs.metrics)", {
        "flight": {"type": "integer"},
    }, ("flight",), extra=True)),
    FLIGHT_METRICS: ("gcs.Metrics", _obj("Metrics", "The metrics gcs fly computed in flight (see gcs.metrics)", {
        "flight": {"type": "integer"},
    }, ("flight",), extra=True)),
    RIG_RAW: ("gcs.RigFrame", _obj("Rig frame", "A raw 4-DOF rig frame (XBee API-2, escaped, as on the wire) sent "
                                   "or received, or received bytes that held no valid frame (type GARBAGE)", {
        "dir": {"type": "string", "enum": ["in", "out"]},
        "type": {"type": "string", "description": "message name (docs/rig-protocol.md) or GARBAGE"},
        "data_b64": {"type": "string", "contentEncoding": "base64", "description": "bytes, base64"},
    }, ("dir", "data_b64"))),
    MAVLINK_RAW: ("gcs.MavlinkFrame", _obj("MAVLink frame", "A raw MAVLink frame as sent or received (replayable)", {
        "dir": {"type": "string", "enum": ["in", "out"]},
        "type": {"type": "string", "description": "message type name"},
        "data_b64": {"type": "string", "contentEncoding": "base64", "description": "frame bytes, base64"},
    }, ("dir", "data_b64"))),
}


def mavlink_topic(direction: str, msg_type: str) -> str:
    """``/mavlink/in/<TYPE>`` or ``/mavlink/out/<TYPE>``."""
    if direction not in ("in", "out"):
        raise ValueError(f"direction must be 'in' or 'out', got {direction!r}")
    return f"/mavlink/{direction}/{msg_type}"


def rig_topic(direction: str, msg_name: str) -> str:
    """``/rig/in/<NAME>`` or ``/rig/out/<NAME>`` (names of docs/rig-protocol.md, e.g. TELEMETRY)."""
    if direction not in ("in", "out"):
        raise ValueError(f"direction must be 'in' or 'out', got {direction!r}")
    return f"/rig/{direction}/{msg_name}"


@functools.cache
def foxglove_schema_bytes(name: str) -> bytes:
    """The vendored Foxglove JSON schema ``name`` (e.g. ``"FrameTransform"``) as shipped, byte for byte.

    Raises
    ------
    FileNotFoundError
        For a schema that is not vendored (an installation without the package data).
    """
    return resources.files("gcs.log").joinpath("foxglove_schemas", f"{name}.json").read_bytes()


def schema_for(topic: str) -> tuple[str, dict]:
    """``(schema name, jsonschema dict)`` of a topic; an open object schema for unknown topics."""
    known = _SCHEMAS.get(topic)
    if known is not None:
        return known
    fox = FOXGLOVE_SCHEMAS.get(topic)
    if fox is not None:
        return f"foxglove.{fox}", json.loads(foxglove_schema_bytes(fox))
    if topic.startswith((MAVLINK_IN, MAVLINK_OUT)):
        msg_type = topic.rsplit("/", 1)[-1]
        return (f"mavlink.{msg_type}", _obj(msg_type, "MAVLink message fields as decoded by pymavlink", {}, extra=True))
    if topic.startswith((RIG_IN, RIG_OUT)):
        msg_type = topic.rsplit("/", 1)[-1]
        return (f"rig.{msg_type}", _obj(msg_type, "4-DOF rig message fields (docs/rig-protocol.md; SI units as "
                                        "named)", {}, extra=True))
    return ("gcs.Message", _obj(topic, "", {}, extra=True))


def schema_json(topic: str) -> tuple[str, bytes]:
    """``(schema name, schema as JSON bytes)`` of a topic (a Foxglove one as vendored, byte for byte)."""
    fox = FOXGLOVE_SCHEMAS.get(topic)
    if fox is not None:
        return f"foxglove.{fox}", foxglove_schema_bytes(fox)
    name, schema = schema_for(topic)
    return name, json.dumps(schema, separators=(",", ":")).encode()
