"""Controller and in-process simulation speed (issue 2).

Run: ``python benchmarks/bench_control.py [--quick]``.  Prints, per controller,
the median time of one policy step (all four inputs) and the simulated seconds
per wall second of the closed-loop simulation (1 ms RK4 plant step, sensors,
estimator and controller in the loop).  Medians over repeated batches, so a
busy machine shows up as spread, not as a wrong median.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time

import numpy as np

from gcs.config import load_config
from gcs.control import CONTROLLERS, make_controller
from gcs.model import State
from gcs.sim import SimOptions, simulate

TARGET_STEP_US = 15.0
TARGET_SIM_RATIO = 100.0


def bench_policy(config, name: str, batches: int, per_batch: int) -> float:
    """Median microseconds of one ``controller.step`` call."""
    ctl = make_controller(name, config)
    rng = np.random.default_rng(0)
    states = [State(*(rng.normal(scale=0.05, size=12) + np.r_[0, 0, 2.0, np.zeros(9)])) for _ in range(per_batch)]
    ref = State(z=2.0, vz=0.1)
    times = []
    for b in range(batches):
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


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="fewer repetitions")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    batches, per_batch, repeats = (5, 2000, 2) if args.quick else (15, 5000, 5)
    config = load_config("outdoor-altitude")
    rows = []
    for name in CONTROLLERS:
        step_us = bench_policy(config, name, batches, per_batch)
        ratio = bench_sim(config, name, 60.0, repeats, noise=True)
        ratio_ideal = bench_sim(config, name, 60.0, repeats, noise=False)
        design_ms = bench_design(config, name, repeats)
        rows.append({"controller": name, "policy_step_median_us": step_us, "design_median_ms": design_ms,
                     "sim_realtime_ratio_noisy": ratio, "sim_realtime_ratio_ideal": ratio_ideal})
    if args.json:
        print(json.dumps(rows))
        return 0
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}; outdoor-altitude config (600 s horizon), "
          f"60 s flights, 1 ms plant step; medians")
    print(f"{'controller':<14} {'policy step [us]':>17} {'design [ms]':>12} {'sim x real time (sensors+estimator)':>37} {'sim x real time (ideal)':>25}")
    for r in rows:
        print(f"{r['controller']:<14} {r['policy_step_median_us']:>17.2f} {r['design_median_ms']:>12.1f} "
              f"{r['sim_realtime_ratio_noisy']:>37.0f} {r['sim_realtime_ratio_ideal']:>25.0f}")
    worst_step = max(r["policy_step_median_us"] for r in rows)
    worst_sim = min(min(r["sim_realtime_ratio_noisy"], r["sim_realtime_ratio_ideal"]) for r in rows)
    print(f"target policy step <= {TARGET_STEP_US:g} us: worst {worst_step:.2f} us "
          f"-> {'met' if worst_step <= TARGET_STEP_US else 'MISSED'}")
    print(f"target simulation >= {TARGET_SIM_RATIO:g}x real time: worst {worst_sim:.0f}x "
          f"-> {'met' if worst_sim >= TARGET_SIM_RATIO else 'MISSED'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
