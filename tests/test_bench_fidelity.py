"""benchmarks/bench_fidelity.py: the medians of repeated flights it compares (--repeats)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
bench_fidelity = pytest.importorskip("bench_fidelity")


def _flight(rms, overshoot, liftoff=0.37, exit_reason="completed"):
    return {"rms_error_m": rms, "J_e": 100.0 * rms, "J_u_hover": 1500.0, "overshoot_m": overshoot,
            "liftoff_s": liftoff, "exit_reason": exit_reason, "wall_s": 30.0}


def test_each_metric_is_the_median_with_its_spread():
    out = bench_fidelity.median_flight([_flight(0.045, 0.005), _flight(0.044, 0.0039), _flight(0.046, 0.0043)])
    assert out["rms_error_m"] == pytest.approx(0.045)
    assert out["overshoot_m"] == pytest.approx(0.0043)
    assert out["spread"]["overshoot_m"] == pytest.approx((0.0039, 0.005))
    assert out["exit_reason"] == "completed" and out["wall_s"] == pytest.approx(90.0)


def test_a_missing_metric_or_a_different_exit_is_not_hidden():
    out = bench_fidelity.median_flight([_flight(0.045, 0.005, liftoff=None),
                                        _flight(0.044, 0.004, exit_reason="landed")])
    assert out["liftoff_s"] is None and "liftoff_s" not in out["spread"]
    assert out["exit_reason"] == "completed/landed"


def test_one_flight_is_its_own_median():
    f = _flight(0.03, 0.004)
    out = bench_fidelity.median_flight([f])
    assert all(out[k] == f[k] for k, _ in bench_fidelity.METRICS)
