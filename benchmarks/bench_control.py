"""Controller step, gain design and in-process simulation speed (issues 2 and 7).

Run: ``python benchmarks/bench_control.py [--quick] [--json]``.  Prints

* per controller, the median time of one policy step (all four inputs; baseline:
  the PD step, the simplest law), the time to design it for the outdoor-altitude
  config (600 s horizon), and the simulated seconds per wall second of the
  closed-loop simulation (1 ms RK4 plant step, sensors, estimator and controller
  in the loop; baseline: the same flight with ideal sensors and no estimator);
* LOC gain design: :func:`gcs.control.loc.finite_horizon_lqr` for each of the
  paper's horizons (indoor 40 s, outdoor altitude 600 s, circle 60 s at 10 ms) and
  the four subsystems (z, psi, y-phi, x-theta), beside python-control's
  ``control.dlqr`` for the same A, B, Q, R: the infinite-horizon gain the
  recursion converges to.  Time of each, the steps the recursion needs to reach
  its fixed point, and the largest absolute difference between the converged
  gain (the recursion run to its fixed point) and dlqr's K.  python-control is
  optional (``pip install control``); without it the baseline is skipped.

Medians over repeated batches, so a busy machine shows up as spread, not as a
wrong median.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np

from benchlib import document, emit, met_text, row
from gcs.config import load_config
from gcs.control import CONTROLLERS, make_controller
from gcs.control.loc import finite_horizon_lqr
from quadrotor.state import State
from gcs.model import linear_psi, linear_x_theta, linear_y_phi, linear_z
from gcs.sim import SimOptions, simulate

TARGET_STEP_US = 15.0
TARGET_SIM_RATIO = 100.0
TARGET_GAIN_DIFF = 1e-8
#: The paper's three experiments, each with its own horizon.
HORIZON_CONFIGS = ("indoor-4dof", "outdoor-altitude", "outdoor-circle")
#: Steps allowed to reach the fixed point when checking the converged gain against dlqr.
CONVERGE_STEPS = 100_000


def bench_policy(config, name: str, batches: int, per_batch: int) -> float:
    """Median microseconds of one ``controller.step`` call."""
    ctl = make_controller(name, config)
    rng = np.random.default_rng(0)
    # Python floats, as the estimator hands them to the controller (numpy scalars are ~30 % slower).
    states = [State(*(rng.normal(scale=0.05, size=12) + np.r_[0, 0, 2.0, np.zeros(9)]).tolist())
              for _ in range(per_batch)]
    ref = State(z=2.0, vz=0.1)
    times = []
    for _ in range(batches):
        t0 = time.perf_counter()
        for i, s in enumerate(states):
            ctl.step(100 + i, s, ref)
        times.append((time.perf_counter() - t0) / per_batch * 1e6)
    return statistics.median(times)


def bench_design(config, name: str, repeats: int) -> float:
    """Median milliseconds to design the controller (gain tables for the config's horizon)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        make_controller(name, config)
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def bench_sim(config, name: str, duration_s: float, repeats: int, noise: bool) -> float:
    """Median simulated seconds per wall second of the closed loop (controller designed beforehand)."""
    designed = make_controller(name, config)
    ratios = []
    for r in range(repeats):
        t0 = time.perf_counter()
        simulate(config, name, run=r, options=SimOptions(duration_s=duration_s, noise=noise), designed=designed)
        ratios.append(duration_s / (time.perf_counter() - t0))
    return statistics.median(ratios)


def lqr_problems(config) -> dict[str, tuple]:
    """The four LOC subsystems of ``config``: name -> (A, B, Q, R, H)."""
    e = config.experiment
    ts, g = e.ts_s, config.vehicle.gravity_m_s2
    systems = {"z": linear_z(ts), "psi": linear_psi(ts), "y_phi": linear_y_phi(ts, g),
               "x_theta": linear_x_theta(ts, g)}
    return {name: (a, b, *config.loc[name].resolved(e.matrices)) for name, (a, b) in systems.items()}


def _fixed_point_steps(F: np.ndarray) -> int:
    """Steps the recursion ran before repeating its last gain (len(F) if it never settled)."""
    differs = np.any(F[:, 0, :] != F[-1, 0, :], axis=1)
    idx = np.flatnonzero(differs)
    return int(idx[-1]) + 2 if idx.size else 1


def bench_lqr(a, b, q, r, h, n: int, repeats: int, dlqr) -> dict:
    """Median ms of finite_horizon_lqr for horizon ``n`` and of ``dlqr`` (None: skipped);
    steps to the fixed point; max |F_converged - K_dlqr|."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        F, _ = finite_horizon_lqr(a, b, q, r, h, n)
        times.append((time.perf_counter() - t0) * 1e3)
    out = {"horizon_steps": n, "ours_ms": statistics.median(times), "steps_run": _fixed_point_steps(F),
           "dlqr_ms": None, "max_abs_diff": None, "converged_steps": None}
    out["settled_within_horizon"] = out["steps_run"] < n
    if dlqr is None:
        return out
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        K, _, _ = dlqr(a, b, q, r)
        times.append((time.perf_counter() - t0) * 1e3)
    out["dlqr_ms"] = statistics.median(times)
    # Settled within the horizon: F[-1] is the fixed point already; otherwise run on until it is.
    Fc = F if out["settled_within_horizon"] else finite_horizon_lqr(a, b, q, r, h, max(n, CONVERGE_STEPS))[0]
    out["converged_steps"] = _fixed_point_steps(Fc)
    out["max_abs_diff"] = float(np.max(np.abs(Fc[-1] - np.asarray(K))))
    out["max_abs_gain"] = float(np.max(np.abs(K)))
    return out


def load_dlqr():
    """python-control's dlqr, or None when the package is not installed."""
    try:
        import control
    except ImportError:
        return None, None
    return control.dlqr, control.__version__


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="fewer repetitions, 20 s flights")
    p.add_argument("--json", action="store_true", help="text on stderr, one JSON document on stdout")
    args = p.parse_args(argv)
    batches, per_batch, repeats = (5, 2000, 2) if args.quick else (15, 5000, 5)
    sim_s = 20.0 if args.quick else 60.0
    config = load_config("outdoor-altitude")
    ctl_rows = []
    for name in CONTROLLERS:
        step_us = bench_policy(config, name, batches, per_batch)
        ratio = bench_sim(config, name, sim_s, repeats, noise=True)
        ratio_ideal = bench_sim(config, name, sim_s, repeats, noise=False)
        design_ms = bench_design(config, name, repeats)
        ctl_rows.append({"controller": name, "policy_step_median_us": step_us, "design_median_ms": design_ms,
                         "sim_realtime_ratio_noisy": ratio, "sim_realtime_ratio_ideal": ratio_ideal})

    dlqr, control_version = load_dlqr()
    lqr = []
    for cname in HORIZON_CONFIGS:
        cfg = load_config(cname)
        for sub, (a, b, q, r, h) in lqr_problems(cfg).items():
            res = bench_lqr(a, b, q, r, h, cfg.experiment.horizon_steps, repeats, dlqr)
            lqr.append({"config": cname, "horizon_s": cfg.experiment.horizon_s, "subsystem": sub, **res})

    data = {"config": "outdoor-altitude", "sim_duration_s": sim_s, "controllers": ctl_rows, "lqr": lqr,
            "python_control": control_version, "numpy": np.__version__}
    pd_step = next(r["policy_step_median_us"] for r in ctl_rows if r["controller"] == "pd")
    rows = []
    for r in ctl_rows:
        rows.append(row(f"policy step, {r['controller']}", r["policy_step_median_us"], "us",
                        baseline="pd policy step", baseline_value=pd_step, target=f"<= {TARGET_STEP_US:g} us",
                        met=r["policy_step_median_us"] <= TARGET_STEP_US))
    for r in ctl_rows:
        worst = min(r["sim_realtime_ratio_noisy"], r["sim_realtime_ratio_ideal"])
        rows.append(row(f"in-process simulation, {r['controller']} (x real time)", r["sim_realtime_ratio_noisy"], "x",
                        baseline="ideal sensors, no estimator", baseline_value=r["sim_realtime_ratio_ideal"],
                        target=f">= {TARGET_SIM_RATIO:g}x", met=worst >= TARGET_SIM_RATIO))
    for cname in HORIZON_CONFIGS:
        sel = [x for x in lqr if x["config"] == cname]
        ours = sum(x["ours_ms"] for x in sel)
        theirs = sum(x["dlqr_ms"] for x in sel) if dlqr is not None else None
        rows.append(row(f"LOC gain design, {cname} ({sel[0]['horizon_s']:g} s horizon, 4 subsystems)", ours, "ms",
                        baseline="control.dlqr" if dlqr else "control.dlqr (skipped: pip install control)",
                        baseline_value=theirs))
        if dlqr is not None:
            diff = max(x["max_abs_diff"] for x in sel)
            rows.append(row(f"max |F converged - K dlqr|, {cname}", diff, "", target=f"<= {TARGET_GAIN_DIFF:g}",
                            met=diff <= TARGET_GAIN_DIFF))

    lines = [f"python {sys.version.split()[0]}, numpy {np.__version__}; outdoor-altitude config (600 s horizon), "
             f"{sim_s:g} s flights, 1 ms plant step; medians",
             f"{'controller':<14} {'policy step [us]':>17} {'design [ms]':>12} "
             f"{'sim x real time (sensors+estimator)':>37} {'sim x real time (ideal)':>25}"]
    for r in ctl_rows:
        lines.append(f"{r['controller']:<14} {r['policy_step_median_us']:>17.2f} {r['design_median_ms']:>12.1f} "
                     f"{r['sim_realtime_ratio_noisy']:>37.0f} {r['sim_realtime_ratio_ideal']:>25.0f}")
    worst_step = max(r["policy_step_median_us"] for r in ctl_rows)
    worst_sim = min(min(r["sim_realtime_ratio_noisy"], r["sim_realtime_ratio_ideal"]) for r in ctl_rows)
    lines.append(f"target policy step <= {TARGET_STEP_US:g} us: worst {worst_step:.2f} us "
                 f"-> {met_text(worst_step <= TARGET_STEP_US)}")
    lines.append(f"target simulation >= {TARGET_SIM_RATIO:g}x real time: worst {worst_sim:.0f}x "
                 f"-> {met_text(worst_sim >= TARGET_SIM_RATIO)}")
    lines.append("")
    lines.append("LOC gain design: finite_horizon_lqr (Riccati recursion, stops at its fixed point) beside "
                 + (f"control.dlqr (python-control {control_version})" if dlqr else "control.dlqr")
                 + f"; median of {repeats}")
    if dlqr is None:
        lines.append("control.dlqr: skipped: pip install control")
    lines.append(f"{'config':<17} {'subsystem':<8} {'N':>6} {'steps run':>9} {'ours [ms]':>10} {'dlqr [ms]':>10} "
                 f"{'ours/dlqr':>9} {'to fixed pt':>11} {'max|F-K|':>10}")
    for x in lqr:
        have = x["dlqr_ms"] is not None
        lines.append(f"{x['config']:<17} {x['subsystem']:<8} {x['horizon_steps']:>6} {x['steps_run']:>9} "
                     f"{x['ours_ms']:>10.1f} " + (f"{x['dlqr_ms']:>10.2f} {x['ours_ms'] / x['dlqr_ms']:>8.0f}x "
                                                  f"{x['converged_steps']:>11} {x['max_abs_diff']:>10.1e}"
                                                  if have else f"{'-':>10} {'-':>9} {'-':>11} {'-':>10}"))
    unsettled = [f"{x['config']} {x['subsystem']}" for x in lqr if not x["settled_within_horizon"]]
    if unsettled:
        lines.append(f"not at the fixed point within the horizon (the whole horizon is computed): "
                     f"{', '.join(unsettled)}")
    emit(document("control", args.quick, data, rows), "\n".join(lines), args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
