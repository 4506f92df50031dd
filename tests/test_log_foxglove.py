"""Foxglove well-known channels of the log: vendored schemas, frames, messages, the encoder, ``gcs log channels``.

The end-to-end check on real ``gcs fly`` / ``gcs sim`` logs is tests/test_log_foxglove_flights.py.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import tomllib
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from gcs.cli import main
from gcs.config import load_config
from gcs.log import foxglove as F
from gcs.log import topics as T
from gcs.log.foxglove_encoder import FoxgloveEncoder, planned_path
from gcs.log.mcap.reader import read_log
from gcs.log.meta import run_attachments
from gcs.log.records import Attachment, Event, FlightEnd, FlightStart, LinkFrame, Tick, TickBlock
from gcs.log.review.channels import log_channels
from gcs.log.sink import InlineSink
from gcs.log.writer import FlightLog
from gcs.mission import Mission
from quadrotor.frames import euler_to_quaternion, quat_rotate

ROOT = Path(__file__).resolve().parents[1]
VENDORED = ROOT / "gcs" / "log" / "foxglove_schemas"
rng = np.random.default_rng(5)


def validator(topic: str) -> jsonschema.protocols.Validator:
    name, schema = T.schema_for(topic)
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    return cls(schema)


def assert_valid(topic: str, data: bytes) -> dict:
    doc = json.loads(data)
    errors = [e.message for e in validator(topic).iter_errors(doc)]
    assert not errors, (topic, errors, doc)
    return doc


# --------------------------------------------------------------------------- vendored schemas

def test_the_vendored_schemas_are_foxgloves_as_recorded():
    source = (VENDORED / "SOURCE.md").read_text()
    assert re.search(r"Commit: [0-9a-f]{40}", source) and "MIT" in source
    assert "Permission is hereby granted, free of charge" in (VENDORED / "LICENSE").read_text()
    rows = dict(re.findall(r"\| (\w+)\.json \| foxglove\.\w+ \| ([0-9a-f]{64}) \|", source))
    assert set(rows) == set(T.FOXGLOVE_SCHEMAS.values())
    for name, digest in rows.items():
        data = (VENDORED / f"{name}.json").read_bytes()
        assert hashlib.sha256(data).hexdigest() == digest, name  # verbatim: not edited since vendored
        assert json.loads(data)["title"] == f"foxglove.{name}"
    for topic, name in T.FOXGLOVE_SCHEMAS.items():
        assert T.schema_json(topic) == (f"foxglove.{name}", (VENDORED / f"{name}.json").read_bytes())


def test_the_vendored_schemas_are_shipped_as_package_data():
    """An installed gcs must find them (pyproject lists packages explicitly: the folder is package data)."""
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"].get("package-data", {})
    patterns = data.get("gcs.log", [])
    files = [p.relative_to(ROOT / "gcs" / "log").as_posix() for p in VENDORED.iterdir() if p.is_file()]
    missing = [f for f in files if not any(Path(f).match(p) for p in patterns)]
    assert not missing, f"add to [tool.setuptools.package-data] \"gcs.log\": {missing}"


# --------------------------------------------------------------------------- frames

@pytest.mark.parametrize("angles", [(0.0, 0.0, 0.0), (0.0, 0.0, math.pi / 2), (0.3, -0.2, 2.5),
                                    *[tuple(rng.uniform(-3, 3, 3)) for _ in range(20)]])
def test_the_body_frame_is_flu_in_enu(angles):
    """Each FLU body axis, rotated by the logged quaternion, is the same physical direction as the FRD
    axis rotated into NED by the vehicle's attitude (quadrotor.frames), written in ENU."""
    q_ned = euler_to_quaternion(*angles)
    qx, qy, qz, qw = F.enu_flu_quaternion(*angles)
    assert math.isclose(qx * qx + qy * qy + qz * qz + qw * qw, 1.0, rel_tol=1e-12)
    for flu, frd in (((1, 0, 0), (1, 0, 0)), ((0, 1, 0), (0, -1, 0)), ((0, 0, 1), (0, 0, -1))):
        n, e, d = quat_rotate(q_ned, frd)
        assert quat_rotate((qw, qx, qy, qz), flu) == pytest.approx((e, n, -d), abs=1e-12)
    assert F.enu_flu_quaternions(np.array([angles]))[0] == pytest.approx((qx, qy, qz, qw), abs=1e-15)


def test_yaw_zero_faces_north_and_positions_are_enu():
    state = (1.0, 2.0, 3.0, 0, 0, 0, 0.0, 0.0, 0.0, 0, 0, 0)  # 1 m north, 2 m east, 3 m up
    doc = assert_valid(T.FOXGLOVE_VEHICLE_POSE, F.pose_json(1_500_000_001, state))
    assert doc["frame_id"] == F.WORLD_FRAME and doc["timestamp"] == {"sec": 1, "nsec": 500_000_001}
    assert doc["pose"]["position"] == {"x": 2.0, "y": 1.0, "z": 3.0}
    q = doc["pose"]["orientation"]
    assert quat_rotate((q["w"], q["x"], q["y"], q["z"]), (1, 0, 0)) == pytest.approx((0, 1, 0), abs=1e-6)
    tf = assert_valid(T.FOXGLOVE_TF, F.transform_json(7, state))
    assert (tf["parent_frame_id"], tf["child_frame_id"]) == (F.WORLD_FRAME, F.VEHICLE_FRAME)
    assert tf["translation"] == doc["pose"]["position"] and tf["rotation"] == q
    assert F.stamp(-5) == (0, 0)  # foxglove time is unsigned


# --------------------------------------------------------------------------- location and log lines

def test_global_position_int_to_location_fix():
    gpi = {"time_boot_ms": 10, "lat": -353632610, "lon": 1491652300, "alt": 584500, "relative_alt": 500,
           "vx": 100, "vy": -200, "vz": -50, "hdg": 9000}
    doc = assert_valid(T.FOXGLOVE_LOCATION, F.location_fix(3_000_000_000, gpi))
    assert doc["latitude"] == pytest.approx(-35.363261) and doc["longitude"] == pytest.approx(149.16523)
    assert doc["altitude"] == pytest.approx(584.5) and doc["frame_id"] == "gps"
    assert doc["heading"] == pytest.approx(math.pi / 2)
    assert doc["velocity"] == pytest.approx({"x": -2.0, "y": 1.0, "z": 0.5})  # ENU from NED cm/s
    assert "heading" not in json.loads(F.location_fix(0, dict(gpi, hdg=65535)))
    assert F.location_fix(0, dict(gpi, lat=0, lon=0)) is None  # no fix yet
    assert F.location_fix(0, {"lat": "x"}) is None


def test_a_simulated_state_is_placed_around_the_sitl_home():
    doc = assert_valid(T.FOXGLOVE_LOCATION, F.sim_fix(0, (100.0, 0.0, 2.0, 0, 1.0, 0, 0, 0, -0.1, 0, 0, 0)))
    lat0, lon0, alt0 = F.SIM_ORIGIN
    assert doc["latitude"] > lat0 and doc["longitude"] == pytest.approx(lon0) and doc["altitude"] == alt0 + 2.0
    assert (doc["latitude"] - lat0) * math.pi / 180 * 6378137.0 == pytest.approx(100.0)
    assert doc["heading"] == pytest.approx(2 * math.pi - 0.1) and doc["velocity"]["x"] == 1.0
    assert F.sim_fix(0, (math.nan,) * 12) is None


@pytest.mark.parametrize(("severity", "level"), [(0, 5), (2, 5), (3, 4), (4, 3), (5, 2), (6, 2), (7, 1), (9, 0)])
def test_statustext_severity_sets_the_log_level(severity, level):
    doc = assert_valid(T.FOXGLOVE_LOG, F.statustext_line(5, {"severity": severity, "text": "PreArm: x\x00\x00"}))
    assert doc["level"] == level and doc["message"] == "PreArm: x" and doc["name"] == "vehicle"


# --------------------------------------------------------------------------- the encoder

def _gpi_frame(lat: int) -> bytes:
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    return bytes(mavlink.MAVLink_global_position_int_message(1, lat, 1491652300, 584000, 0, 0, 0, 0, 100)
                 .pack(mav))


def _statustext_frame(severity: int, text: bytes) -> bytes:
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    return bytes(mavlink.MAVLink_statustext_message(severity, text).pack(mav))


def test_the_encoder_writes_every_foxglove_channel_from_the_records(tmp_path):
    config = load_config("outdoor-circle")
    (cfg_json,) = [d for n, _, d in run_attachments(config) if n == "config.json"]
    path = tmp_path / "x.mcap"
    s = (0.5, 0.2, 1.0, 0, 0, 0, 0.01, -0.02, 0.3, 0, 0, 0)
    nan = (math.nan,) * 12
    with FlightLog(path) as log:
        sink = InlineSink(log)
        assert isinstance(sink.encoder, FoxgloveEncoder)
        sink.put_many([
            Attachment("config.json", "application/json", cfg_json),
            FlightStart(1_000, "loc", "outdoor-circle", 0.01, 3, extra={"origin_m": [1.0, 2.0, 0.5]}),
            Tick(2_000, 0, s, s, (1, 0, 0, 0), None, 3, "horizon"),
            Tick(3_000, 1, nan, s, (1, 0, 0, 0), None, 2, "horizon"),  # left out, not crashed
            LinkFrame(3_500, "mavlink", "in", _gpi_frame(-353632610)),
            LinkFrame(3_600, "mavlink", "in", _gpi_frame(0)),  # lat 0 but lon not: a fix on the equator
            LinkFrame(3_700, "mavlink", "in", _statustext_frame(4, b"EKF variance")),
            Event(4_000, "failsafe", "telemetry stale: landing"),
            Event(4_100, "statustext", "EKF variance"),  # the frame above is its Log line
            FlightEnd(5_000, s, state=s),
        ])
        assert sink.encoder.skipped == 1
    log = read_log(path)
    for topic in T.FOXGLOVE_TOPICS:
        for _, data in log.messages[topic]:
            assert_valid(topic, data)
    assert log.counts[T.FOXGLOVE_TF] == log.counts[T.FOXGLOVE_VEHICLE_POSE] == 2  # tick 0 and the end
    assert log.counts[T.FOXGLOVE_REFERENCE_POSE] == 3 and log.counts[T.FOXGLOVE_LOCATION] == 2
    (t_path, path_doc), = log.decoded(T.FOXGLOVE_REFERENCE_PATH)
    mission = Mission(config.mission)
    assert t_path == 1_000 and len(path_doc["poses"]) == math.ceil(mission.duration_s / F.PATH_STEP_S) + 1
    r = mission.reference(mission.duration_s / 2)
    mid = path_doc["poses"][len(path_doc["poses"]) // 2]["position"]
    assert (mid["x"], mid["y"], mid["z"]) == pytest.approx((r.y + 2.0, r.x + 1.0, r.z + 0.5), abs=1e-4)  # origin
    lines = [d for _, d in log.decoded(T.FOXGLOVE_LOG)]
    assert [(d["name"], d["level"], d["message"]) for d in lines] == [
        ("vehicle", F.LEVEL_WARNING, "EKF variance"), ("gcs.failsafe", F.LEVEL_ERROR, "telemetry stale: landing")]
    assert [t for t, _ in log.decoded(T.FOXGLOVE_TF)] == [2_000, 5_000]
    assert log.decoded(T.FOXGLOVE_TF)[0][1]["timestamp"] == {"sec": 0, "nsec": 2_000}


def test_a_simulated_block_gives_poses_every_tick_and_fixes_at_10_hz(tmp_path):
    n, ts_ns = 250, 10_000_000
    truth = rng.normal(size=(n, 12))
    truth[7, 8] = math.inf
    ref = np.zeros((n, 12))
    path = tmp_path / "sim.mcap"
    with FlightLog(path) as log:
        sink = InlineSink(log)
        sink.put_many([FlightStart(None, "pd", "x", 0.01, n, "sim"),
                       TickBlock(0, truth, truth, ref, np.zeros((n, 4)), np.zeros(n, dtype=int), ["pd"] * n)])
        assert sink.encoder.skipped == 1
    log = read_log(path)
    poses = log.decoded(T.FOXGLOVE_VEHICLE_POSE)
    assert len(poses) == n - 1 and log.counts[T.FOXGLOVE_REFERENCE_POSE] == n
    assert T.FOXGLOVE_REFERENCE_PATH not in log.counts  # no config attached: no planned path
    k = 42
    t, doc = poses[k - 1]
    assert t == k * ts_ns and doc["pose"]["position"] == pytest.approx(
        {"x": truth[k, 1], "y": truth[k, 0], "z": truth[k, 2]}, abs=1e-5)
    q = F.enu_flu_quaternion(*truth[k, 6:9])
    assert [doc["pose"]["orientation"][c] for c in "xyzw"] == pytest.approx(q, abs=1e-6)
    fixes = log.decoded(T.FOXGLOVE_LOCATION)
    assert [t for t, _ in fixes] == [k * ts_ns for k in range(0, n, 10)]
    for topic in (T.FOXGLOVE_TF, T.FOXGLOVE_VEHICLE_POSE, T.FOXGLOVE_LOCATION):
        for _, data in log.messages[topic]:
            assert_valid(topic, data)


def test_planned_path_of_a_bad_config_or_origin():
    assert planned_path(b"{}") is None and planned_path(b"not json") is None
    (cfg,) = [d for n, _, d in run_attachments(load_config("outdoor-altitude")) if n == "config.json"]
    assert planned_path(cfg, [1.0, 2.0]) is None and planned_path(cfg, "abc") is None
    path = planned_path(cfg, [math.nan, 0.0, 0.0])
    assert path and json.loads(F.poses_in_frame(0, path))["poses"] == []  # nothing non-finite on the wire


# --------------------------------------------------------------------------- gcs log channels

def test_channels_lists_and_validates_and_reads_a_truncated_file(tmp_path, capsys):
    path = tmp_path / "c.mcap"
    s = (0.0,) * 12
    with FlightLog(path, chunk_size_bytes=2048) as log:
        InlineSink(log).put_many([FlightStart(0, "pd", "x", 0.01, 300)] + [
            Tick(k * 10_000_000, k, s, s, (1, 0, 0, 0), None, 0, "pd") for k in range(300)])
    doc = log_channels(path, validate=True)
    rows = {r["topic"]: r for r in doc["channels"]}
    assert rows[T.FOXGLOVE_TF] | {"validation": None} == {
        "topic": T.FOXGLOVE_TF, "schema": "foxglove.FrameTransform", "schema_encoding": "jsonschema",
        "message_encoding": "json", "messages": 300, "foxglove": True, "validation": None}
    assert rows[T.FOXGLOVE_TF]["validation"] == {"valid": 300, "invalid": 0, "errors": [], "schema_source": "file"}
    assert rows[T.STATE]["schema"] == "gcs.State" and not rows[T.STATE]["foxglove"]
    assert "validation" not in rows[T.STATE]
    assert main(["log", "channels", str(path), "--validate"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"/foxglove/tf\s+foxglove\.FrameTransform\s+json/jsonschema\s+300\s+valid 300/300", out)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    doc = log_channels(cut, validate=True)
    assert doc["truncated"]
    v = next(r for r in doc["channels"] if r["topic"] == T.FOXGLOVE_TF)["validation"]
    assert v["schema_source"] == "vendored" and v["invalid"] == 0 and 0 < v["valid"] < 300


def test_channels_reports_an_invalid_message(tmp_path, capsys):
    path = tmp_path / "bad.mcap"
    with FlightLog(path) as log:
        log.write(T.FOXGLOVE_LOG, 5, {"timestamp": {"sec": 0, "nsec": 5}, "level": 9, "message": "x"})
    doc = log_channels(path, validate=True)
    v = doc["channels"][0]["validation"]
    assert v["invalid"] == 1 and v["valid"] == 0 and any("required" in e for e in v["errors"])
    assert main(["log", "channels", str(path), "--validate"]) == 1
    assert "valid 0/1" in capsys.readouterr().out


# --------------------------------------------------------------------------- the Foxglove layout

def _panels(node) -> list[str]:
    return [node] if isinstance(node, str) else _panels(node["first"]) + _panels(node["second"])


def test_the_layout_shows_the_channels_the_log_has():
    layout = json.loads((ROOT / "docs" / "foxglove-layout.json").read_text())
    panels = layout["configById"]
    assert sorted(_panels(layout["layout"])) == sorted(panels)  # every configured panel is placed, once
    kinds = {p.split("!")[0] for p in panels}
    assert {"3D", "map", "RosOut", "Plot"} <= kinds
    three_d = panels["3D!vehicle"]
    assert three_d["followTf"] == F.VEHICLE_FRAME and three_d["followMode"] == "follow-position"
    assert set(three_d["transforms"]) == {f"frame:{F.WORLD_FRAME}", f"frame:{F.VEHICLE_FRAME}"}
    assert three_d["layers"]["grid"]["frameId"] == F.WORLD_FRAME
    shown = {t for t, s in three_d["topics"].items() if s["visible"]}
    assert shown == {T.FOXGLOVE_VEHICLE_POSE, T.FOXGLOVE_REFERENCE_POSE, T.FOXGLOVE_REFERENCE_PATH}
    assert three_d["topics"][T.FOXGLOVE_REFERENCE_PATH]["type"] == "line"
    assert panels["map!track"]["followTopic"] == T.FOXGLOVE_LOCATION
    assert panels["RosOut!events"]["topicToRender"] == T.FOXGLOVE_LOG
    for pid in (p for p in panels if p.startswith("Plot!")):
        for path in panels[pid]["paths"]:
            topic, field = path["value"].rsplit(".", 1)
            assert field in T.schema_for(topic)[1]["properties"], path["value"]  # a field of our own schema
    refs = {p["value"] for pid in panels if pid.startswith("Plot!") for p in panels[pid]["paths"]}
    assert {"/control/state.z", "/control/reference.z", "/control/state.x", "/control/reference.x"} <= refs
