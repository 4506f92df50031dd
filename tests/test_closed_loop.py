"""Closed-loop flights of every controller on the in-process simulation (config sensor noise, calm air)."""

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

from gcs.control import make_controller
from quadrotor.state import Command, State
from gcs.sim import SimOptions, run_experiment, simulate

CONTROLLERS = ["nlsoc", "loc", "pd"]


def window(run, t0, t1):
    t = run.record.time_s
    return run.record.state[(t >= t0) & (t < t1), 2]


@pytest.mark.parametrize("name", CONTROLLERS)
def test_outdoor_holds_2_m(outdoor, name):
    run = simulate(outdoor, name, options=SimOptions(duration_s=40.0))
    hold = window(run, 15.0, 40.0)
    assert abs(hold[-500:].mean() - 2.0) < 0.03          # last 5 s
    assert np.abs(hold - 2.0).max() < 0.10
    assert run.metrics["overshoot_m"] < 0.10
    assert abs(run.metrics["steady_state_error_m"]) < 0.03


def test_outdoor_literal_nlsoc_sags_about_12_cm(outdoor):
    run = simulate(outdoor, "nlsoc-literal", options=SimOptions(duration_s=40.0))
    sag = 2.0 - window(run, 35.0, 40.0).mean()
    assert 0.08 < sag < 0.16                              # notes: about 0.12 m
    assert run.metrics["steady_state_error_m"] > 0.08
    calm = simulate(outdoor, "nlsoc-literal", options=SimOptions(duration_s=40.0, noise=False))
    assert 2.0 - calm.record.state[-1, 2] == pytest.approx(0.118, abs=0.003)


@pytest.mark.parametrize("name,bound", [("nlsoc", 0.03), ("pd", 0.03), ("loc", 0.08)])
def test_indoor_holds_30_cm(indoor, name, bound):
    # LOC's eq. 21 weights are light (closed-loop period about 30 s): a wider bound, stated here.
    run = simulate(indoor, name)
    assert np.abs(window(run, 20.0, 40.0) - 0.30).max() < bound      # within the optimal horizon
    assert abs(window(run, 55.0, 60.0).mean() - 0.30) < 0.01          # after the handover to PD
    assert (run.record.steps_to_go[4000:] == 0).all() if name != "pd" else True


def test_indoor_literal_nlsoc_cannot_lift_off(indoor):
    run = simulate(indoor, "nlsoc-literal")
    assert window(run, 0.0, 40.0).max() < 0.005           # F2 ~ 0.01 N << m g
    assert run.record.command[:4000, 0].max() < 1.0
    assert abs(window(run, 55.0, 60.0).mean() - 0.30) < 0.01  # PD lifts it after the horizon


def _circle_error(run, t0, t1):
    t, s, r = run.record.time_s, run.record.state, run.record.ref
    m = (t > t0) & (t < t1)
    return np.hypot(s[m, 0] - r[m, 0], s[m, 1] - r[m, 1])


@pytest.mark.parametrize("name", CONTROLLERS)
def test_circle_is_tracked_and_the_vehicle_lands(circle, name):
    run = simulate(circle, name, options=SimOptions(noise=False))
    assert _circle_error(run, 12.0, 48.0).max() < 0.25
    assert run.record.state[-1, 2] < 0.05


@pytest.mark.parametrize("name", CONTROLLERS)
def test_the_reference_acceleration_fed_forward_shrinks_the_circle_lag(circle, name):
    """The centripetal acceleration enters the laws as a disturbance -a_ref does: the tilt the law
    holds turns the vehicle with the reference.  Attitude references at 0 (the paper's, the option
    off) leave a steady lag on the circle, LOC's the largest (its lateral loop is slow)."""
    literal = dataclasses.replace(circle, experiment=dataclasses.replace(circle.experiment,
                                                                         acceleration_reference=False))
    opts = SimOptions(noise=False, duration_s=40.0)
    fed = _circle_error(simulate(circle, name, options=opts), 30.0, 40.0)
    lag = _circle_error(simulate(literal, name, options=opts), 30.0, 40.0)
    assert fed.mean() < 0.8 * lag.mean()     # measured 30-40 s: nlsoc 0.72, loc 0.57, pd 0.54
    if name == "loc":
        assert lag.mean() > 0.15          # measured 0.176 m: the tilt LOC penalises is the one the circle needs


def test_nlsoc_tracks_the_circle_best_in_calm_air(circle):
    res = run_experiment(circle, ["nlsoc", "loc", "pd"], runs=1, options=SimOptions(noise=False))
    je = {n: res.summary[n]["J_e"]["mean"] for n in res.per_run}
    assert je["nlsoc"] < je["pd"] < je["loc"]


@pytest.mark.parametrize("after", ["terminal", "restart"])
def test_after_horizon_policies_keep_flying(outdoor, after):
    exp = dataclasses.replace(outdoor.experiment, horizon_s=5.0, after_horizon=after)
    cfg = dataclasses.replace(outdoor, experiment=exp)
    run = simulate(cfg, "nlsoc", options=SimOptions(duration_s=25.0))
    assert abs(window(run, 20.0, 25.0).mean() - 2.0) < 0.05
    j = run.record.steps_to_go
    if after == "terminal":
        assert (j[500:] == 1).all()
    else:
        assert j[500] == 500 and j[999] == 1 and j[1000] == 500


def test_same_seed_same_flight_and_seeds_differ(outdoor):
    opts = SimOptions(duration_s=12.0, wind=True)
    a = simulate(outdoor, "loc", seed=3, options=opts)
    b = simulate(outdoor, "loc", seed=3, options=opts)
    c = simulate(outdoor, "loc", seed=4, options=opts)
    np.testing.assert_array_equal(a.record.state, b.record.state)
    assert not np.array_equal(a.record.state, c.record.state)
    assert a.metrics == b.metrics


def test_controllers_reset_and_share_the_interface(outdoor):
    for name in ("nlsoc", "nlsoc-literal", "loc", "pd"):
        ctl = make_controller(name, outdoor)
        cmd = ctl.step(0, State(), State())
        assert isinstance(cmd, Command) and all(np.isfinite(cmd))
        assert 0.0 <= cmd.thrust_n <= outdoor.vehicle.max_thrust_n
        ctl.reset()


def test_cli_json_schema():
    p = subprocess.run([sys.executable, "-m", "gcs.cli", "sim", "--config", "indoor-4dof", "--controller", "all",
                        "--runs", "2", "--duration", "5", "--json", "--no-log"],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)
    assert doc["experiment"] == "indoor-4dof" and doc["runs"] == 2 and doc["duration_s"] == 5.0
    assert set(doc["results"]) == {"nlsoc", "nlsoc-literal", "loc", "pd"}
    for name, metrics in doc["results"].items():
        for key in ("J_u", "J_u_all", "J_e", "J_e_setpoint", "steady_state_error_m", "overshoot_m"):
            assert set(metrics[key]) == {"mean", "std"}
            assert isinstance(metrics[key]["mean"], float)
    assert "J" not in doc["results"]["pd"] and "J" in doc["results"]["loc"]


def test_loc_terminal_policy_is_the_one_step_gain(outdoor):
    # "terminal" keeps the last step's law: for LOC F(1) = (R + B'HB)^-1 B'HA, which with
    # eq. 23's H has no position feedback (documented in the README).
    exp = dataclasses.replace(outdoor.experiment, horizon_s=1.0, after_horizon="terminal")
    ctl = make_controller("loc", dataclasses.replace(outdoor, experiment=exp))
    far = ctl.step(500, State(z=1.0), State(z=2.0))
    near = ctl.step(501, State(z=1.9), State(z=2.0))
    assert far.thrust_n == pytest.approx(near.thrust_n) == pytest.approx(9.81)
    restart = make_controller("loc", dataclasses.replace(outdoor,
                                                         experiment=dataclasses.replace(exp, after_horizon="restart")))
    assert restart.step(100, State(z=1.0), State(z=2.0)).thrust_n > 20.0


def test_cli_rejects_short_durations_and_printed_matrices_fly():
    p = subprocess.run([sys.executable, "-m", "gcs.cli", "sim", "--config", "indoor-4dof", "--duration", "0.004"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "duration" in p.stderr and "Traceback" not in p.stderr
    p = subprocess.run([sys.executable, "-m", "gcs.cli", "sim", "--config", "outdoor-altitude", "--controller", "nlsoc",
                        "--matrices", "printed", "--runs", "1", "--duration", "2", "--json", "--no-log"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    p = subprocess.run([sys.executable, "-m", "gcs.cli", "sim", "--config", "indoor-4dof", "--wind", "--duration", "1"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "describes no wind" in p.stderr


def test_cli_table():
    p = subprocess.run([sys.executable, "-m", "gcs.cli", "sim", "--config", "outdoor-altitude", "--controller", "pd",
                        "--runs", "1", "--duration", "3", "-q", "--no-log"],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert "outdoor-altitude: 1 run(s) x 3 s" in p.stdout and "J_e = sum||e||" in p.stdout
