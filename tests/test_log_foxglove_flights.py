"""The Foxglove channels of real logs: a short lockstep ``gcs fly`` (SITL and rig) and a ``gcs sim``, every
message validated against Foxglove's published JSON schemas, the channel list checked (``gcs log channels``)."""

from __future__ import annotations

import json
import subprocess
import sys

import jsonschema
import pytest

from gcs.log import foxglove as F
from gcs.log import topics as T
from gcs.log.mcap.reader import read_log

FOXGLOVE = {T.FOXGLOVE_TF: "foxglove.FrameTransform", T.FOXGLOVE_VEHICLE_POSE: "foxglove.PoseInFrame",
            T.FOXGLOVE_REFERENCE_POSE: "foxglove.PoseInFrame", T.FOXGLOVE_REFERENCE_PATH: "foxglove.PosesInFrame",
            T.FOXGLOVE_LOCATION: "foxglove.LocationFix", T.FOXGLOVE_LOG: "foxglove.Log"}


def _gcs(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    p = subprocess.run([sys.executable, "-m", "gcs.cli", *args], capture_output=True, text=True, timeout=timeout)
    assert p.returncode == 0, p.stderr
    return p


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("foxglove")
    fly, rig, sim = d / "fly.mcap", d / "rig.mcap", d / "sim.mcap"
    _gcs("fly", "-q", "--sitl", "lockstep", "--controller", "loc", "--duration", "3", "--log", str(fly))
    _gcs("fly", "-q", "--rig", "4dof", "--sitl", "lockstep", "--controller", "pd", "--duration", "2", "--log", str(rig))
    _gcs("sim", "-q", "--config", "outdoor-circle", "--controller", "loc", "--runs", "2", "--duration", "3",
         "--log", str(sim))
    return {"fly": fly, "rig": rig, "sim": sim}


def _channels(path) -> dict:
    p = _gcs("log", "channels", str(path), "--validate", "--json")
    return {r["topic"]: r for r in json.loads(p.stdout)["channels"]}


def _validate_all(log) -> None:
    """Every Foxglove message against the vendored schema, here (independently of gcs log channels)."""
    for topic in FOXGLOVE:
        name, schema = T.schema_for(topic)
        v = jsonschema.validators.validator_for(schema)(schema)
        for _, data in log.messages.get(topic, []):
            errors = [e.message for e in v.iter_errors(json.loads(data))]
            assert not errors, (topic, errors)


@pytest.mark.parametrize("which", ["fly", "rig", "sim"])
def test_every_foxglove_message_is_valid_and_listed(logs, which):
    rows = _channels(logs[which])
    expected = dict(FOXGLOVE)
    if which == "rig":
        del expected[T.FOXGLOVE_LOCATION]  # no GLOBAL_POSITION_INT on the rig: no map track
    for topic, schema in expected.items():
        r = rows[topic]
        assert (r["schema"], r["message_encoding"], r["schema_encoding"]) == (schema, "json", "jsonschema"), topic
        v = r["validation"]
        assert r["messages"] > 0 and v == {"valid": r["messages"], "invalid": 0, "errors": [], "schema_source": "file"}
    assert T.FOXGLOVE_LOCATION not in rows or which != "rig"
    # Our own channels are there unchanged, beside them.
    assert rows[T.STATE]["schema"] == "gcs.State" and rows[T.EVENTS]["schema"] == "gcs.Event"
    _validate_all(read_log(logs[which], list(FOXGLOVE)))


def test_the_flight_log_poses_follow_the_estimate_and_the_map_the_gps(logs):
    log = read_log(logs["fly"])
    states, refs = log.decoded(T.STATE), log.decoded(T.REFERENCE)
    tf, poses, rposes = log.decoded(T.FOXGLOVE_TF), log.decoded(T.FOXGLOVE_VEHICLE_POSE), \
        log.decoded(T.FOXGLOVE_REFERENCE_POSE)
    assert len(tf) == len(poses) == len(states) and len(rposes) == len(refs)
    for (t, s), (tp, p), (tt, f) in zip(states, poses, tf, strict=True):
        assert t == tp == tt and F.stamp(t) == (p["timestamp"]["sec"], p["timestamp"]["nsec"])
        assert (p["pose"]["position"]["x"], p["pose"]["position"]["y"], p["pose"]["position"]["z"]) == \
            pytest.approx((s["y"], s["x"], s["z"]), abs=1e-5)
        assert f["translation"] == p["pose"]["position"] and f["child_frame_id"] == F.VEHICLE_FRAME
    assert rposes[-1][1]["pose"]["position"]["z"] == pytest.approx(refs[-1][1]["z"], abs=1e-5)
    # The map: one fix per GLOBAL_POSITION_INT with a fix, at its time, where it says.
    gpi = [(t, d) for t, d in log.decoded("/mavlink/in/GLOBAL_POSITION_INT") if d["lat"] or d["lon"]]
    fixes = log.decoded(T.FOXGLOVE_LOCATION)
    assert gpi and [t for t, _ in fixes] == [t for t, _ in gpi]
    assert all(f["latitude"] == pytest.approx(g["lat"] * 1e-7) and f["frame_id"] == "gps"
               for (_, f), (_, g) in zip(fixes, gpi, strict=True))
    # The planned reference path: the mission (3 s takeoff) from the takeoff point, once, at the flight's start.
    (t_path, path), = log.decoded(T.FOXGLOVE_REFERENCE_PATH)
    (t_flight, flight), = log.decoded(T.FLIGHT)
    assert t_path == t_flight
    ox, oy, oz = flight["origin_m"]
    assert path["poses"][0]["position"] == pytest.approx({"x": oy, "y": ox, "z": oz}, abs=1e-4)
    assert len(path["poses"]) == 31  # 3 s every 0.1 s
    for i, pose in enumerate(path["poses"][:30]):  # the reference flown at tick 10 i (0.1 s apart)
        t, r = refs[10 * i]
        assert t == t_flight + i * 100_000_000
        assert pose["position"] == pytest.approx({"x": r["y"], "y": r["x"], "z": r["z"]}, abs=1e-4)
    # The Log panel: every event but the statustext ones, and every STATUSTEXT with its severity.
    events = [d for _, d in log.decoded(T.EVENTS)]
    texts = [d for _, d in log.decoded("/mavlink/in/STATUSTEXT")]
    lines = [d for _, d in log.decoded(T.FOXGLOVE_LOG)]
    assert len(lines) == len([e for e in events if e["kind"] != "statustext"]) + len(texts)
    assert {(ln["message"], ln["level"]) for ln in lines if ln["name"] == "vehicle"} == {
        (t["text"], F.SEVERITY_LEVEL[t["severity"]]) for t in texts}
    assert {ln["name"] for ln in lines} >= {"gcs.mode", "gcs.arming", "gcs.phase", "gcs.flight_end", "vehicle"}


def test_the_sim_log_has_a_path_per_flight_and_a_derived_map_track(logs):
    log = read_log(logs["sim"])
    flights = log.decoded(T.FLIGHT)
    paths = log.decoded(T.FOXGLOVE_REFERENCE_PATH)
    assert len(flights) == len(paths) == 2 and [t for t, _ in paths] == [t for t, _ in flights]
    truth, poses = log.decoded(T.TRUTH), log.decoded(T.FOXGLOVE_VEHICLE_POSE)
    assert len(poses) == len(truth)
    for (t, s), (tp, p) in zip(truth, poses, strict=True):
        assert t == tp and p["pose"]["position"]["x"] == pytest.approx(s["y"], abs=1e-5)
    fixes = log.decoded(T.FOXGLOVE_LOCATION)
    assert len(fixes) == 2 * 30  # 3 s at 10 Hz, each flight
    lat0, lon0, _ = F.SIM_ORIGIN
    assert all(f["frame_id"] == "sim" and abs(f["latitude"] - lat0) < 1e-3 and abs(f["longitude"] - lon0) < 1e-3
               for _, f in fixes)


def test_export_writes_the_reference_path_one_pose_a_row(logs, tmp_path):
    import csv

    from gcs.log.review import export_csv

    res = export_csv(logs["sim"], tmp_path / "csv")
    (ch,) = [c for c in res["channels"] if c["topic"] == T.FOXGLOVE_REFERENCE_PATH]
    n = sum(len(d["poses"]) for _, d in read_log(logs["sim"], [T.FOXGLOVE_REFERENCE_PATH]).decoded(
        T.FOXGLOVE_REFERENCE_PATH))
    with open(ch["csv"], newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == ch["rows"] == n and ch["columns"] < 20
    assert [int(r["pose"]) for r in rows[:3]] == [0, 1, 2] and {r["flight"] for r in rows} == {"0", "1"}
