"""Campaign throughput: ``gcs campaign`` beside the same flights in-process (issue 7).

Run: ``python benchmarks/bench_campaign.py [--quick] [--json]`` (``--json``: the text
on stderr, one JSON document on stdout, see ``benchlib.py``).  Prints "skipped: gcs
campaign not available" and exits 0 when this ``gcs`` has no ``campaign`` command.

* A small campaign, ``gcs campaign --experiment all --runs 1 --controllers C
  --duration-scale F --no-figures`` (C = nlsoc,loc and F = 0.1 with ``--quick``, all
  four controllers and F = 0.25 without), flown with ``--workers 1`` and with
  ``--workers 2``: simulated vehicle-seconds per wall second of the flights (the
  ``timing`` of its ``campaign.json``), and the wall time of the whole command.
* Baseline: the same experiments, controllers, runs and mission lengths flown
  in-process by :func:`gcs.sim.run_experiment` (what ``gcs sim`` does: the reduced
  plant, sensors, estimator and controller in one loop; no SITL, no MAVLink, no
  process per flight), vehicle-seconds per wall second.
* Extrapolation to the full paper campaign, 3 experiments x 4 controllers x 10 runs
  with outdoor-altitude cut to 120 s and the 60 s circle and indoor missions whole,
  against the 10-minute target.  Per experiment, from the small campaign's runs: a
  run costs ``overhead + flown / speed``, where ``speed`` is the mission loop's
  lockstep speed (``loop.realtime_ratio`` of the run's summary), ``overhead`` the rest
  of the run's wall time (process and SITL start, preflight, design) and ``flown``
  the full mission plus the measured landing tail; the runs' wall times add up,
  divided by the parallel speed-up the small campaign showed (sum of run wall times
  / flights' wall time), plus the command's fixed cost (planning, optimality tables,
  report).  The in-process baseline extrapolates the same way (design time + flights
  at the measured speed, one process).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchlib import document, emit, met_text, row

#: The full paper campaign: experiment -> mission seconds flown per run (before landing).
PAPER_CAMPAIGN_S = {"indoor-4dof": 60.0, "outdoor-altitude": 120.0, "outdoor-circle": 60.0}
PAPER_CONTROLLERS = 4
PAPER_RUNS = 10
TARGET_WALL_S = 600.0


def campaign_available() -> bool:
    p = subprocess.run([sys.executable, "-m", "gcs.cli", "campaign", "--help"], capture_output=True, text=True)
    return p.returncode == 0 and "--workers" in p.stdout


def run_campaign(out: Path, controllers: str, scale: float, workers: int) -> dict:
    """One ``gcs campaign`` command; its timing, plan durations and runs (with their summaries)."""
    argv = [sys.executable, "-m", "gcs.cli", "campaign", "--experiment", "all", "--runs", "1",
            "--controllers", controllers, "--duration-scale", str(scale), "--workers", str(workers),
            "--no-figures", "-q", "--out", str(out)]
    t0 = time.perf_counter()
    p = subprocess.run(argv, capture_output=True, text=True)
    command_wall = time.perf_counter() - t0
    if p.returncode not in (0, 1):
        raise SystemExit(f"gcs campaign failed ({p.returncode}): {p.stderr[-800:]}")
    doc = json.loads((out / "campaign.json").read_text())
    runs = json.loads((out / "runs.json").read_text())
    for r in runs:
        try:
            r["summary"] = json.loads(Path(r["summary_path"]).read_text())
        except (OSError, TypeError, ValueError):
            r["summary"] = None
    return {"workers": workers, "command_wall_s": command_wall, "timing": doc["timing"],
            "durations_s": doc["plan"]["durations_s"], "runs": runs, "last_line": p.stdout.strip().splitlines()[-1:]}


def extrapolate(c: dict) -> dict:
    """Wall seconds of the full paper campaign from one small campaign (model in the module docstring)."""
    ok = [r for r in c["runs"] if r["status"] == "ok" and r["summary"] and r["summary"].get("loop")]
    if not ok:
        raise SystemExit("gcs campaign: no run completed, nothing to extrapolate from")
    speedup = sum(r["wall_s"] for r in ok) / c["timing"]["wall_s"]
    per_exp = {}
    for exp, full_s in PAPER_CAMPAIGN_S.items():
        rs = [r for r in ok if r["experiment"] == exp]
        if not rs:
            continue
        speed = statistics.median(r["summary"]["loop"]["realtime_ratio"] for r in rs)
        overhead = statistics.median(r["wall_s"] - r["summary"]["loop"]["wall_s"] for r in rs)
        tail = statistics.median(r["flown_s"] - c["durations_s"][exp] for r in rs)
        run_wall = overhead + (full_s + tail) / speed
        per_exp[exp] = {"lockstep_speed": speed, "overhead_s": overhead, "landing_tail_s": tail,
                        "full_run_wall_s": run_wall, "runs_wall_s": PAPER_CONTROLLERS * PAPER_RUNS * run_wall}
    fixed = c["command_wall_s"] - c["timing"]["wall_s"]
    total = fixed + sum(e["runs_wall_s"] for e in per_exp.values()) / speedup
    return {"parallel_speedup": speedup, "fixed_s": fixed, "experiments": per_exp, "wall_s": total,
            "vehicle_s": sum(PAPER_CONTROLLERS * PAPER_RUNS * (s + per_exp[e]["landing_tail_s"])
                             for e, s in PAPER_CAMPAIGN_S.items() if e in per_exp)}


def in_process(controllers: list[str], durations: dict[str, float]) -> dict:
    """The same flights through gcs.sim.run_experiment; throughput and the full-campaign extrapolation."""
    from gcs.config import load_config
    from gcs.control import make_controller
    from gcs.sim import SimOptions, run_experiment

    out = {"experiments": {}}
    wall = vehicle = full = 0.0
    for exp, dur in durations.items():
        config = load_config(exp)
        t0 = time.perf_counter()
        run_experiment(config, controllers, runs=1, options=SimOptions(duration_s=dur))
        w = time.perf_counter() - t0
        design = 0.0
        for name in controllers:  # run_experiment designs each controller once: timed apart for the model
            t0 = time.perf_counter()
            make_controller(name, config)
            design += time.perf_counter() - t0
        v = len(controllers) * dur
        speed = v / max(w - design, 1e-9)
        full_exp = design / len(controllers) * PAPER_CONTROLLERS + \
            PAPER_CONTROLLERS * PAPER_RUNS * PAPER_CAMPAIGN_S[exp] / speed
        out["experiments"][exp] = {"wall_s": w, "design_s": design, "vehicle_s": v, "flight_speed": speed,
                                   "full_wall_s": full_exp}
        wall, vehicle, full = wall + w, vehicle + v, full + full_exp
    out.update(wall_s=wall, vehicle_s=vehicle, throughput=vehicle / wall, full_wall_s=full)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two controllers, missions cut to a tenth")
    ap.add_argument("--json", action="store_true", help="text on stderr, one JSON document on stdout")
    args = ap.parse_args(argv)
    if not campaign_available():
        emit(document("campaign", args.quick, {}, [], skipped="gcs campaign not available"),
             "skipped: gcs campaign not available", args.json)
        return 0
    controllers = "nlsoc,loc" if args.quick else "nlsoc,nlsoc-literal,loc,pd"
    scale = 0.1 if args.quick else 0.25
    d: dict = {"controllers": controllers, "duration_scale": scale, "campaigns": {}, "extrapolation": {}}
    with tempfile.TemporaryDirectory(prefix="bench_campaign_") as tmp:
        for w in (1, 2):
            c = run_campaign(Path(tmp) / f"w{w}", controllers, scale, w)
            d["extrapolation"][w] = extrapolate(c)
            for r in c["runs"]:
                r.pop("summary", None)
            d["campaigns"][w] = c
    durations = d["campaigns"][1]["durations_s"]
    base = d["in_process"] = in_process(controllers.split(","), durations)
    tp = {w: d["campaigns"][w]["timing"]["throughput"] for w in (1, 2)}
    rows = []
    for w in (1, 2):
        t = d["campaigns"][w]["timing"]
        rows.append(row(f"gcs campaign --workers {w} (vehicle-s per wall s)", tp[w], "x",
                        baseline="in-process gcs.sim.run_experiment", baseline_value=base["throughput"],
                        note=f"{t['runs']} flights, {t['failed']} failed"))
    rows.append(row("gcs campaign --workers 2 beside --workers 1 (vehicle-s per wall s; ratio = speed-up)", tp[2], "x",
                    baseline="--workers 1", baseline_value=tp[1]))
    for w in (1, 2):
        e = d["extrapolation"][w]
        rows.append(row(f"full paper campaign (120 flights), --workers {w}: wall", e["wall_s"], "s",
                        baseline="in-process, one process", baseline_value=base["full_wall_s"],
                        target=f"<= {TARGET_WALL_S:g} s", met=e["wall_s"] <= TARGET_WALL_S))

    lines = [f"small campaign: 3 experiments x {controllers} x 1 run, missions x{scale:g} "
             f"({', '.join(f'{k} {v:g} s' for k, v in durations.items())})"]
    for w in (1, 2):
        c = d["campaigns"][w]
        t = c["timing"]
        lines.append(f"  --workers {w}: {t['runs']} flights ({t['failed']} failed), {t['vehicle_s']:.0f} vehicle-s in "
                     f"{t['wall_s']:.1f} s of flights = {tp[w]:.2f} vehicle-s per wall s; whole command "
                     f"{c['command_wall_s']:.1f} s")
    lines.append(f"  baseline, the same flights in-process (gcs.sim.run_experiment): "
                 f"{base['vehicle_s']:.0f} vehicle-s in "
                 f"{base['wall_s']:.1f} s = {base['throughput']:.1f} vehicle-s per wall s "
                 f"(campaign at {tp[1] / base['throughput']:.2f} / {tp[2] / base['throughput']:.2f} of it)")
    lines.append(f"full paper campaign: 3 experiments x {PAPER_CONTROLLERS} controllers x {PAPER_RUNS} runs "
                 f"({', '.join(f'{k} {v:g} s' for k, v in PAPER_CAMPAIGN_S.items())}); target <= {TARGET_WALL_S:g} s")
    lines.append(f"  {'experiment':<17} {'lockstep x RT':>13} {'overhead/run':>13} {'landing':>8} {'wall/run':>9} "
                 f"{'40 runs':>8}   (--workers 2)")
    for exp, e in d["extrapolation"][2]["experiments"].items():
        lines.append(f"  {exp:<17} {e['lockstep_speed']:>12.1f}x {e['overhead_s']:>12.1f}s "
                     f"{e['landing_tail_s']:>7.1f}s {e['full_run_wall_s']:>8.1f}s {e['runs_wall_s']:>7.0f}s")
    for w in (1, 2):
        e = d["extrapolation"][w]
        lines.append(f"  --workers {w}: parallel speed-up {e['parallel_speedup']:.2f}, fixed {e['fixed_s']:.1f} s -> "
                     f"~{e['wall_s']:.0f} s ({e['wall_s'] / 60:.1f} min) -> {met_text(e['wall_s'] <= TARGET_WALL_S)}")
    lines.append(f"  baseline in-process (one process): ~{base['full_wall_s']:.0f} s "
                 f"({base['full_wall_s'] / 60:.1f} min)")
    emit(document("campaign", args.quick, d, rows), "\n".join(lines), args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
