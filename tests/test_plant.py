import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.integrate import solve_ivp

from quadrotor.state import State
from quadrotor.plant import ReducedParams, hover_thrust_n, step
from quadrotor.sensors import SensorParams, Sensors
from quadrotor.wind import Wind, WindParams

P = ReducedParams(drag_n_per_m_s=0.0)


def airborne(**kw):
    return State(z=kw.pop("z", 10.0), **kw)


def test_hover_is_an_equilibrium():
    s = airborne()
    for _ in range(100):
        s = step(s, (hover_thrust_n(P), 0, 0, 0), 0.01, P)
    assert s.z == pytest.approx(10.0, abs=1e-9) and s.vz == pytest.approx(0.0, abs=1e-9)


def test_free_fall_is_exact():
    s = step(airborne(vz=1.0), (0.0, 0, 0, 0), 1.0, P)
    assert s.z == pytest.approx(10.0 + 1.0 - 0.5 * 9.81, rel=1e-12)
    assert s.vz == pytest.approx(1.0 - 9.81, rel=1e-12)


def test_rk4_matches_a_tight_reference_integration_with_tilt_and_drag():
    params = ReducedParams(drag_n_per_m_s=0.3)
    s0 = airborne(vx=0.5, roll=0.1, pitch=-0.2, roll_rate=0.5, pitch_rate=-0.3, yaw_rate=0.1)
    u = (11.0, 2.0, -1.5, 0.5)
    wind = (1.0, -2.0, 0.2)
    m, g, c = params.mass_kg, params.gravity_m_s2, params.drag_n_per_m_s

    def f(t, x):
        phi, th = x[6], x[7]
        acc = [-u[0] * math.sin(th) / m, u[0] * math.cos(th) * math.sin(phi) / m,
               u[0] * math.cos(th) * math.cos(phi) / m - g]
        acc = [a + c / m * (w - v) for a, w, v in zip(acc, wind, x[3:6])]
        return list(x[3:6]) + acc + list(x[9:12]) + list(u[1:])

    ref = solve_ivp(f, (0, 0.5), list(s0), rtol=1e-12, atol=1e-12).y[:, -1]
    s = s0
    for _ in range(50):
        s = step(s, u, 0.01, params, wind)
    np.testing.assert_allclose(s, ref, rtol=1e-8, atol=1e-9)


def test_stays_on_the_ground_below_hover_thrust_and_lifts_above():
    s = State()
    for _ in range(50):
        s = step(s, (0.9 * hover_thrust_n(P), 3.0, 3.0, 3.0), 0.01, P)
    assert s == State()
    for _ in range(50):
        s = step(s, (1.2 * hover_thrust_n(P), 0, 0, 0), 0.01, P)
    assert s.z > 0.05 and s.vz > 0


def test_touchdown_stops_and_levels():
    s = State(z=0.05, vz=-1.0, vx=1.0, roll=0.1, roll_rate=1.0)
    s = step(s, (0.0, 0, 0, 0), 0.2, P)
    assert s.z == 0.0 and s.vz == 0.0 and s.vx == 0.0 and s.roll == 0.0 and s.roll_rate == 0.0


def test_inputs_saturate():
    params = ReducedParams(max_thrust_n=20.0, max_angular_accel_rad_s2=10.0, drag_n_per_m_s=0.0)
    a = step(airborne(), (1e6, 1e6, -1e6, 0), 0.01, params)
    b = step(airborne(), (20.0, 10.0, -10.0, 0), 0.01, params)
    assert a == b


def test_drag_gives_the_wind_speed_at_steady_state():
    params = ReducedParams(drag_n_per_m_s=0.5)
    s = airborne()
    for _ in range(3000):
        s = step(s, (hover_thrust_n(params), 0, 0, 0), 0.01, params, (2.0, -1.0, 0.0))
    assert s.vx == pytest.approx(2.0, abs=1e-3) and s.vy == pytest.approx(-1.0, abs=1e-3)


def test_bad_step_arguments():
    with pytest.raises(ValueError, match="dt"):
        step(State(), (0, 0, 0, 0), 0.0, P)
    with pytest.raises(ValueError, match="mass_kg"):
        ReducedParams(mass_kg=-1)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-50, 50), st.floats(-500, 500), st.floats(-500, 500), st.floats(-500, 500)),
                min_size=1, max_size=40))
def test_never_below_ground_nor_nan(commands):
    s = State(z=0.5)
    for c in commands:
        s = step(s, c, 0.01, ReducedParams())
        assert s.z >= 0.0
        assert all(math.isfinite(v) for v in s)


def test_wind_is_seeded_and_has_its_statistics():
    w1 = Wind(WindParams(mean_speed_m_s=2.0, direction_deg=90.0, gust_std_m_s=0.5, gust_tau_s=1.0),
              np.random.default_rng(3))
    w2 = Wind(WindParams(mean_speed_m_s=2.0, direction_deg=90.0, gust_std_m_s=0.5, gust_tau_s=1.0),
              np.random.default_rng(3))
    a = np.array([w1.sample(0.01) for _ in range(20000)])
    b = np.array([w2.sample(0.01) for _ in range(20000)])
    np.testing.assert_array_equal(a, b)
    assert a[:, 1].mean() == pytest.approx(2.0, abs=0.15)
    assert a[:, 0].std() == pytest.approx(0.5, rel=0.3)


def test_sensors_quantise_altitude():
    s = Sensors(SensorParams(altitude="ultrasonic", altitude_resolution_m=0.04), np.random.default_rng(0))
    m = s.measure(State(z=0.317))
    assert m.z == pytest.approx(0.32)
    assert m[:2] == (0.0, 0.0)
    with pytest.raises(ValueError, match="altitude"):
        SensorParams(altitude="lidar")
