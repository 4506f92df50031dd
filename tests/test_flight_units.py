"""Units of the flight stack: output adapters, telemetry decoding, clocks, loop statistics."""

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.estimate import StateEstimator
from quadrotor.clock import ManualClock
from gcs.vehicles.output import OutputAdapter, OutputModel
from gcs.flight.stats import LoopStats
from gcs.vehicles.telemetry import Telemetry
from quadrotor.frames import quaternion_to_euler
from quadrotor.state import Command, State
from gcs.model import ModelParams

MAV = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)


def packed(msg):
    """The message as received: packed, so that it carries its source system and component."""
    msg.pack(MAV)
    return msg


def model(kind, **kw):
    args = dict(kind=kind, mass_kg=1.0, gravity_m_s2=9.81, hover_throttle=0.4, inertia_kg_m2=(0.01, 0.01, 0.02),
                max_torque_nm=(2.0, 2.0, 0.2), rate_gain_1_s=(25.0, 25.0, 10.0), angle_gain_1_s=(4.5, 4.5, 4.5))
    args.update(kw)
    return OutputModel(**args)


def test_thrust_normalisation_uses_the_hover_throttle():
    m = model("attitude")
    assert m.thrust_norm(9.81) == pytest.approx(0.4)
    assert m.thrust_norm(2 * 9.81) == pytest.approx(0.8)
    assert m.thrust_norm(100.0) == 1.0 and m.thrust_norm(-1.0) == 0.0


def test_actuator_controls_are_torques_over_their_maximum():
    a = OutputAdapter(model("actuator"), MAV)
    f = a.fields(State(z=1.0), Command(9.81, 50.0, -100.0, 5.0))
    assert f["message"] == "SET_ACTUATOR_CONTROL_TARGET"
    assert f["controls"][:4] == pytest.approx([0.01 * 50 / 2.0, 0.01 * -100 / 2.0, 0.02 * 5 / 0.2, 0.4])
    assert a.fields(State(), Command(9.81, 1e4, 0, 0))["controls"][0] == 1.0
    msg = packed(a.encode(f, 1234))
    assert msg.get_type() == "SET_ACTUATOR_CONTROL_TARGET" and msg.group_mlx == 0


def test_rates_output_adds_the_acceleration_over_the_rate_gain():
    a = OutputAdapter(model("rates"), MAV)
    f = a.fields(State(roll_rate=0.1), Command(9.81, 5.0, -2.5, 1.0))
    assert f["type_mask"] == 128
    assert f["body_rates"] == pytest.approx([0.1 + 5.0 / 25, -2.5 / 25, 1.0 / 10])
    assert math.fsum(c * c for c in f["q"]) == pytest.approx(1.0)


def test_attitude_output_leads_by_one_period_and_feeds_forward():
    a = OutputAdapter(model("attitude"), MAV)
    s = State(roll=0.1, roll_rate=0.5)
    cmd = Command(9.81, 20.0, 0.0, 0.0)
    f = a.fields(s, cmd)
    assert f["type_mask"] == 0
    roll_t = quaternion_to_euler(f["q"])[0]
    assert roll_t == pytest.approx(0.1 + 0.5 * 0.01 + 0.5 * 20.0 * 0.01 ** 2, abs=1e-9)
    # The autopilot's rate demand K_a e + ff equals omega + alpha / K_r.
    e = roll_t - 0.1
    assert 4.5 * e + f["body_rates"][0] == pytest.approx(0.5 + 20.0 / 25.0, rel=1e-3)


def test_output_model_is_checked():
    with pytest.raises(ValueError, match="hover_throttle"):
        model("attitude", hover_throttle=1.2)
    with pytest.raises(ValueError, match="output"):
        model("torque")


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
