"""``gcs fly`` against the built-in SITL: flight speed and where a tick goes (issues 4 and 7).

Run: ``python benchmarks/bench_fly.py [--quick] [--json]``.

* Lockstep: the outdoor-circle mission with NLSOC and the whole ground station in
  the loop (``gcs fly --sitl lockstep --summary FILE -q``; the SITL is a separate
  process, as a real autopilot would be), once with the flight log
  (``--log``, the default behaviour of gcs fly) and once with ``--no-log``, for
  seeds 0..2 (seed 0 and a 20 s mission cut, ``--duration 20``, with ``--quick``).
  Simulated seconds per wall second of the mission loop (target >= 25x, flights
  with a log), beside the baseline of the same mission and controller flown
  in-process by :func:`gcs.sim.simulate` (reduced plant, no link, no SITL).
* Tick breakdown, from the summaries' ``loop.<stage>_p50_ms`` / ``_p99_ms``: decode
  (drain the link, telemetry into the estimator; in lockstep mostly done while the
  clock waits for the vehicle's step, so the wall time per tick, ``loop.wall_s /
  ticks``, is also shown beside the tick's work), estimate (predict), control
  (failsafe checks, reference, controller, safety envelope), send (output adapter,
  encode, send), log (hand the tick to the writer process); medians over the
  flights.  Baselines measured here: the estimator's predict and the controller's
  ``step`` alone, and the tick of the flight without a log for the logging cost.
  ``bench_link.py`` has the bare MAVLink encode/decode of the same messages.
* Real time (not with ``--quick``): the full 60 s mission flown in real time;
  deadline misses, wake-up jitter and the tick breakdown.  Targets: 0 misses,
  jitter p99 <= 1 ms, tick p99 <= 1 ms.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

from benchlib import document, emit, met_text, row

STAGES = ("decode", "estimate", "control", "send", "log")
CONFIG = "outdoor-circle"
CONTROLLER = "nlsoc"
TARGET_LOCKSTEP = 25.0


def fly(*args: str) -> dict:
    """One ``gcs fly`` run; its ``--summary`` document."""
    with tempfile.TemporaryDirectory(prefix="bench_fly_") as d:
        path = os.path.join(d, "s.json")
        extra = [] if "--no-log" in args else ["--log", os.path.join(d, "f.mcap")]
        p = subprocess.run([sys.executable, "-m", "gcs.cli", "fly", "-q", "--summary", path, "--config", CONFIG,
                            "--controller", CONTROLLER, *extra, *args], capture_output=True, text=True)
        if p.returncode != 0:
            raise SystemExit(f"gcs fly failed ({p.returncode}): {p.stderr[-500:]}")
        with open(path) as fh:
            return json.load(fh)


def med(docs: list[dict], key: str) -> float:
    return statistics.median(d["loop"][key] for d in docs)


def in_process(duration_s: float, repeats: int) -> float:
    """Median simulated s per wall s of the same mission flown by gcs.sim.simulate (designed beforehand)."""
    from gcs.config import load_config
    from gcs.control import make_controller
    from gcs.sim import SimOptions, simulate

    config = load_config(CONFIG)
    designed = make_controller(CONTROLLER, config)
    ratios = []
    for r in range(repeats):
        t0 = time.perf_counter()
        simulate(config, CONTROLLER, run=r, options=SimOptions(duration_s=duration_s), designed=designed)
        ratios.append(duration_s / (time.perf_counter() - t0))
    return statistics.median(ratios)


def bare_stages(n: int = 3000) -> dict:
    """Median ms of the estimator's predict + state() and of the controller's step, alone in this process."""
    import numpy as np

    from gcs.config import load_config
    from gcs.control import make_controller, model_params
    from gcs.estimate import StateEstimator
    from quadrotor.state import Command, State

    config = load_config(CONFIG)
    ctl = make_controller(CONTROLLER, config)
    est = StateEstimator(config.experiment.ts_s, model_params(config), (0.05, 0.05, 0.05), 1.0)
    est.correct_position((0.0, 0.0, 1.5))
    rng = np.random.default_rng(0)
    cmds = [Command(9.81 + 0.1 * a, 0.1 * b, 0.1 * c, 0.0) for a, b, c in rng.normal(size=(n, 3)).tolist()]
    refs = [State(z=1.5 + 0.01 * a, x=0.01 * b) for a, b in rng.normal(size=(n, 2)).tolist()]
    t_est, t_ctl = [], []
    for k in range(n):
        t0 = time.perf_counter_ns()
        est.predict(0.01, cmds[k])
        s = est.state()
        t1 = time.perf_counter_ns()
        ctl.step(k, s, refs[k])
        t2 = time.perf_counter_ns()
        t_est.append(t1 - t0)
        t_ctl.append(t2 - t1)
    return {"estimate": statistics.median(t_est) / 1e6, "control": statistics.median(t_ctl) / 1e6}


def breakdown_lines(title: str, cols: dict[str, dict]) -> list[str]:
    """A stage table: one column pair (p50, p99 in us) per named set of loop figures."""
    head = f"  {'stage':<9}" + "".join(f" {name + ' p50':>16} {'p99':>8}" for name in cols)
    lines = [title, head]
    for stage in STAGES + ("tick",):
        lines.append(f"  {stage:<9}" + "".join(f" {lp[stage + '_p50_ms'] * 1000:>14.1f}us"
                                               f" {lp[stage + '_p99_ms'] * 1000:>6.0f}us"
                                               for lp in cols.values()))
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one seed, 20 s missions, no real-time flight")
    ap.add_argument("--json", action="store_true", help="text on stderr, one JSON document on stdout")
    args = ap.parse_args(argv)
    seeds = (0,) if args.quick else (0, 1, 2)
    cut = ("--duration", "20") if args.quick else ()
    logged, plain = [], []
    for seed in seeds:
        logged.append(fly("--sitl", "lockstep", "--seed", str(seed), *cut))
        plain.append(fly("--sitl", "lockstep", "--seed", str(seed), "--no-log", *cut))
    duration = statistics.median(d["duration_s"] for d in logged)
    keys = [f"{s}_{q}_ms" for s in STAGES + ("tick",) for q in ("p50", "p99")]
    d = {"config": CONFIG, "controller": CONTROLLER, "seeds": list(seeds), "duration_s": duration,
         "lockstep_ratio_log": med(logged, "realtime_ratio"), "lockstep_ratio_no_log": med(plain, "realtime_ratio"),
         "lockstep_ratios_log": [x["loop"]["realtime_ratio"] for x in logged],
         "loop_log": {k: med(logged, k) for k in keys}, "loop_no_log": {k: med(plain, k) for k in keys}}
    # In lockstep a tick's wall time is its work plus the wait for the vehicle's step (the SITL's
    # physics, the round trip, and the telemetry decoded while waiting).
    d["wall_per_tick_us_log"] = statistics.median(x["loop"]["wall_s"] / x["loop"]["ticks"] * 1e6 for x in logged)
    d["wall_per_tick_us_no_log"] = statistics.median(x["loop"]["wall_s"] / x["loop"]["ticks"] * 1e6 for x in plain)
    d["in_process_ratio"] = in_process(duration, len(seeds) + 1)
    d["in_process_wall_per_tick_us"] = 0.01 / d["in_process_ratio"] * 1e6
    d["bare_ms"] = bare_stages()
    lo, ln = d["loop_log"], d["loop_no_log"]
    rows = [
        row("lockstep gcs fly, with log (x real time)", d["lockstep_ratio_log"], "x",
            baseline="in-process gcs.sim.simulate", baseline_value=d["in_process_ratio"],
            target=f">= {TARGET_LOCKSTEP:g}x", met=d["lockstep_ratio_log"] >= TARGET_LOCKSTEP),
        row("lockstep gcs fly, --no-log (x real time)", d["lockstep_ratio_no_log"], "x",
            baseline="in-process gcs.sim.simulate", baseline_value=d["in_process_ratio"]),
        row("lockstep wall time per tick, with log", d["wall_per_tick_us_log"], "us",
            baseline="in-process gcs.sim.simulate", baseline_value=d["in_process_wall_per_tick_us"],
            note=f"tick work p50 {lo['tick_p50_ms'] * 1000:.0f} us, the rest waits for the SITL"),
        row("lockstep tick p50, with log", lo["tick_p50_ms"] * 1000, "us",
            baseline="tick p50 --no-log", baseline_value=ln["tick_p50_ms"] * 1000),
        row("lockstep tick p99, with log", lo["tick_p99_ms"] * 1000, "us",
            baseline="tick p99 --no-log", baseline_value=ln["tick_p99_ms"] * 1000),
        row("lockstep estimate stage p50 (--no-log)", ln["estimate_p50_ms"] * 1000, "us",
            baseline="estimator predict alone", baseline_value=d["bare_ms"]["estimate"] * 1000),
        row("lockstep control stage p50 (--no-log)", ln["control_p50_ms"] * 1000, "us",
            baseline="controller.step alone", baseline_value=d["bare_ms"]["control"] * 1000),
    ]
    lines = [f"lockstep, {CONFIG} {duration:g} s, {CONTROLLER}, whole GCS in the loop, "
             f"seeds {', '.join(map(str, seeds))}: "
             f"median {d['lockstep_ratio_log']:.1f}x real time with the log "
             f"(runs {', '.join(f'{r:.1f}' for r in d['lockstep_ratios_log'])}), "
             f"{d['lockstep_ratio_no_log']:.1f}x --no-log; "
             f"target >= {TARGET_LOCKSTEP:g}x -> {met_text(d['lockstep_ratio_log'] >= TARGET_LOCKSTEP)}",
             f"baseline, the same mission in-process (gcs.sim.simulate, no link): "
             f"{d['in_process_ratio']:.1f}x real time "
             f"-> lockstep flight at {d['lockstep_ratio_log'] / d['in_process_ratio']:.2f} of it",
             f"wall time per tick {d['wall_per_tick_us_log']:.0f} us with the log "
             f"({d['wall_per_tick_us_no_log']:.0f} us "
             f"--no-log; in-process {d['in_process_wall_per_tick_us']:.0f} us): the tick's own work (p50 "
             f"{lo['tick_p50_ms'] * 1000:.0f} us) is "
             f"{lo['tick_p50_ms'] * 1000 / d['wall_per_tick_us_log']:.0%} of it, the rest "
             f"is the wait for the SITL's step (its physics, the round trip; telemetry is decoded while waiting)",
             *breakdown_lines("lockstep tick breakdown (median over flights of each flight's p50 / p99):",
                              {"with log": lo, "--no-log": ln}),
             f"  baselines alone in this process: estimator predict {d['bare_ms']['estimate'] * 1000:.1f} us, "
             f"{CONTROLLER} step {d['bare_ms']['control'] * 1000:.1f} us; logging adds "
             f"{(lo['tick_p50_ms'] - ln['tick_p50_ms']) * 1000:+.1f} us to the tick p50"]
    if not args.quick:
        doc = fly("--sitl", "realtime")
        lp = doc["loop"]
        d["realtime"] = {k: lp[k] for k in ("ticks", "deadline_misses", "jitter_p50_ms", "jitter_p99_ms", *keys)}
        ok = lp["deadline_misses"] == 0 and lp["jitter_p99_ms"] <= 1.0 and lp["tick_p99_ms"] <= 1.0
        rows += [row("real time: deadline misses", lp["deadline_misses"], "", target="0",
                     met=lp["deadline_misses"] == 0),
                 row("real time: jitter p99", lp["jitter_p99_ms"], "ms", target="<= 1 ms",
                     met=lp["jitter_p99_ms"] <= 1.0),
                 row("real time: tick p99", lp["tick_p99_ms"], "ms", baseline="lockstep tick p99 with log",
                     baseline_value=lo["tick_p99_ms"], target="<= 1 ms", met=lp["tick_p99_ms"] <= 1.0)]
        lines += [f"real time, {doc['duration_s']:g} s: {lp['ticks']} ticks, {lp['deadline_misses']} deadline misses, "
                  f"jitter p50 {lp['jitter_p50_ms']:.3f} ms p99 {lp['jitter_p99_ms']:.3f} ms, "
                  f"tick p50 {lp['tick_p50_ms']:.3f} ms p99 {lp['tick_p99_ms']:.3f} ms",
                  *breakdown_lines("real-time tick breakdown:", {"real time": lp}),
                  f"targets 0 misses, jitter p99 <= 1 ms, tick p99 <= 1 ms -> {met_text(ok)}"]
    emit(document("fly", args.quick, d, rows), "\n".join(lines), args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
