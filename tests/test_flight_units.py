"""Units of the flight stack: telemetry decoding, clocks, loop statistics (output adapters: test_output_adapters.py)."""

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.estimate import StateEstimator
from quadrotor.clock import ManualClock
from gcs.flight.stats import LoopStats
from gcs.vehicles.telemetry import Telemetry
from gcs.model import ModelParams

MAV = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)


def packed(msg):
    """The message as received: packed, so that it carries its source system and component."""
    msg.pack(MAV)
    return msg


def test_telemetry_is_converted_to_the_paper_frame():
    est = StateEstimator(0.01, ModelParams(), (0.05,) * 3, 1.0)
    events = []
    tel = Telemetry(est, (1e-6,) * 3, (1e-6,) * 3, on_event=lambda k, t: events.append((k, t)))
    tel.handle(packed(MAV.local_position_ned_encode(100, 1.0, 2.0, -3.0, 0.1, 0.2, -0.5)), 0)
    tel.handle(packed(MAV.attitude_encode(100, 0.1, -0.2, 0.3, 0.0, 0.0, 0.0)), 0)
    tel.handle(packed(MAV.local_position_ned_encode(110, 1.0, 2.0, -3.0, 0.1, 0.2, -0.5)), 10_000_000)
    s = est.state()
    assert (s.x, s.y, s.z) == pytest.approx((1.0, 2.0, 3.0), abs=1e-3)
    assert s.vz == pytest.approx(0.5, abs=1e-3) and s.roll == pytest.approx(0.1) and s.pitch == pytest.approx(-0.2)
    tel.handle(packed(MAV.heartbeat_encode(2, 3, mavlink.MAV_MODE_FLAG_SAFETY_ARMED | 1, 20, 4)), 0)
    assert tel.status.armed and tel.status.mode == "GUIDED_NOGPS"
    assert ("arming", "armed") in events and ("mode", "GUIDED_NOGPS") in events
    tel.handle(packed(MAV.statustext_encode(4, b"Arm: not level")), 0)
    assert ("statustext", "Arm: not level") in events
    assert tel.fresh(100_000_000, 0.3) and not tel.fresh(500_000_000, 0.3)


def test_body_rates_become_euler_rates():
    est = StateEstimator(0.01, ModelParams(), (0.05,) * 3, 1.0)
    tel = Telemetry(est)
    tel.handle(packed(MAV.attitude_encode(0, 0.3, 0.4, 0.0, 0.0, 1.0, 0.0)), 0)
    s = est.state()
    assert s.roll_rate == pytest.approx(math.sin(0.3) * math.tan(0.4))
    assert s.pitch_rate == pytest.approx(math.cos(0.3))


def test_loop_stats_and_manual_clock():
    clock = ManualClock()
    clock.sleep_until_ns(5)
    assert clock.now_ns() == 5
    st = LoopStats(10_000_000)
    for j in (0, 100_000, 20_000_000):
        st.record(j, {"decode": 1000, "estimate": 2000, "control": 3000, "send": 4000})
    s = st.summary()
    assert s["ticks"] == 3 and s["deadline_misses"] == 1
    assert s["tick_p50_ms"] == pytest.approx(0.01)


def test_messages_from_another_component_are_not_the_autopilot():
    est = StateEstimator(0.01, ModelParams(), (0.05,) * 3, 1.0)
    tel = Telemetry(est)
    companion = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    hb = companion.heartbeat_encode(18, 8, mavlink.MAV_MODE_FLAG_SAFETY_ARMED, 9, 4)
    hb.pack(companion)
    tel.handle(hb, 0)
    assert not tel.status.armed and tel.status.custom_mode == -1
