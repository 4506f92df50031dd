import numpy as np
import pytest

from gcs.estimate import StateEstimator, kalman_gain_cv
from quadrotor.state import Command
from gcs.model import ModelParams


def test_gain_is_a_stable_alpha_beta_pair():
    kp, kv = kalman_gain_cv(0.01, 2.0, 0.05)
    assert 0 < kp < 1 and 0 < kv < 2 * (2 - kp) / 0.01
    with pytest.raises(ValueError):
        kalman_gain_cv(0.0, 1.0, 1.0)


def test_tracks_a_climb_from_quantised_altitude_without_lag():
    rng = np.random.default_rng(0)
    ts, model = 0.01, ModelParams()
    est = StateEstimator(ts, model, (0.05, 0.05, np.sqrt(0.05 ** 2 + 0.1 ** 2 / 12)), 2.0)
    hover = Command(model.hover_thrust_n, 0, 0, 0)
    errs = []
    for k in range(3000):
        z, vz = 1.0 + 0.5 * k * ts, 0.5
        reading = (0.0, 0.0, round((z + rng.normal(0, 0.05)) / 0.1) * 0.1, 0, 0, 0, 0, 0, 0)
        s = est.update(reading, hover)
        if k > 500:
            errs.append((s.z - z, s.vz - vz))
    errs = np.array(errs)
    assert abs(errs[:, 0].mean()) < 0.01 and abs(errs[:, 1].mean()) < 0.02
    assert errs[:, 0].std() < 0.05 and errs[:, 1].std() < 0.15


def test_never_estimates_below_ground():
    est = StateEstimator(0.01, ModelParams(), (0.01, 0.01, 0.01), 1.0)
    for _ in range(100):
        s = est.update((0, 0, 0.0, 0, 0, 0, 0, 0, 0), Command(0.0, 0, 0, 0))
    assert s.z >= 0.0 and s.vz >= 0.0


def test_filter_converges_to_the_steady_state_gain():
    from gcs.estimate import AxisFilter
    f = AxisFilter(2.0)
    for _ in range(5000):
        f.predict(0.01, 0.0)
        ppp, ppv = f.ppp, f.ppv
        f.correct_position(0.0, 0.05 ** 2)
    kp, kv = ppp / (ppp + 0.05 ** 2), ppv / (ppp + 0.05 ** 2)
    assert (kp, kv) == pytest.approx(kalman_gain_cv(0.01, 2.0, 0.05), rel=1e-6)


def test_slow_position_and_velocity_readings_are_fused():
    est = StateEstimator(0.01, ModelParams(), (0.05, 0.05, 0.05), 1.0)
    hover = Command(9.81, 0, 0, 0)
    for k in range(1000):
        t = k * 0.01
        est.predict(0.01, hover)
        if k % 5 == 0:  # 20 Hz position/velocity at 100 Hz control
            est.correct_position((0.5 * t, 0.0, 1.0))
            est.correct_velocity((0.5, 0.0, 0.0), (0.01, 0.01, 0.01))
    s = est.state()
    assert s.x == pytest.approx(0.5 * 9.99, abs=0.05) and s.vx == pytest.approx(0.5, abs=0.05)
