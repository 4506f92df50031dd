"""Run every benchmark in this folder and write the report: ``python benchmarks/run.py [--quick]``.

Each ``bench_*.py`` runs in its own process (so one's imports and caches do not
skew another's) with ``--json`` (and ``--quick`` when given): its text arrives on
stderr and one JSON document on stdout (``benchlib.py``).  Written to
``benchmarks/results/``:

* ``latest.txt``: the machine, then every benchmark's text output;
* ``latest.json``: the machine and every benchmark's document;
* ``REPORT.md``: a table per benchmark (figure, baseline, ratio, target, met or
  missed), a breakdown of a ``gcs fly`` tick beside its parts measured alone, and
  the machine: CPU count, Python, load average at the start and the end, date,
  whether ``--quick`` was used.

The benchmarks time things; nothing asserts on a time.  On a shared machine the
load average tells how far to trust the figures.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: Report order; any other bench_*.py found follows.
ORDER = ("control", "fly", "link", "sitl", "log", "campaign", "rig", "firmware", "autopilots", "fidelity", "robustness")
TITLES = {"control": "Controller step and gain design (bench_control.py)",
          "fly": "gcs fly: lockstep speed and the loop tick (bench_fly.py)",
          "link": "Link overhead: MavlinkLink vs raw pymavlink (bench_link.py)",
          "sitl": "SITL speed vs the in-process loop (bench_sitl.py)",
          "log": "Logging cost and log review time (bench_log.py)",
          "campaign": "Campaign throughput (bench_campaign.py)",
          "rig": "Indoor rig protocol and emulator (bench_rig.py)",
          "firmware": "ArduCopter SITL in the loop: reliable speed-up (bench_firmware.py)",
          "autopilots": "The same flights on the built-in SITL, ArduCopter and PX4 (bench_autopilots.py)",
          "fidelity": "sitl --emulate arducopter vs ArduCopter SITL: metrics and step responses (bench_fidelity.py)",
          "robustness": "Non-nominal vehicles beside the autopilot's own position controller (bench_robustness.py)"}


def benches(only: list[str] | None) -> list[Path]:
    found = {p.stem[len("bench_"):]: p for p in HERE.glob("bench_*.py")}
    names = [n for n in ORDER if n in found] + sorted(n for n in found if n not in ORDER)
    if only:
        names = [n for n in names if n in only]
    return [found[n] for n in names]


def machine(quick: bool) -> dict:
    def git(*a):
        try:
            return subprocess.run(["git", *a], cwd=HERE, capture_output=True, text=True, timeout=10).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""

    return {"date_utc": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
            "cpu_count": os.cpu_count(), "python": sys.version.split()[0], "platform": platform.platform(),
            "load_start": os.getloadavg(), "quick": quick,
            "commit": git("rev-parse", "--short", "HEAD")
            + (" (modified tree)" if git("status", "--porcelain") else "")}


def run_bench(path: Path, extra: list[str]) -> dict:
    """Run one benchmark; its document (or a failure record), its text and its wall time."""
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, str(path), "--json", *extra], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    name = path.stem[len("bench_"):]
    doc = None
    if p.returncode == 0:
        try:
            doc = json.loads(p.stdout.strip().splitlines()[-1])
        except (ValueError, IndexError):
            doc = None
    if doc is None:
        doc = {"bench": name, "rows": [], "data": {}, "skipped": None,
               "failed": f"exit {p.returncode}: {(p.stderr or p.stdout)[-1500:]}"}
    doc["wall_s"] = wall
    return {"name": name, "file": path.name, "doc": doc, "text": p.stderr.rstrip()}


# ---------------------------------------------------------------------- Markdown
def fmt(v, unit: str = "") -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, int):
        s = str(v)
    elif v != v:
        s = "nan"
    elif v == 0 or abs(v) >= 100:
        s = f"{v:.0f}"
    elif abs(v) >= 10:
        s = f"{v:.1f}"
    elif abs(v) >= 0.01:
        s = f"{v:.2f}"
    else:
        s = f"{v:.1e}"
    return f"{s} {unit}".rstrip() if unit and unit != "x" else (f"{s}x" if unit == "x" else s)


def met_cell(met) -> str:
    return "-" if met is None else ("met" if met else "**missed**")


def bench_table(doc: dict) -> list[str]:
    if doc.get("failed"):
        return ["Failed: " + "`" + doc["failed"].strip().splitlines()[-1][:300] + "`"
                if doc["failed"].strip() else "Failed."]
    if doc.get("skipped"):
        return [f"Skipped: {doc['skipped']}."]
    out = ["| figure | value | baseline | baseline value | ratio | target | met |",
           "|---|---:|---|---:|---:|---|---|"]
    for r in doc["rows"]:
        fig = (r["figure"] + (f" ({r['note']})" if r.get("note") else "")).replace("|", "\\|")
        out.append(f"| {fig} | {fmt(r['value'], r['unit'])} | {r['baseline'] or '-'} | "
                   f"{fmt(r['baseline_value'], r['unit'])} | {fmt(r['ratio'], 'x')} | {r['target'] or '-'} | "
                   f"{met_cell(r['met'])} |")
    return out


def tick_table(docs: dict) -> list[str]:
    """Where a gcs fly tick goes, stage by stage, beside each stage's part measured alone."""
    fly = docs.get("fly", {}).get("data") or {}
    if not fly.get("loop_no_log"):
        return []
    cols = [("lockstep --no-log", fly["loop_no_log"]), ("lockstep with log", fly["loop_log"])]
    if fly.get("realtime"):
        cols.append(("real time with log", fly["realtime"]))
    share_col = cols[-1]
    link = docs.get("link", {}).get("data") or {}
    log = docs.get("log", {}).get("data") or {}
    bare = fly.get("bare_ms", {})

    def us(x):
        return None if x is None else x * 1000

    def twice(x):
        return None if x is None else 2 * x

    alone = {
        "decode": (twice(link.get("drain_link_us")), "MavlinkLink.drain of ATTITUDE + LOCAL_POSITION_NED (bench_link)",
                   twice(link.get("decode_raw_codec_us"))),
        "estimate": (us(bare.get("estimate")), "estimator predict alone (bench_fly)", None),
        "control": (us(bare.get("control")), f"{fly.get('controller')} step alone (bench_fly)", None),
        "send": (link.get("send_link_us"), "MavlinkLink encode+send of SET_ATTITUDE_TARGET (bench_link)",
                 link.get("send_raw_codec_us")),
        "log": (log.get("fly_log_paced_100hz_median_us"), "FlightRecorder tick, paced at 100 Hz (bench_log)", None),
    }
    out = [f"`gcs fly` ({fly.get('config')}, {fly.get('controller')}; "
           f"lockstep {fmt(fly.get('duration_s'))} s missions, "
           f"medians over flights of each flight's p50 / p99), each stage beside its part measured alone:", "",
           "| stage | " + " | ".join(f"p50 {n} | p99 {n}" for n, _ in cols)
           + f" | share of tick p50 ({share_col[0]}) | part alone | what | raw pymavlink |",
           "|---|" + "---:|---:|" * len(cols) + "---:|---:|---|---:|"]
    for stage in ("decode", "estimate", "control", "send", "log", "tick"):
        a, what, raw = alone.get(stage, (None, "", None))
        lp = share_col[1]
        share = lp[f"{stage}_p50_ms"] / lp["tick_p50_ms"] if lp["tick_p50_ms"] else None
        cells = " | ".join(f"{fmt(us(c[stage + '_p50_ms']), 'us')} | {fmt(us(c[stage + '_p99_ms']), 'us')}"
                           for _, c in cols)
        out.append(f"| {stage} | {cells} | {'-' if stage == 'tick' or share is None else f'{100 * share:.0f} %'} | "
                   f"{fmt(a, 'us')} | {what or '-'} | {fmt(raw, 'us')} |")
    if fly.get("wall_per_tick_us_log"):
        w, t = fly["wall_per_tick_us_log"], fly["loop_log"]["tick_p50_ms"] * 1000
        out += ["", f"In lockstep a tick takes {fmt(w, 'us')} of wall time (in-process simulation: "
                    f"{fmt(fly.get('in_process_wall_per_tick_us'), 'us')}); "
                    f"the tick's own work (p50 {fmt(t, 'us')}) is "
                    f"{100 * t / w:.0f} % of it, the rest is the wait for the SITL's step "
                    f"(its physics, the round trip, "
                    f"and the telemetry, decoded while waiting: hence the small lockstep decode stage)."]
    out += ["", "The stages' p50s need not add up to the tick's p50 (medians of different samples). "
            "Logging shows in every stage: MAVLink frames are recorded as they are received (decode) and sent (send)."]
    return out


def targets_summary(results: list[dict]) -> list[str]:
    met, missed = [], []
    for r in results:
        for row in r["doc"].get("rows", []):
            if row.get("met") is True:
                met.append(f"{r['name']}: {row['figure']}")
            elif row.get("met") is False:
                missed.append(f"{r['name']}: {row['figure']} = {fmt(row['value'], row['unit'])} "
                              f"(target {row['target']})")
    out = [f"{len(met)} targets met, {len(missed)} missed."]
    if missed:
        out += ["", "Missed:", ""] + [f"- {m}" for m in missed]
    return out


def report_md(mach: dict, results: list[dict]) -> str:
    docs = {r["name"]: r["doc"] for r in results}
    la0, la1 = mach["load_start"], mach["load_end"]
    lines = ["# Benchmark report", "",
             f"`python benchmarks/run.py{' --quick' if mach['quick'] else ''}`, {mach['date_utc']}, "
             f"commit {mach['commit'] or '?'}.", "",
             "| machine | |", "|---|---|",
             f"| CPUs | {mach['cpu_count']} |", f"| Python | {mach['python']} |", f"| platform | {mach['platform']} |",
             f"| load average (1, 5, 15 min) at start | {la0[0]:.2f}, {la0[1]:.2f}, {la0[2]:.2f} |",
             f"| load average at end | {la1[0]:.2f}, {la1[1]:.2f}, {la1[2]:.2f} |",
             f"| --quick | {'yes (fewer repeats, shorter flights)' if mach['quick'] else 'no'} |",
             f"| total wall time | {mach['wall_s']:.0f} s |", "",
             "Every figure is a median over repeats measured in this run, beside a baseline measured in the same "
             "run; ratio = value / baseline value. A load average above the CPU count means other work shared "
             "the machine and the times are inflated.", "",
             "## Targets", ""] + targets_summary(results)
    for r in results:
        lines += ["", f"## {TITLES.get(r['name'], r['file'])}", "", f"Ran in {r['doc']['wall_s']:.0f} s.", ""]
        lines += bench_table(r["doc"])
        if r["name"] == "fly":
            tt = tick_table(docs)
            if tt:
                lines += ["", "### Where a tick goes", ""] + tt
        if r["name"] == "link" and "rig" in docs and docs["rig"].get("rows"):
            lines += ["", "Rig protocol (XBee frames; from bench_rig.py): "
                      + "; ".join(f"{x['figure']} {fmt(x['value'], x['unit'])}" for x in docs["rig"]["rows"][:2]) + "."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="pass --quick to every benchmark")
    ap.add_argument("--only", action="append", metavar="NAME",
                    help="run only this benchmark (control, fly, link, ...); repeatable")
    args = ap.parse_args(argv)
    out_dir = HERE / "results"
    out_dir.mkdir(exist_ok=True)
    mach = machine(args.quick)
    t0 = time.perf_counter()
    results = []
    for bench in benches(args.only):
        print(f"== {bench.name}", flush=True)
        r = run_bench(bench, ["--quick"] if args.quick else [])
        print(r["text"] + (f"\nFAILED: {r['doc']['failed']}" if r["doc"].get("failed") else ""), flush=True)
        print(f"({r['doc']['wall_s']:.0f} s)\n", flush=True)
        results.append(r)
    mach["wall_s"] = time.perf_counter() - t0
    mach["load_end"] = os.getloadavg()
    head = (f"{mach['date_utc']}  python {mach['python']}  {mach['cpu_count']} CPUs  quick={mach['quick']}  "
            f"load start {', '.join(f'{x:.2f}' for x in mach['load_start'])}  "
            f"end {', '.join(f'{x:.2f}' for x in mach['load_end'])}  commit {mach['commit']}")
    (out_dir / "latest.txt").write_text(head + "\n\n" + "\n\n".join(
        f"== {r['file']} ({r['doc']['wall_s']:.0f} s)\n{r['text']}"
        + (f"\nFAILED: {r['doc']['failed']}" if r["doc"].get("failed") else "") for r in results) + "\n")
    (out_dir / "latest.json").write_text(json.dumps({"machine": mach,
                                                     "benchmarks": {r["name"]: r["doc"] for r in results}},
                                                    indent=1, allow_nan=True) + "\n")
    (out_dir / "REPORT.md").write_text(report_md(mach, results))
    print(f"wrote {out_dir / 'latest.txt'}, {out_dir / 'latest.json'} and {out_dir / 'REPORT.md'}")
    return 1 if any(r["doc"].get("failed") for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
