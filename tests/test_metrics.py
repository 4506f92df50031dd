import numpy as np
import pytest

from gcs.config import PhaseConfig
from gcs.metrics import CostSpec, FlightRecord, controller_cost, flight_metrics, summarize
from gcs.mission import Mission


def record(z, vz, thrust, ts=0.1):
    k = len(thrust)
    state = np.zeros((k + 1, 12))
    state[:, 2], state[:, 5] = z, vz
    ref = np.zeros((k + 1, 12))
    ref[:, 2] = 1.0
    cmd = np.zeros((k, 4))
    cmd[:, 0] = thrust
    cmd[:, 3] = 0.5
    return FlightRecord(ts, state, ref, cmd, np.arange(k, 0, -1))


def test_hand_computed_metrics(outdoor):
    mission = Mission([PhaseConfig("takeoff", 0.2, z_m=1.0), PhaseConfig("hold", 0.2)])
    z = np.array([0.0, 0.5, 1.2, 1.0, 1.0])
    vz = np.array([0.0, 1.0, 0.0, 0.0, 0.0])
    rec = record(z, vz, [10.0, 12.0, 8.0, 9.81])
    rec.ref[:, 2] = [0.0, 0.5, 1.0, 1.0, 1.0]       # the ramp, then the hold
    rec.ref[:2, 5] = 5.0                             # ramp velocity
    m = flight_metrics(rec, outdoor, mission, None)
    assert "J" not in m
    assert m["J_u"] == pytest.approx(10 + 12 + 8 + 9.81)
    assert m["J_u_hover"] == pytest.approx(0.19 + 2.19 + 1.81 + 0.0)
    assert m["J_u_all"] == pytest.approx(m["J_u"] + 4 * 0.5)
    # against the reference: e = [z_ref - z, vz_ref - vz]
    assert m["J_e"] == pytest.approx(5.0 + 4.0 + 0.2 + 0.0)
    # against the final set point (1 m, 0 m/s)
    assert m["J_e_setpoint"] == pytest.approx(1.0 + np.hypot(0.5, 1.0) + 0.2 + 0.0)
    assert m["overshoot_m"] == pytest.approx(0.2)
    # the hold's last second is the whole hold here: steps 2 and 3
    assert m["steady_state_error_m"] == pytest.approx(np.mean([1.0 - 1.2, 1.0 - 1.0]))


def test_a_take_off_point_above_the_origin_moves_the_set_point_with_it(outdoor):
    """PX4's altitude estimate on the ground is often 0.5 m off: the mission is flown from there, and the
    set-point metrics are those of the same flight from z = 0."""
    mission = Mission([PhaseConfig("takeoff", 0.2, z_m=1.0), PhaseConfig("hold", 0.2)])
    z, vz = np.array([0.0, 0.5, 1.2, 1.0, 1.0]), np.array([0.0, 1.0, 0.0, 0.0, 0.0])
    base, high = record(z, vz, [10.0, 12.0, 8.0, 9.81]), record(z + 0.5, vz, [10.0, 12.0, 8.0, 9.81])
    base.ref[:, 2] = [0.0, 0.5, 1.0, 1.0, 1.0]
    high.ref[:, 2] = base.ref[:, 2] + 0.5
    a, b = flight_metrics(base, outdoor, mission, None), flight_metrics(high, outdoor, mission, None)
    for name in ("overshoot_m", "J_e_setpoint", "steady_state_error_m", "J_e", "rms_error_m"):
        assert b[name] == pytest.approx(a[name]), name
    assert b["overshoot_m"] == pytest.approx(0.2)


def test_steady_state_falls_back_to_the_end_of_a_short_flight(outdoor):
    mission = Mission([PhaseConfig("takeoff", 0.2, z_m=1.0), PhaseConfig("hold", 100.0)])
    rec = record(np.array([0.0, 0.5, 0.9, 1.0, 1.0]), np.zeros(5), [9.81] * 4)
    m = flight_metrics(rec, outdoor, mission, None)
    assert m["steady_state_error_m"] == pytest.approx(np.mean(1.0 - np.array([0.0, 0.5, 0.9, 1.0])))


def test_quadratic_cost_of_eq5(outdoor):
    mission = Mission([PhaseConfig("takeoff", 0.1, z_m=1.0), PhaseConfig("hold", 1.0)])
    rec = record(np.array([0.0, 0.5, 1.0]), np.zeros(3), [9.81, 10.81])
    cost = CostSpec("loc", np.diag([2.0, 1.0]), np.array([[3.0]]), np.diag([5.0, 1.0]), horizon_steps=10)
    m = flight_metrics(rec, outdoor, mission, cost)
    expected = 0.5 * (2 * 1.0 + 2 * 0.25 + 3 * 0.0 + 3 * 1.0 ** 2) + 0.5 * 5 * 0.0
    assert m["J"] == pytest.approx(expected)
    cost1 = CostSpec("loc", np.diag([2.0, 1.0]), np.array([[3.0]]), np.diag([5.0, 1.0]), horizon_steps=1)
    assert flight_metrics(rec, outdoor, mission, cost1)["J"] == pytest.approx(0.5 * 2 * 1.0 + 0.5 * 5 * 0.25)


def test_controller_cost_kinds(outdoor):
    assert controller_cost("pd", outdoor) is None
    assert controller_cost("loc", outdoor).Q.shape == (2, 2)
    c = controller_cost("nlsoc-literal", outdoor)
    assert c.Q.shape == (4, 4) and not c.gravity_compensated


def test_summarize_mean_and_sample_std():
    s = summarize([{"J_u": 1.0}, {"J_u": 3.0}])
    assert s["J_u"] == {"mean": 2.0, "std": pytest.approx(np.sqrt(2.0))}
    assert summarize([{"J_u": 1.0}])["J_u"]["std"] == 0.0
    with pytest.raises(ValueError):
        summarize([])
