"""The log pipeline: typed records, the one framing, the one encoder for flown and simulated ticks, the sinks."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from gcs.errors import LogError
from gcs.log.writer import FlightLog
from gcs.log import topics as T
from gcs.log.framing import from_wire, pack, to_wire, unpack
from gcs.log.mcap.reader import read_log
from gcs.log.recorder import FlightRecorder
from gcs.log.records import (RECORDS, Attachment, CloseLog, Event, FlightEnd, FlightStart, Garbage, LinkFrame,
                             LogDone, LogFailed, LoopTiming, Metadata, Metrics, OpenLog, Tick, TickBlock)
from gcs.log.sink import BackgroundSink, InlineSink
from quadrotor.state import Command, State

rng = np.random.default_rng(11)
TIMING = LoopTiming(1e-4, 3e-4, False, 1e-5, 2e-5, 3e-5, 4e-5, 5e-5)
COST = {"kind": "nlsoc", "Q": [[2.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 3.0, 0], [0, 0, 0, 0.5]],
        "R": [[0.1, 0.0], [0.0, 0.2]], "gravity_compensated": True, "mass_kg": 1.2, "gravity_m_s2": 9.81}


def _every_record() -> list:
    s, c = tuple(rng.normal(size=12).tolist()), tuple(rng.normal(size=4).tolist())
    return [FlightStart(5, "loc", "x", 0.01, 10, cost=COST, extra={"origin_m": [0.0, 1.0, 2.0]}),
            Tick(6, 0, s, s, c, c, 9, "horizon", TIMING), Tick(7, 1, s, s, c, None, 8, "pd"),
            TickBlock(0, np.zeros((2, 12)), np.ones((2, 12)), np.zeros((2, 12)), np.zeros((2, 4)),
                      np.array([2, 1]), ["horizon", "horizon"]),
            LinkFrame(8, "mavlink", "in", b"\xfd\x01"), Garbage(9, "rig", "in", b"\x00"),
            Event(10, "mode", "GUIDED", {"custom_mode": 20}), FlightEnd(11, s, state=s), Metrics(12, {"J": 1.0}),
            Metadata("flight", {"a": "b"}), Attachment("x.json", "application/json", b"{}"),
            OpenLog("/tmp/x.mcap", {"fsync": False}, 10), CloseLog(), LogDone({"messages": 1}), LogFailed("boom")]


def test_every_record_type_travels_through_the_framing():
    records = _every_record()
    assert {type(r) for r in records} == set(RECORDS)
    frame = pack(records)
    back = unpack(frame[8:])
    assert [type(r) for r in back] == [type(r) for r in records]
    assert type(back[1].timing) is LoopTiming and back[1].timing == TIMING and back[2].timing is None
    for a, b in zip(records, back, strict=True):
        if type(a) is TickBlock:
            assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
        else:
            assert a == b
    with pytest.raises(TypeError, match="not a log record"):
        pack([("tick", 0)])


class _Collect:
    path = None

    def __init__(self) -> None:
        self.wire: list = []

    def put_wire(self, wire: list) -> None:
        self.wire += wire

    def close(self) -> dict:
        return {}


def test_the_recorder_builds_records_in_their_wire_form():
    sink = _Collect()
    rec = FlightRecorder(sink, offset_ns=100)
    rec.flight_start(5, controller="loc", experiment="x", ts_s=0.01, steps=3, cost=COST, origin_m=[1.0, 2.0, 0.0])
    s, c = State(*range(12)), Command(9.81, 0.0, 0.0, 0.1)
    rec.frame(6, "rig", "in", bytearray(b"\x7e\x00"))
    rec.garbage(7, "mavlink", "in", b"junk")
    rec.tick(8, 0, s, s, c, c, 3, "horizon", TIMING)
    rec.event(9, "mode", "GUIDED", custom_mode=20)
    rec.flight_end(10, s, s)
    rec.flight_metrics(11, {"J": 2})
    rec.close()
    records = [from_wire(w) for w in sink.wire]
    assert [type(r) for r in records] == [FlightStart, LinkFrame, Garbage, Tick, Event, FlightEnd, Metrics]
    start, frame, garbage, tick, event, end, metrics = records
    assert start.t_ns == 105 and start.controller == "loc" and start.flight == 0 and start.cost == COST
    assert start.extra == {"origin_m": [1.0, 2.0, 0.0]} and start.source == "flight"
    assert frame == LinkFrame(106, "rig", "in", b"\x7e\x00", True) and type(frame.data) is bytes
    assert garbage == Garbage(107, "mavlink", "in", b"junk")
    assert tick.t_ns == 108 and tick.state == tuple(s) and tick.command_limited == tuple(c) and tick.truth is None
    assert type(tick.timing) is LoopTiming and tick.timing == TIMING and (tick.steps_to_go, tick.mode) == (3, "horizon")
    assert event == Event(109, "mode", "GUIDED", {"custom_mode": 20})
    assert end == FlightEnd(110, tuple(s), tuple(s)) and metrics == Metrics(111, {"J": 2.0})
    for r in records:
        assert to_wire(r) == sink.wire[records.index(r)]


def _messages(path, topics):
    log = read_log(path, "all")
    return {t: [(ts, d.decode()) for ts, d in log.messages.get(t, [])] for t in topics}


def test_a_simulated_tick_and_a_flown_tick_make_the_same_control_messages(tmp_path):
    n = 30
    truth, est, ref = rng.normal(size=(n, 12)), rng.normal(size=(n, 12)), np.repeat(rng.normal(size=(1, 12)), n, 0)
    ref[20:] += 1.0  # a reference step
    cmd, j = rng.normal(size=(n, 4)), np.arange(n, 0, -1)
    modes = ["horizon"] * 25 + ["terminal"] * 5
    start = FlightStart(None, "nlsoc", "x", 0.01, n, "sim", cost=COST)
    paths = tmp_path / "block.mcap", tmp_path / "ticks.mcap"
    with FlightLog(paths[0]) as log:
        InlineSink(log).put_many([start, TickBlock(0, truth, est, ref, cmd, j, modes)])
    with FlightLog(paths[1]) as log:
        InlineSink(log).put_many([start] + [
            Tick(k * 10_000_000, k, tuple(est[k]), tuple(ref[k]), tuple(cmd[k]), None, int(j[k]), modes[k],
                 truth=tuple(truth[k])) for k in range(n)])
    exact = (T.FLIGHT, T.STATE, T.REFERENCE, T.ERROR, T.COMMAND, T.HORIZON, T.TRUTH)
    block, ticks = _messages(paths[0], (*exact, T.COST)), _messages(paths[1], (*exact, T.COST))
    for topic in exact:
        assert block[topic] == ticks[topic] and block[topic], topic
    # The stage cost: vectorised for a block, per tick in plain Python: equal to rounding.
    a = [json.loads(d) for _, d in block[T.COST]]
    b = [json.loads(d) for _, d in ticks[T.COST]]
    assert len(a) == len(b) == n
    for x, y in zip(a, b, strict=True):
        assert x == pytest.approx(y, rel=1e-12, abs=1e-300)


def test_the_recorder_takes_loop_timing_or_its_tuple(tmp_path):
    path = tmp_path / "t.mcap"
    rec = FlightRecorder(InlineSink(FlightLog(path)))
    rec.flight_start(0, controller="pd", experiment="x", ts_s=0.01, steps=2, cost=None)
    s, c = tuple(float(i) for i in range(12)), (9.81, 0.0, 0.0, 0.0)
    rec.tick(10, 0, s, s, c, c, 0, "pd", TIMING)
    rec.tick(20, 1, s, s, c, c, 0, "pd", tuple(TIMING))
    rec.close()
    assert rec.stats["flights"] == 1 and rec.stats["dropped"] == 0
    assert LoopTiming._fields == T.TIMING_FIELDS  # the record and the topic's fields agree
    timing = [d for _, d in read_log(path).decoded(T.TIMING)]
    assert timing[0] == dict(timing[1], k=0) == dict({"k": 0}, **TIMING._asdict())
    assert isinstance(timing[0]["deadline_missed"], bool)


def test_a_writer_far_behind_drops_and_counts(tmp_path):
    path = tmp_path / "drop.mcap"
    sink = BackgroundSink(path, max_backlog_bytes=1)  # nothing fits: every frame is dropped
    sink.put_many([Event(0, "x", "dropped"), Event(1, "x", "dropped")])
    stats = sink.close()
    assert stats["dropped"] == 2 and stats["messages"] == 0
    assert not read_log(path).truncated
    with pytest.raises(LogError, match="closed"):
        sink.put_many([Event(2, "x", "late")])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="F_SETPIPE_SZ is Linux's")
def test_a_starved_writer_backlog_waits_in_the_kernel_not_in_the_producer(tmp_path):
    """A niced writer starved of CPU: what the producer handed over sits in the enlarged pipe, so a
    SIGKILL of the producer loses none of it."""
    import fcntl

    from gcs.log.sink import PIPE_BYTES

    path = tmp_path / "starved.mcap"
    sink = BackgroundSink(path)
    fd = sink._proc.stdin.fileno()
    assert fcntl.fcntl(fd, fcntl.F_GETPIPE_SZ) >= min(PIPE_BYTES, int(open("/proc/sys/fs/pipe-max-size").read()))
    os.kill(sink._proc.pid, signal.SIGSTOP)
    try:
        n = 0
        while n < 300_000 // 40:  # ~300 kB of records: far more than a default 64 kB pipe
            sink.put_many([Event(n + i, "note", "x" * 24) for i in range(100)])
            n += 100
        assert not sink._pipe._backlog and sink.dropped == 0
    finally:
        os.kill(sink._proc.pid, signal.SIGCONT)
    stats = sink.close()
    assert stats["dropped"] == 0 and read_log(path, None).counts[T.EVENTS] == n


def test_the_writer_finishes_the_file_when_its_producer_is_killed(tmp_path):
    path = tmp_path / "orphan.mcap"
    script = textwrap.dedent(f"""
        import sys, time
        from gcs.log.records import Event, FlightStart
        from gcs.log.sink import BackgroundSink
        for overflow in ("drop", "wait"):
            sink = BackgroundSink({str(path)!r} + overflow, overflow=overflow)
            sink.put_many([FlightStart(0, "pd")] + [Event(k, "note", str(k)) for k in range(1000)])
        print("ready", flush=True)
        time.sleep(3600)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(1.0)  # "wait" frames are queued in the producer until its sender thread writes them
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    for overflow in ("drop", "wait"):
        p = tmp_path / f"orphan.mcap{overflow}"
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and (not p.exists() or read_log(p, None).truncated):
            time.sleep(0.1)
        log = read_log(p, None)
        assert not log.truncated, overflow
        assert log.counts[T.EVENTS] == 1000 and log.counts[T.FLIGHT] == 1
