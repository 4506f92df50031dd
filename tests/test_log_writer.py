"""FlightLog: every channel round-trips, the file is always finished, flushes, pre-flight checks."""

import io
import json
import math
import shutil
import time
from collections import namedtuple

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from gcs.errors import LogError
from gcs.log.writer import FlightLog, check_writable
from gcs.log import topics as T
from gcs.log.mcap.fast import FastWriter
from gcs.log.mcap.reader import read_log
from quadrotor.state import Command, State

rng = np.random.default_rng(7)
STATE = State(*rng.normal(size=12))
REF = State(*rng.normal(size=12))
TRUTH = State(*(rng.normal(size=12) * 1e-7))
DISTURBANCE = (0.025, -0.032, 0.125, 0.001, -0.0015, 1e-17)
CMD = Command(*rng.normal(size=4) * 10)
LIMITED = Command(9.81, 0.0, -1e-300, 5e300)


class FakeMavlink:
    """What FlightLog.mavlink needs of a pymavlink message."""

    def __init__(self, mtype, fields, frame):
        self._t, self._f, self._b = mtype, fields, frame

    def get_type(self):
        return self._t

    def to_dict(self):
        return dict(self._f, mavpackettype=self._t)

    def get_msgbuf(self):
        return bytearray(self._b)


def _write_everything(path, **kw):
    frame = bytes(range(40))
    with FlightLog(path, **kw) as log:
        log.metadata("flight", {"controller": "loc", "experiment": "outdoor-altitude", "n": 3})
        log.attachment("config.json", "application/json", '{"a": 1}')
        log.attachment("gains/loc.json", "application/json", b"\x00\x01")
        assert log.flight_start(1_000, controller="loc", experiment="outdoor-altitude", ts_s=0.01, steps=2) == 0
        log.control_tick(1_000, state=STATE, reference=REF, command=CMD, command_limited=LIMITED, k=0,
                         steps_to_go=60000, mode="horizon", cost=(1.5, 2.25, 3.75), truth=TRUTH,
                         disturbance=DISTURBANCE)
        log.control_tick(11_000, state=list(STATE), reference=np.array(REF), command=CMD, k=1, steps_to_go=0,
                         mode="fallback_pd")
        log.event(11_000, "mode", "GUIDED_NOGPS", custom_mode=20, armed=True)
        log.loop_timing(11_000, k=1, jitter_s=1e-4, tick_s=2.5e-4, deadline_missed=False, control_s=1e-5)
        log.mavlink(12_000, "in", FakeMavlink("ATTITUDE", {"roll": 0.1, "pitch": -0.2, "time_boot_ms": 5}, frame))
        log.mavlink(12_500, "out", FakeMavlink("SET_ATTITUDE_TARGET", {"q": [1.0, 0.0, 0.0, 0.0], "thrust": 0.39},
                                               frame[:20]))
        log.mavlink_raw(13_000, "in", b"\xfd\x00garbage", "BAD")
        log.write("/custom/thing", 14_000,
                  {"nested": {"a": [1, 2, {"b": None}]}, "blob": b"\xff", "np": np.float32(0.5)})
        log.write_values(T.TRUTH, 15_000, np.arange(12.0))
    return frame


def test_every_channel_round_trips(tmp_path):
    path = tmp_path / "all.mcap"
    frame = _write_everything(path)
    log = read_log(path)
    assert not log.truncated and log.problem == ""
    assert log.summary_message_count == log.message_count
    assert log.profile == "gcs"
    d = {topic: log.decoded(topic) for topic in log.topics}
    sf, cf = T.STATE_FIELDS, T.COMMAND_FIELDS
    assert [t for t, _ in d[T.STATE]] == [1_000, 11_000]
    for topic, value in ((T.STATE, STATE), (T.REFERENCE, REF)):
        for _, m in d[topic]:
            assert [m[f] for f in sf] == list(value)  # exact: 17 significant digits
    assert [d[T.TRUTH][0][1][f] for f in sf] == list(TRUTH)
    assert [d[T.TRUTH][1][1][f] for f in sf] == list(range(12))
    err = d[T.ERROR][0][1]
    for i, f in enumerate(sf):
        expect = REF[i] - STATE[i]
        if f == "yaw":
            expect = (expect + math.pi) % (2 * math.pi) - math.pi
        assert err[f] == expect
    assert [d[T.COMMAND][0][1][f] for f in cf] == list(CMD)
    assert [t for t, _ in d[T.DISTURBANCE]] == [1_000]  # only the tick that gave one
    assert [d[T.DISTURBANCE][0][1][f] for f in T.DISTURBANCE_FIELDS] == list(DISTURBANCE)
    assert [d[T.COMMAND_LIMITED][0][1][f] for f in cf] == list(LIMITED) and len(d[T.COMMAND_LIMITED]) == 1
    assert [m for _, m in d[T.HORIZON]] == [{"k": 0, "steps_to_go": 60000, "mode": "horizon"},
                                            {"k": 1, "steps_to_go": 0, "mode": "fallback_pd"}]
    assert d[T.COST] == [(1_000, {"state_cost": 1.5, "input_cost": 2.25, "stage_cost": 3.75})]
    assert d[T.FLIGHT][0][1]["controller"] == "loc" and d[T.FLIGHT][0][1]["steps"] == 2
    assert d[T.EVENTS] == [(11_000, {"kind": "mode", "text": "GUIDED_NOGPS", "custom_mode": 20, "armed": True})]
    assert d[T.TIMING][0][1] == {"k": 1, "jitter_s": 1e-4, "tick_s": 2.5e-4, "deadline_missed": False,
                                 "control_s": 1e-5}
    assert d["/mavlink/in/ATTITUDE"] == [(12_000, {"roll": 0.1, "pitch": -0.2, "time_boot_ms": 5})]
    assert d["/mavlink/out/SET_ATTITUDE_TARGET"][0][1]["q"] == [1.0, 0.0, 0.0, 0.0]
    raw = d[T.MAVLINK_RAW]
    import base64
    assert [(m["dir"], m["type"], base64.b64decode(m["data_b64"])) for _, m in raw] == [
        ("in", "ATTITUDE", frame), ("out", "SET_ATTITUDE_TARGET", frame[:20]), ("in", "BAD", b"\xfd\x00garbage")]
    assert d["/custom/thing"][0][1] == {"nested": {"a": [1, 2, {"b": None}]}, "blob": "/w==", "np": 0.5}
    # Channels: JSON messages with jsonschema schemas, one channel per topic.
    assert len({c.topic for c in log.channels.values()}) == len(log.channels)
    for c in log.channels.values():
        assert c.message_encoding == "json" and c.schema_encoding == "jsonschema"
    # Metadata and attachments.
    assert log.metadata_dict("flight") == {"controller": "loc", "experiment": "outdoor-altitude", "n": "3"}
    assert log.attachment("config.json").data == b'{"a": 1}'
    assert log.attachment("gains/loc.json").data == b"\x00\x01"


def test_schemas_are_json_schema_objects_and_mcap_reads_the_file(tmp_path):
    path = tmp_path / "all.mcap"
    _write_everything(path)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count > 0
        for schema in summary.schemas.values():
            doc = json.loads(schema.data)
            assert schema.encoding == "jsonschema" and doc["type"] == "object"
        state = summary.schemas[next(c.schema_id for c in summary.channels.values() if c.topic == T.STATE)]
        props = json.loads(state.data)["properties"]
        assert list(props) == list(T.STATE_FIELDS) and "[m, up]" in props["z"]["description"]
        n = sum(1 for _ in reader.iter_messages())
    assert n == summary.statistics.message_count


def test_non_finite_values_round_trip(tmp_path):
    path = tmp_path / "nan.mcap"
    with FlightLog(path) as log:
        log.write_values(T.STATE, 0, [math.nan, math.inf, -math.inf] + [0.0] * 9)
        log.write_values(T.COMMAND, 1, Command(None, 1.0, 2.0, 3.0))
        with pytest.raises(ValueError, match="expected 4 values"):
            log.write_values(T.COMMAND, 2, (1.0, 2.0))
        with pytest.raises(ValueError, match="no fixed fields"):
            log.write_values("/whatever", 2, (1.0,))
    m = read_log(path).decoded(T.STATE)[0][1]
    assert math.isnan(m["x"]) and m["y"] == math.inf and m["z"] == -math.inf
    assert read_log(path).decoded(T.COMMAND)[0][1]["thrust_n"] is None


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_compressions(tmp_path, compression):
    path = tmp_path / f"{compression}.mcap"
    with FlightLog(path, compression=compression, chunk_size_bytes=4096) as log:
        for k in range(500):
            log.control_tick(k * 10_000_000, state=STATE, reference=REF, command=CMD, k=k)
    log = read_log(path, [T.HORIZON])
    assert not log.truncated and log.counts[T.STATE] == 500
    assert [m["k"] for _, m in log.decoded(T.HORIZON)] == list(range(500))


@pytest.mark.parametrize("batched", [False, True])
def test_fast_add_message_writes_the_same_bytes_as_mcap(batched):
    def build(cls, batched):
        buf = io.BytesIO()
        w = cls(buf, chunk_size=2000, compression=CompressionType.ZSTD)
        w.start(profile="p", library="l")
        sid = w.register_schema("s", "jsonschema", b"{}")
        chans = [w.register_channel(f"/t{i}", "json", sid) for i in range(3)]
        for k in range(300):
            t = 1000 - k if k % 7 == 0 else k * 10
            data = [(c, f'{{"k":{k},"c":{c}}}'.encode()) for c in chans]
            if batched:
                w.add_messages(data, t, k)
            else:
                for c, d in data:
                    w.add_message(c, t, d, k, sequence=0)
            if k % 97 == 0:
                w.flush()
            if k == 150:
                w.add_metadata("m", {"a": "b"})
        w.finish()
        return buf.getvalue()

    fast = FastWriter(io.BytesIO())
    assert fast.fast, "mcap's Writer internals changed: the fast path is off (still correct, slower)"
    if not batched:
        assert build(FastWriter, False) == build(Writer, False)
        return
    # A batch closes a full chunk after its last message, not in the middle: same messages, other chunking.
    def content(data):
        reader = make_reader(io.BytesIO(data))
        stats = reader.get_summary().statistics
        msgs = [(c.topic, m.log_time, m.publish_time, m.data) for _, c, m in reader.iter_messages(log_time_order=False)]
        return (stats.message_count, dict(stats.channel_message_counts), stats.message_start_time,
                stats.message_end_time), msgs

    assert content(build(FastWriter, True)) == content(build(Writer, False))


def test_exception_inside_with_still_finishes_the_file(tmp_path):
    path = tmp_path / "boom.mcap"
    with pytest.raises(RuntimeError, match="boom"), FlightLog(path) as log:
        log.event(5, "warning", "about to fail")
        raise RuntimeError("boom")
    log = read_log(path)
    assert not log.truncated and log.counts[T.EVENTS] == 1


def test_closed_log_rejects_writes_and_close_is_idempotent(tmp_path):
    log = FlightLog(tmp_path / "c.mcap")
    log.close()
    log.close()
    with pytest.raises(LogError, match="closed"):
        log.event(0, "x", "y")
    with pytest.raises(LogError, match="closed"):
        log.flush()


def test_background_flush_makes_data_readable_while_the_log_is_open(tmp_path):
    path = tmp_path / "open.mcap"
    log = FlightLog(path, flush_interval_s=0.1)
    try:
        for k in range(50):
            log.control_tick(k, state=STATE, reference=REF, command=CMD, k=k)
        deadline = time.monotonic() + 3.0
        seen = 0
        while time.monotonic() < deadline and seen < 50:
            time.sleep(0.05)
            seen = read_log(path, None).counts.get(T.STATE, 0)
        assert seen == 50, "the idle writer did not flush within the interval"
        r = read_log(path, None)
        assert r.truncated and "footer" in r.problem
        log.event(100, "x", "explicit flush")
        log.flush()
        assert read_log(path, None).counts[T.EVENTS] == 1
    finally:
        log.close()
    assert not read_log(path, None).truncated


def test_check_writable(tmp_path, monkeypatch):
    assert check_writable(tmp_path / "new" / "dir" / "x.mcap") == tmp_path / "new" / "dir" / "x.mcap"
    assert (tmp_path / "new" / "dir").is_dir() and list((tmp_path / "new" / "dir").iterdir()) == []
    with pytest.raises(LogError, match="is a directory"):
        check_writable(tmp_path)
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    with pytest.raises(LogError, match="cannot create the log directory"):
        check_writable(blocker / "x.mcap")
    with pytest.raises(LogError, match="cannot create the log directory"):
        FlightLog(blocker / "sub" / "x.mcap")
    usage = shutil.disk_usage(tmp_path)
    with pytest.raises(LogError, match="disk nearly full"):
        check_writable(tmp_path / "x.mcap", expected_bytes=usage.free + 1)
    Usage = namedtuple("Usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: Usage(10**9, 10**9 - 1000, 1000))
    with pytest.raises(LogError, match=r"disk nearly full: 1\.0 kB free"):
        FlightLog(tmp_path / "y.mcap")
    assert not (tmp_path / "y.mcap").exists()


def test_unwritable_directory(tmp_path, monkeypatch):
    import tempfile

    def refuse(*a, **k):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", refuse)
    with pytest.raises(LogError, match="cannot write logs there: Permission denied"):
        check_writable(tmp_path / "x.mcap")
