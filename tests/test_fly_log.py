"""``gcs fly`` logs every flight to MCAP: channels, metrics equal to the in-flight ones, SIGKILL, bad paths."""

from __future__ import annotations

import base64
import json
import os
import signal
import subprocess
import sys
import time
from itertools import pairwise
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.cli import main
from gcs.config import load_config
from gcs.errors import LogError
from gcs.flight.flight import Flight
from gcs.vehicles.mavlink import MavlinkSession
from gcs.link.mavlink import MavlinkLink
from gcs.log.writer import FlightLog
from gcs.log import topics as T
from gcs.log.mcap.reader import read_log
from gcs.log.recorder import FlightRecorder
from gcs.log.review import log_info, log_metrics
from gcs.log.sink import InlineSink
from sitl.copter.server import SitlServer
from sitl.net.udp import UdpTransport


def _fly(*args: str, timeout: float = 240) -> tuple[subprocess.CompletedProcess, dict]:
    return subprocess.run([sys.executable, "-m", "gcs.cli", "fly", "-q", *args], capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    """One lockstep flight of the circle mission, cut at 12 s, with its log and summary."""
    d = tmp_path_factory.mktemp("flylog")
    log, summary = d / "flight.mcap", d / "summary.json"
    p = _fly("--sitl", "lockstep", "--controller", "nlsoc", "--duration", "12", "--log", str(log),
             "--summary", str(summary))
    assert p.returncode == 0, p.stderr
    return log, json.loads(summary.read_text())


def test_metrics_from_the_log_equal_the_in_flight_ones(flown):
    path, summary = flown
    m = log_metrics(path)
    assert not m["truncated"]
    (row,) = m["flights"]
    assert row["controller"] == "nlsoc" and row["steps"] == 1200
    assert row["metrics"] == summary["metrics"]  # exactly: the log keeps every double
    assert row["in_run_match"] is True
    assert summary["log"] == str(path)


def test_every_channel_is_there_and_round_trips(flown):
    path, summary = flown
    log = read_log(path)
    ticks = summary["loop"]["ticks"]
    for topic in (T.COMMAND, T.COMMAND_LIMITED, T.ERROR, T.HORIZON, T.COST, T.TIMING):
        assert log.counts[topic] == ticks, topic
    assert log.counts[T.STATE] == log.counts[T.REFERENCE] == ticks + 1  # + the state closing the record
    assert T.DISTURBANCE not in log.counts  # the built-in SITL flies without the disturbance observer ("auto")
    for topic in ("/mavlink/in/ATTITUDE", "/mavlink/in/LOCAL_POSITION_NED", "/mavlink/in/HEARTBEAT",
                  "/mavlink/in/COMMAND_ACK", "/mavlink/in/PARAM_VALUE", "/mavlink/in/STATUSTEXT",
                  "/mavlink/out/SET_ATTITUDE_TARGET", "/mavlink/out/COMMAND_LONG", "/mavlink/out/PARAM_SET",
                  "/mavlink/out/HEARTBEAT", T.FLIGHT, T.FLIGHT_METRICS, T.EVENTS):
        assert log.counts.get(topic, 0) > 0, topic
    # The raw frames replay: each decodes to the message on its decoded channel, in order.
    parser = mavlink.MAVLink(None)
    decoded = {"in": [], "out": []}
    for _, d in log.decoded(T.MAVLINK_RAW):
        msg = parser.decode(bytearray(base64.b64decode(d["data_b64"])))
        assert msg.get_type() == d["type"]
        decoded[d["dir"]].append(msg)
    per_type = sum(n for t, n in log.counts.items() if t.startswith(("/mavlink/in/", "/mavlink/out/")))
    assert sum(map(len, decoded.values())) == per_type == log.counts[T.MAVLINK_RAW]
    # (the summary's counters stop at the end of the flight; parameters are restored after it)
    assert per_type >= summary["link"]["received"] + summary["link"]["sent"]
    for direction in ("in", "out"):
        for mtype in ("ATTITUDE", "SET_ATTITUDE_TARGET", "HEARTBEAT"):
            raw = [m for m in decoded[direction] if m.get_type() == mtype]
            chan = [d for _, d in log.decoded(f"/mavlink/{direction}/{mtype}")]
            assert len(raw) == len(chan)
            assert all(m.to_dict() == dict(d, mavpackettype=mtype) for m, d in zip(raw, chan))
    # Per-tick internals: error = reference - estimate, the command before and after the envelope, horizon.
    (_, s0), (_, r0), (_, e0) = log.decoded(T.STATE)[0], log.decoded(T.REFERENCE)[0], log.decoded(T.ERROR)[0]
    assert e0["z"] == pytest.approx(r0["z"] - s0["z"])
    hor = [d for _, d in log.decoded(T.HORIZON)]
    assert [h["k"] for h in hor] == list(range(ticks)) and hor[0]["mode"] == "horizon" and hor[0]["steps_to_go"] > 0
    timing = [d for _, d in log.decoded(T.TIMING)]
    assert all(isinstance(t["deadline_missed"], bool) and t["tick_s"] > 0 for t in timing)
    kinds = {d["kind"] for _, d in log.decoded(T.EVENTS)}
    assert {"link", "param", "mode", "arming", "phase", "statustext", "landed", "flight_end"} <= kinds
    md = log.metadata_dict("flight")
    assert md["controller"] == "nlsoc" and md["source"] == "flight" and md["software_version"]
    names = {a.name for a in log.attachments}
    assert {"config.json", "config.toml", "gains/nlsoc.json"} <= names
    cfg = json.loads(log.attachment("config.json").data)
    assert sum(p["duration_s"] for p in cfg["mission"]["phases"]) == 12.0  # the mission as flown (--duration)


def test_the_disturbance_observer_is_logged_every_tick_when_on(tmp_path):
    config = Path(__file__).resolve().parents[1] / "configs" / "outdoor-circle.toml"
    text = config.read_text().replace("[estimator]\n", '[estimator]\ndisturbance = "on"\n')
    (tmp_path / "observed.toml").write_text(text)
    log_path, summary_path = tmp_path / "flight.mcap", tmp_path / "summary.json"
    p = _fly("--sitl", "lockstep", "--controller", "nlsoc", "--config", str(tmp_path / "observed.toml"),
             "--duration", "6", "--log", str(log_path), "--summary", str(summary_path))
    assert p.returncode == 0, p.stderr
    ticks = json.loads(summary_path.read_text())["loop"]["ticks"]
    log = read_log(log_path)
    assert log.counts[T.DISTURBANCE] == ticks
    rows = [d for _, d in log.decoded(T.DISTURBANCE)]
    assert all(list(d) == list(T.DISTURBANCE_FIELDS) for d in rows)
    # within the observer's clips: the learnt part 3 m/s^2 (plus the drag term), the velocity offset 0.5 m/s
    assert all(abs(d[f]) <= 3.5 for d in rows for f in T.DISTURBANCE_FIELDS[:3])
    assert all(abs(d[f]) <= 0.5 for d in rows for f in T.DISTURBANCE_FIELDS[3:])
    # on the ground only the drag term of the noisy velocity; once airborne it learns (here mostly the
    # built-in SITL's white position/velocity noise: the observer is off there by default, "auto")
    assert all(abs(d["dx_m_s2"]) < 0.5 for d in rows[:50])
    assert max(abs(d["dx_m_s2"]) for d in rows[-300:]) > 0.5
    name, schema = T.schema_for(T.DISTURBANCE)
    assert name == "gcs.Disturbance" and schema["required"] == list(T.DISTURBANCE_FIELDS)


def test_info_names_the_flight(flown, capsys):
    path, _ = flown
    info = log_info(path)
    assert info["controllers"] == ["nlsoc"] and info["experiment"] == "outdoor-circle" and not info["truncated"]
    assert main(["log", "info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "/mavlink/out/SET_ATTITUDE_TARGET" in out and "complete" in out


def _children(pid: int) -> list[int]:
    out = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        text = (task / "children").read_text().split()
        out += [int(c) for c in text]
    return out


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc")
@pytest.mark.parametrize("victims", ["gcs", "gcs+writer"])
def test_sigkill_mid_flight_leaves_a_readable_log_to_about_its_last_second(tmp_path, victims):
    """Killed in real time 2 s into the mission.  The ground station alone: its writer process sees
    the pipe close and finishes the file.  With its writer: the file is truncated, readable, and
    reaches to within about a second of the kill (the writer flushes every half second)."""
    path = tmp_path / "killed.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "gcs.cli", "fly", "--sitl", "realtime", "--log", str(path),
                             "--controller", "pd"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    kids: list[int] = []
    try:
        for line in proc.stdout:
            if "t    2.00 s" in line:
                break
        kids = _children(proc.pid)
        killed_ns = time.time_ns()
        os.kill(proc.pid, signal.SIGKILL)
        if victims == "gcs+writer":
            for k in kids:
                if "gcs.log.worker" in _cmdline(k):
                    os.kill(k, signal.SIGKILL)
        proc.wait(10)
        # The built-in SITL and the log writer notice and stop by themselves.
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and any(_cmdline(k) for k in kids):
            time.sleep(0.1)
        assert not [k for k in kids if _cmdline(k)], "a child of the killed ground station is still running"
    finally:
        if proc.poll() is None:
            proc.kill()
        for k in kids:
            try:
                os.kill(k, signal.SIGKILL)
            except ProcessLookupError:
                pass
    log = read_log(path, [T.STATE, T.HORIZON])
    assert log.truncated == (victims == "gcs+writer")
    ks = [d["k"] for _, d in log.decoded(T.HORIZON)]
    # (in real time a late tick is skipped, so k may jump; what was logged is in order, none twice)
    assert ks and ks[0] == 0 and all(b > a for a, b in pairwise(ks)), "an ordered prefix of the flight"
    assert log.counts[T.STATE] >= len(ks)
    lag_s = (killed_ns - log.last_ns[T.STATE]) / 1e9  # real-time logs are on the UTC time line
    assert -0.05 < lag_s < 1.0, f"the last {lag_s:.2f} s before the kill are missing"
    m = log_metrics(path)  # the review tools take it, and say so when it is truncated
    assert m["flights"][0]["partial"] and m["truncated"] == log.truncated


def test_unwritable_log_path_is_refused_before_anything_flies(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    summary = tmp_path / "s.json"
    p = _fly("--sitl", "lockstep", "--log", str(blocker / "sub" / "x.mcap"), "--summary", str(summary), timeout=60)
    assert p.returncode == 7
    assert "cannot create the log directory" in p.stderr and "--no-log" in p.stderr
    assert "Traceback" not in p.stderr
    assert json.loads(summary.read_text())["exit_reason"] == "preflight_refused"


def test_full_disk_is_refused_before_anything_flies(tmp_path, monkeypatch, capsys):
    import shutil
    from collections import namedtuple

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10 ** 9, 10 ** 9 - 10 ** 6, 10 ** 6))
    started = []
    monkeypatch.setattr("gcs.vehicles.embedded.EmbeddedSitl.start", lambda self: started.append(1) or self)
    assert main(["fly", "--sitl", "lockstep", "--log", str(tmp_path / "x.mcap"), "-q"]) == 7
    err = capsys.readouterr().err
    assert "disk nearly full" in err and not started
    assert not (tmp_path / "x.mcap").exists()


class _FailingSink(InlineSink):
    """A log whose disk fills up after ``after`` batches."""

    def __init__(self, log: FlightLog, after: int) -> None:
        super().__init__(log)
        self.after = after

    def put_wire(self, wire: list) -> None:
        self.after -= 1
        if self.after < 0:
            raise LogError(f"{self.path}: write failed: No space left on device")
        super().put_wire(wire)


def test_a_log_that_fails_in_flight_does_not_stop_the_flight(tmp_path):
    config = load_config("outdoor-altitude").with_duration(6.0)
    sink = _FailingSink(FlightLog(tmp_path / "x.mcap"), after=40)
    rec = FlightRecorder(sink)
    with SitlServer(UdpTransport(("127.0.0.1", 0)), lockstep=True, seed=3) as server:
        link = MavlinkLink(server.connection_string)
        flight = Flight(config, "loc", MavlinkSession(config, link), recorder=rec)
        flight.preflight()
        result = flight.fly()
        link.close()
    rec.close()
    assert result.exit_reason == "completed"
    assert any(e["kind"] == "warning" and "flight log failed" in e["text"] for e in result.events)
    log = read_log(tmp_path / "x.mcap")  # closed when it failed: what it holds is readable
    assert not log.truncated and log.counts.get(T.STATE, 0) > 0
