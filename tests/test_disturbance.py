"""The disturbance observer (gcs/estimate.py) and the laws' compensation of a disturbance acceleration."""

import math

import numpy as np
import pytest

from gcs.config import load_config
from gcs.control import NO_DISTURBANCE, make_controller
from gcs.estimate import DisturbanceObserver, StateEstimator
from gcs.model import ModelParams, disturbance_tilt
from quadrotor.dynamics import eq1_acceleration
from quadrotor.state import Command, State

MODEL = ModelParams(1.0, 9.81)
TS = 0.01


def hover_flight(d_true, seconds, *, observer, z0=1.5, vel_bias=(0.0, 0.0, 0.0), thrust_n=9.81, start_z=None):
    """A point mass at hover thrust pushed by ``d_true``, measured every tick in position and (biased) velocity."""
    est = StateEstimator(TS, MODEL, (0.05,) * 3, 2.0, ground_z_m=None)
    est.disturbance = observer
    if observer is not None and observer.ground_z_m is None:
        observer.ground_z_m = 0.0   # it took off from z = 0
    p = [0.0, 0.0, z0 if start_z is None else start_z]
    v = [0.0, 0.0, 0.0]
    cmd = Command(thrust_n, 0.0, 0.0, 0.0)
    a = eq1_acceleration(thrust_n, 0.0, 0.0, 9.81)
    for k in range(int(seconds / TS)):
        if k:
            est.predict(TS, cmd)
        for i in range(3):
            v[i] += (a[i] + d_true[i]) * TS
            p[i] += v[i] * TS
        est.correct_position(tuple(p), (0.05 ** 2,) * 3)
        est.correct_velocity(tuple(vi + b for vi, b in zip(v, vel_bias)), (0.05 ** 2,) * 3)
    return est, p, v


def test_the_observer_converges_to_a_steady_disturbance():
    d = (0.1, -0.2, 0.6)
    est, p, v = hover_flight(d, 25.0, observer=DisturbanceObserver(2.0))
    assert est.disturbance.value == pytest.approx(list(d), abs=0.01)
    s = est.state()
    assert (s.vx, s.vy, s.vz) == pytest.approx(tuple(v), abs=0.02)   # the filters (at 15 m/s) follow it


def test_the_observer_converges_with_its_time_constant():
    obs = DisturbanceObserver(2.0)
    hover_flight((0.0, 0.0, 0.5), 2.0, observer=obs)
    # dd/dt = (d_true - d) / tau_d: about 1 - 1/e after one time constant (the filters' own lag aside)
    assert 0.4 * 0.5 < obs.value[2] < 0.8 * 0.5


def test_the_observer_does_not_learn_on_the_ground_nor_at_idle():
    obs = DisturbanceObserver(2.0)
    obs.ground_z_m = 0.0
    hover_flight((0.0, 0.0, 9.81), 10.0, observer=obs, thrust_n=0.0, z0=0.0)   # the ground holds it up
    assert obs.value == [0.0, 0.0, 0.0] and not obs.learning
    obs = DisturbanceObserver(2.0)
    obs.gate(0.0, 9.81, 9.81)
    obs.gate(0.2, 9.81, 9.81)
    assert not obs.learning               # 0.2 m above the lowest altitude seen: not yet airborne
    obs.gate(0.31, 9.81, 9.81)
    assert obs.learning
    obs.gate(1.0, 3.0, 9.81)
    assert not obs.learning               # idle thrust: not flying


def test_the_estimate_is_clipped():
    obs = DisturbanceObserver(1.0, max_m_s2=0.5)
    hover_flight((2.0, 0.0, 0.0), 10.0, observer=obs)
    assert obs.value[0] == pytest.approx(0.5)


def test_drag_is_modelled_not_estimated():
    obs = DisturbanceObserver(2.0, drag_1_s=0.25)
    obs.value = [0.1, 0.0, 0.0]
    assert obs.acceleration((0.4, -0.2, 0.0)) == pytest.approx((0.0, 0.05, 0.0))


def test_a_velocity_reading_offset_is_removed():
    """LOCAL_POSITION_NED's velocity off its position's derivative by 2 cm/s: the offset is estimated and
    the estimate's velocity follows the positions (no drift for a weak position loop to turn into error)."""
    bias = (0.02, -0.02, 0.0)
    obs = DisturbanceObserver(2.0, velocity_bias_time_constant_s=2.0)
    est, p, v = hover_flight((0.0, 0.0, 0.0), 20.0, observer=obs, vel_bias=bias)
    assert obs.velocity_bias == pytest.approx(list(bias), abs=2e-3)
    s = est.state()
    assert (s.vx, s.vy) == pytest.approx((v[0], v[1]), abs=2e-3)
    assert obs.value == pytest.approx([0.0, 0.0, 0.0], abs=0.01)     # and it is not taken for a disturbance
    plain, _, _ = hover_flight((0.0, 0.0, 0.0), 20.0, observer=None, vel_bias=bias)
    assert abs(plain.state().vx - v[0]) > 0.01                        # without it the estimate keeps the offset


def test_without_an_observer_the_estimator_reports_no_disturbance():
    est, _, _ = hover_flight((0.3, 0.0, 0.0), 2.0, observer=None)
    assert est.disturbance_m_s2() == (0.0, 0.0, 0.0)
    assert StateEstimator(TS, MODEL, (0.05,) * 3, 2.0).disturbance_m_s2() == (0.0, 0.0, 0.0)


def test_bad_observer_parameters_are_refused():
    for kw in ({"time_constant_s": 0.0}, {"time_constant_s": 1.0, "drag_1_s": -1.0},
               {"time_constant_s": 1.0, "velocity_bias_time_constant_s": 0.0}):
        with pytest.raises(ValueError):
            DisturbanceObserver(**kw)


# ---------------------------------------------------------------------- the laws

def test_disturbance_tilt_balances_eq1():
    u = 10.0
    phi, th = disturbance_tilt(u, 1.0, 9.81, 0.3, -0.2)
    ax, ay, _ = eq1_acceleration(u, phi, th, 9.81)
    assert (ax + 0.3, ay - 0.2) == pytest.approx((0.0, 0.0), abs=1e-12)
    assert disturbance_tilt(u, 1.0, 9.81, 0.0, 0.0) == (0.0, 0.0)
    assert math.sin(disturbance_tilt(u, 1.0, 9.81, 100.0, 0.0)[1]) == pytest.approx(0.5)   # clipped at 30 deg


@pytest.mark.parametrize("name", ["nlsoc", "nlsoc-literal", "loc", "pd"])
def test_zero_disturbance_changes_nothing(name):
    cfg = load_config("outdoor-circle")
    a, b = make_controller(name, cfg), make_controller(name, cfg)
    rng = np.random.default_rng(3)
    for k in range(50):
        s = State(*rng.normal(0.0, 0.2, 12))
        r = State(*rng.normal(0.0, 0.2, 12))
        assert a.step(k, s, r) == b.step(k, s, r, disturbance_m_s2=NO_DISTURBANCE)


@pytest.mark.parametrize("name", ["nlsoc", "loc", "pd"])
def test_at_the_set_point_the_laws_hold_it_against_the_disturbance(name):
    """At the reference, tilted as the disturbance needs: thrust m (g - d_z) / cos, no angular acceleration."""
    cfg = load_config("outdoor-circle")
    ctl = make_controller(name, cfg)
    d = (0.15, -0.1, 0.6)
    thrust = 9.81 - 0.6
    for _ in range(3):   # the tilt depends on the thrust and the thrust on the tilt: iterate
        phi, th = disturbance_tilt(thrust, 1.0, 9.81, d[0], d[1])
        thrust = (9.81 - 0.6) / (math.cos(phi) * math.cos(th))
    s = State(z=1.5, roll=phi, pitch=th)
    cmd = ctl.step(100, s, State(z=1.5), disturbance_m_s2=d)
    assert cmd.thrust_n == pytest.approx(thrust, rel=1e-6)
    assert (cmd.roll_accel_rad_s2, cmd.pitch_accel_rad_s2) == pytest.approx((0.0, 0.0), abs=1e-6)
    acc = eq1_acceleration(cmd.thrust_n, phi, th, 9.81)
    assert [a + di for a, di in zip(acc, d)] == pytest.approx([0.0, 0.0, 0.0], abs=1e-9)


@pytest.mark.parametrize("name", ["nlsoc", "loc", "pd"])
def test_compensated_the_closed_loop_has_no_steady_error(name):
    """Eq. 1 plus a constant disturbance, flown for 40 s: with the disturbance given the error vanishes."""
    cfg = load_config("outdoor-altitude")
    d = (0.1, -0.1, 0.6)

    def fly(dist):
        ctl = make_controller(name, cfg)
        x = np.array([0.0, 0.0, 1.0] + [0.0] * 9)
        ref = State(z=1.0)
        for k in range(4000):
            c = ctl.step(k, State(*x), ref, disturbance_m_s2=dist)
            a = eq1_acceleration(c.thrust_n, x[6], x[7], 9.81)
            acc = np.r_[np.add(a, d), [c.roll_accel_rad_s2, c.pitch_accel_rad_s2, c.yaw_accel_rad_s2]]
            x[3:6] += acc[:3] * TS
            x[9:12] += acc[3:] * TS
            x[0:3] += x[3:6] * TS
            x[6:9] += x[9:12] * TS
        return np.abs(x[:3] - [0.0, 0.0, 1.0])

    assert fly(d).max() < 0.01
    assert fly(NO_DISTURBANCE).max() > 0.03


@pytest.mark.parametrize("tau_b", [0.15, 2.0])
def test_readings_that_agree_give_no_velocity_offset_on_a_circle(tau_b):
    """Position and velocity readings of the same 1 m, 20 s circle (0.31 m/s) at 100 Hz: no offset.

    The discrete low-pass once took d/dt of the *updated* position low-pass, which reads (1 - dt/tau_b)
    of the velocity: at tau_b = 0.15 s a false offset of 6.7 % of every velocity (0.015 m/s RMS here),
    which made NLSOC fly ArduCopter's circle 8 % too wide."""
    obs = DisturbanceObserver(0.15, velocity_bias_time_constant_s=tau_b)
    w, dt, worst = 2.0 * math.pi / 20.0, 0.01, 0.0
    for k in range(4000):  # 40 s; judged once the start-up transient (~10 tau_b) has gone
        t = k * dt
        obs.advance(dt)
        obs.position_reading(0, math.cos(w * t))
        obs.position_reading(1, math.sin(w * t))
        obs.velocity_reading(0, -w * math.sin(w * t))
        obs.velocity_reading(1, w * math.cos(w * t))
        if t > 10.0 * tau_b + 5.0:
            worst = max(worst, abs(obs.velocity_bias[0]), abs(obs.velocity_bias[1]))
    assert worst < 0.003 * w  # under 0.3 % of the speed (measured 0.16 %)


def _circle_reading(obs, t, w=2.0 * math.pi / 20.0):
    obs.position_reading(0, math.cos(w * t))
    obs.position_reading(1, math.sin(w * t))
    obs.velocity_reading(0, -w * math.sin(w * t))
    obs.velocity_reading(1, w * math.cos(w * t))


def test_readings_at_half_the_loop_rate_give_no_velocity_offset():
    """50 Hz telemetry, 100 Hz loop: the low-passes step over the time between readings."""
    obs = DisturbanceObserver(0.15, velocity_bias_time_constant_s=0.15)
    worst = 0.0
    for k in range(3000):
        obs.advance(0.01)
        if k % 2 == 0:
            _circle_reading(obs, k * 0.01)
        if k > 500:
            worst = max(worst, abs(obs.velocity_bias[0]), abs(obs.velocity_bias[1]))
    # Euler over 20 ms of a curving path: 0.3 % of the speed (one step miscounted would read 6.7 %)
    assert worst < 0.005 * 2.0 * math.pi / 20.0


@pytest.mark.parametrize("how", ["drop-out", "stalled loop"])
def test_a_gap_in_the_readings_is_neither_a_velocity_offset_nor_a_disturbance(how):
    """1 s without readings on a 0.31 m/s circle: the position comes back 0.31 m on.  Taken as steady
    readings, (p - H p) / tau_b reads 2 m/s (clipped to 0.5) and the closing correction a disturbance;
    both are held across the gap instead (drop-out: no reading for > reading_gap_s; stalled loop: the
    session calls restart() and the backlog arrives before the next advance)."""
    obs = DisturbanceObserver(0.15, velocity_bias_time_constant_s=0.15)
    obs.learning = True
    k = 0
    for k in range(500):
        obs.advance(0.01)
        _circle_reading(obs, k * 0.01)
    if how == "drop-out":
        obs.advance(0.01)  # takes the last reading
        before = list(obs.velocity_bias)
        for _ in range(99):  # the loop runs on, nothing comes
            obs.advance(0.01)
            assert obs.velocity_bias == before  # held while nothing comes
        k += 101
        _circle_reading(obs, k * 0.01)
    else:
        obs.restart()
        for _ in range(100):  # the backlog, all at once
            k += 1
            _circle_reading(obs, k * 0.01)
    value = list(obs.value)
    obs.absorb(0, 0.2)  # the corrections that close the gap
    obs.absorb(1, -0.2)
    assert obs.value == value
    peak = 0.0
    for j in range(200):
        k += 1
        obs.advance(0.01)
        _circle_reading(obs, k * 0.01)
        peak = max(peak, abs(obs.velocity_bias[0]), abs(obs.velocity_bias[1]))
    # the velocity turned by 0.31 rad over the gap: a short transient of the low-passes (measured 0.020 m/s)
    # where the jump read as an offset at the clip (0.5 m/s)
    assert peak < 0.03
    assert abs(obs.velocity_bias[0]) < 0.002 and abs(obs.velocity_bias[1]) < 0.002
    obs.absorb(0, 0.15)  # and then it learns again
    assert obs.value[0] == pytest.approx(value[0] + 1.0)


def test_without_the_gap_rule_a_gap_would_read_as_a_large_offset():
    """The same drop-out under a gap threshold longer than it: the offset jumps to its clip."""
    obs = DisturbanceObserver(0.15, velocity_bias_time_constant_s=0.15, reading_gap_s=5.0)
    for k in range(500):
        obs.advance(0.01)
        _circle_reading(obs, k * 0.01)
    for _ in range(100):
        obs.advance(0.01)
    _circle_reading(obs, 600 * 0.01)
    obs.advance(0.01)
    assert max(abs(b) for b in obs.velocity_bias[:2]) == pytest.approx(0.5)


def test_a_bad_reading_gap_is_refused():
    with pytest.raises(ValueError, match="reading_gap_s"):
        DisturbanceObserver(0.15, reading_gap_s=0.0)


def test_the_mavlink_session_restarts_the_observer_on_a_backlog():
    """A drained batch with more positions than the reading gap holds at the telemetry rate (a stalled
    loop's backlog, here 50 Hz x 0.2 s = 10) restarts the observer before the telemetry takes it."""
    from types import SimpleNamespace

    from gcs.vehicles.mavlink import MavlinkSession

    class Msg:
        def __init__(self, kind):
            self.kind = kind

        def get_type(self):
            return self.kind

    obs = DisturbanceObserver(0.15, velocity_bias_time_constant_s=0.15)
    session = SimpleNamespace(estimator=SimpleNamespace(disturbance=obs),
                              config=SimpleNamespace(flight=SimpleNamespace(telemetry_rate_hz=50.0)))
    steady = [Msg("LOCAL_POSITION_NED"), Msg("ATTITUDE")] * 10
    MavlinkSession._backlog(session, steady)
    assert obs._hold == [False, False, False]
    MavlinkSession._backlog(session, steady + [Msg("LOCAL_POSITION_NED")])
    assert obs._hold == [True, True, True] and obs._gap == [True, True, True]
    session.estimator.disturbance = None
    MavlinkSession._backlog(session, steady * 5)  # no observer: nothing to do
