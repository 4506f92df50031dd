"""benchmarks/ekf_dataflash_fit.py: it recovers the EKF error model from a synthetic log made with known values."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
fit = pytest.importorskip("ekf_dataflash_fit")
pytest.importorskip("scipy")

KV, KP, KG, LAG_S, LIFTOFF_S = 1.3, 1.2, 2.7, 0.05, 4.0


def _lag(t, x, tau):
    y = np.empty_like(x)
    y[0] = x[0]
    a = 1.0 - np.exp(-np.diff(t, prepend=t[0]) / tau)
    for i in range(1, len(x)):
        y[i] = y[i - 1] + a[i] * (x[i] - y[i - 1])
    return y


def synthetic_log() -> dict[str, np.ndarray]:
    """Arming at 10 s, a steady AHRS tilt error of 0.12/0.09 deg, liftoff 4 s later, a 1 m circle; the
    EKF = the truth's position lagged + the model's errors, the velocity + the velocity error."""
    t = np.arange(10.0, 40.0, 0.0025)  # the truth at 400 Hz
    up = t >= 10.0 + LIFTOFF_S
    w = np.where(up, t - 10.0 - LIFTOFF_S, 0.0)
    truth_n, truth_e = np.sin(0.5 * w), 1.0 - np.cos(0.5 * w)
    truth_vn, truth_ve = np.where(up, 0.5 * np.cos(0.5 * w), 0.0), np.where(up, 0.5 * np.sin(0.5 * w), 0.0)
    truth_d = np.where(up, -0.1 - 0.5 * w, -0.1)
    truth = np.column_stack([t, truth_n, truth_e, truth_vn, truth_ve, truth_d])
    att_t = np.arange(10.0, 40.0, 0.04)
    att = np.column_stack([att_t, np.full_like(att_t, 0.12), np.full_like(att_t, 0.09)])
    sim = np.column_stack([att_t, np.zeros_like(att_t), np.zeros_like(att_t)])
    d = {"truth": truth, "att": att, "sim": sim}
    a_n, a_e = fit.false_acceleration(d, t)
    err = np.zeros((len(t), 4))  # e_pN, e_pE, e_vN, e_vE
    for axis, a in enumerate((a_n, a_e)):
        ev, ep = a[0] / KG, 0.0
        for i in range(len(t)):
            if not up[i]:
                ev, ep = a[i] / KG, 0.0
            err[i, axis], err[i, 2 + axis] = ep, ev
            dt = 0.0025
            if up[i]:
                ev, ep = ev + dt * (a[i] - KV * ev), ep + dt * (ev - KP * ep)
    ekf_n = _lag(t, truth_n, LAG_S) + err[:, 0]
    ekf_e = _lag(t, truth_e, LAG_S) + err[:, 1]
    k = slice(None, None, 10)  # the EKF at 40 Hz
    d["ekf"] = np.column_stack([t, ekf_n, ekf_e, truth_vn + err[:, 2], truth_ve + err[:, 3], truth_d])[k]
    return d


def test_the_fit_recovers_the_liftoff_the_ground_gain_and_the_flight_model():
    d = synthetic_log()
    assert fit.liftoff_time(d) == pytest.approx(10.0 + LIFTOFF_S, abs=0.02)
    assert fit.ground_velocity_gain(d) == pytest.approx(KG, rel=1e-3)
    t, err, a_n, a_e = fit.prepare(d)
    assert t[0] >= 10.0 + LIFTOFF_S and err[0, 0] == 0.0 and err[0, 1] == 0.0
    (kv, kp, lag), rms, no_lag = fit.fit_horizontal([(t, err, (a_n, a_e), d["truth"])])
    assert kv == pytest.approx(KV, rel=0.05)
    assert kp == pytest.approx(KP, rel=0.05)
    assert lag == pytest.approx(LAG_S, rel=0.05)
    assert rms < 0.2 * no_lag  # the lag explains most of what the error model alone leaves


def test_a_log_that_never_lifts_off_is_a_clear_error():
    d = synthetic_log()
    d["truth"][:, 5] = -0.1
    with pytest.raises(SystemExit, match="never left the ground"):
        fit.liftoff_time(d)


def test_the_false_acceleration_is_g_times_the_earth_frame_tilt():
    d = synthetic_log()
    a_n, a_e = fit.false_acceleration(d, np.array([12.0]))
    c, s = math.cos(math.radians(fit.HEADING_DEG)), math.sin(math.radians(fit.HEADING_DEG))
    north, east = math.radians(c * 0.12 - s * 0.09), math.radians(s * 0.12 + c * 0.09)
    assert a_n[0] == pytest.approx(-fit.G * east) and a_e[0] == pytest.approx(fit.G * north)
