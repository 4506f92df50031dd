"""Link emulation (baud, loss, latency), clocks and the stream scheduler."""

from __future__ import annotations

import math
import random

import pytest
from pymavlink import mavutil
from sitl_testkit import Gcs

from quadrotor.clock import ManualClock, MonotonicClock
from sitl.copter.streams import StreamScheduler
from sitl.net.radio import RadioLink, RadioParams, RadioPipe

M = mavutil.mavlink
MS = 1_000_000


def test_baud_limit_serialises_chunks():
    pipe = RadioPipe(RadioParams(baud=57600, queue_bytes=10000), random.Random(0))
    for i in range(10):
        assert pipe.push(i, b"x" * 576, 0)          # 576 bytes = 100 ms at 57600 baud (10 bits/byte)
    assert pipe.pop_ready(99 * MS) == []
    assert [k for k, _ in pipe.pop_ready(100 * MS)] == [0]
    assert pipe.next_event_ns() == 200 * MS
    assert [k for k, _ in pipe.pop_ready(1000 * MS)] == list(range(1, 10))
    assert pipe.next_event_ns() is None


def test_latency_and_idle_line():
    pipe = RadioPipe(RadioParams(baud=0, latency_s=0.03), random.Random(0))
    pipe.push("a", b"abc", 5 * MS)
    assert pipe.pop_ready(34 * MS) == [] and pipe.next_event_ns() == 35 * MS
    assert pipe.pop_ready(35 * MS) == [("a", b"abc")]


def test_queue_overflow_drops():
    pipe = RadioPipe(RadioParams(baud=9600, queue_bytes=600), random.Random(0))
    assert pipe.push(1, b"x" * 500, 0)
    assert not pipe.push(2, b"x" * 200, 0)
    assert pipe.dropped == 1


def test_loss_is_seeded():
    def lost(seed):
        link = RadioLink(RadioParams(loss=0.2), seed)
        out = []
        for i in range(2000):
            out.append(link.down.push(i, b"frame", 0))
            link.down.pop_ready(0)
        return out
    a, b = lost(1), lost(1)
    assert a == b and a != lost(2)
    assert a.count(False) == pytest.approx(400, rel=0.15)


def test_radio_params_validation():
    for bad in (dict(baud=-1), dict(loss=1.5), dict(latency_s=-0.1), dict(latency_s=math.inf),
                dict(latency_s=math.nan), dict(queue_bytes=10)):
        with pytest.raises(ValueError):
            RadioParams(**bad)
    assert not RadioParams().active and RadioParams(baud=57600).active


def test_clocks():
    c = ManualClock(5)
    assert c.now_ns() == 5
    c.advance(0.5)
    assert c.now_ns() == 500_000_005
    with pytest.raises(ValueError):
        c.advance(-1)
    m = MonotonicClock()
    assert m.now_ns() <= m.now_ns()


def test_stream_scheduler():
    s = StreamScheduler()
    assert s.due(0) == [] and s.due(1000 * MS) == [M.MAVLINK_MSG_ID_HEARTBEAT]
    assert s.set_interval_us(M.MAVLINK_MSG_ID_ATTITUDE, 10_000, 0)
    assert not s.set_interval_us(9999, 10_000, 0)
    got = sum(M.MAVLINK_MSG_ID_ATTITUDE in s.due(t * 2_500_000) for t in range(1, 401))
    assert got == 100                                 # 100 Hz over 1 s of 400 Hz ticks
    assert s.interval_us(M.MAVLINK_MSG_ID_ATTITUDE) == 10_000
    s.set_interval_us(M.MAVLINK_MSG_ID_ATTITUDE, -1, 0)
    assert s.interval_us(M.MAVLINK_MSG_ID_ATTITUDE) == -1 and s.interval_us(9999) == 0
    s.set_interval_us(M.MAVLINK_MSG_ID_VFR_HUD, 0, 0)                  # 0 = default rate
    assert s.interval_us(M.MAVLINK_MSG_ID_VFR_HUD) == 250_000
    assert s.set_group_rate(M.MAV_DATA_STREAM_POSITION, 5, 0)
    assert s.interval_us(M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT) == 200_000
    assert s.set_group_rate(M.MAV_DATA_STREAM_ALL, 0, 0)
    assert s.interval_us(M.MAVLINK_MSG_ID_LOCAL_POSITION_NED) == -1
    assert not s.set_group_rate(99, 5, 0)


def test_lossy_latent_link_in_lockstep(make_server, make_gcs):
    srv = make_server(radio=RadioParams(baud=115200, latency_s=0.005, loss=0.0))
    gcs = make_gcs(srv)
    gcs.start_lockstep_streams()
    for _ in range(20):
        gcs.step(0.5)
    assert srv.snapshot()["steps"] == 20
    lossy = make_server(radio=RadioParams(loss=0.5), seed=9)
    g2 = Gcs(lossy.connection_string, hello=False)
    try:
        for _ in range(40):
            g2.conn.mav.param_request_read_send(1, 1, b"GUID_TIMEOUT", -1)
        g2.recv(timeout=0.3, cond=lambda m: False)
    finally:
        g2.close()
    c = lossy.snapshot()["counters"]
    assert c["lost_in"] + c["lost_out"] > 10
    assert 0 < len(g2.log.get("PARAM_VALUE", [])) < 40
