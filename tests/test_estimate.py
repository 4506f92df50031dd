import numpy as np
import pytest

from gcs.estimate import StateEstimator, kalman_gain_cv
from gcs.model import Command, ModelParams


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
