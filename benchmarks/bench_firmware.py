"""``gcs fly --sitl arducopter``: how fast ArduPilot's real firmware can be flown reliably (issue 13).

Run: ``python benchmarks/bench_firmware.py [--quick] [--json]`` (needs the ArduCopter SITL binary:
``$GCS_ARDUCOPTER`` or ``../shared/arducopter``; skipped without it).

For each speed-up S (1, 2, 3, 5; ``--quick``: 2 and 5) one outdoor-circle LOC flight cut at 12 s
(the firmware boots at 10x, then flies at S on the vehicle's clock).  Figures per S: the wall time
of the whole run, simulated seconds per wall second of the mission, the share of the mission's
ticks skipped or late (a tick is late when the loop wakes a period or more after its deadline on
the vehicle's clock), wake-up jitter p99 and the RMS position error — beside speed-up 1, the real
time baseline of the same run.  "Reliable" = no more than 1 % of the ticks skipped.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchlib import document, emit, met_text, row

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from gcs.vehicles.arducopter_sitl import ENV_VAR, locate_arducopter

ROOT = Path(__file__).resolve().parents[1]
RELIABLE_SKIPPED = 0.01


def binary() -> str | None:
    return locate_arducopter(ROOT.parent / "shared" / "arducopter")


def fly(speedup: float, arducopter: str) -> dict:
    with tempfile.TemporaryDirectory(prefix="bench_fw_") as d:
        path = os.path.join(d, "s.json")
        env = dict(os.environ, GCS_STATE_DIR=d, PYTHONPATH=str(ROOT))
        t0 = time.monotonic()
        p = subprocess.run([sys.executable, "-m", "gcs.cli", "fly", "--sitl", "arducopter", "--arducopter", arducopter,
                            "--speedup", f"{speedup:g}", "--controller", "loc", "--duration", "12", "--no-log", "-q",
                            "--summary", path], env=env, capture_output=True, text=True, timeout=600)
        wall = time.monotonic() - t0
        try:
            s = json.loads(Path(path).read_text())
        except (OSError, ValueError):
            s = {"exit_reason": f"no summary (exit {p.returncode}): {p.stderr.strip().splitlines()[-1:]}"}
        s["run_wall_s"] = wall
        return s


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="speed-ups 2 and 5 only")
    ap.add_argument("--json", action="store_true", help="text on stderr, one JSON document on stdout")
    args = ap.parse_args(argv)
    exe = binary()
    if exe is None:
        why = f"no ArduCopter SITL binary (${ENV_VAR} or ../shared/arducopter)"
        emit(document("firmware", args.quick, {}, [], skipped=why), f"skipped: {why}", args.json)
        return 0
    speedups = (1.0, 2.0, 5.0) if args.quick else (1.0, 2.0, 3.0, 5.0)
    runs = {s: fly(s, exe) for s in speedups}
    data, rows, lines = {}, [], ["speed-up  exit        run wall [s]  mission x  skipped  jitter p99 [ms]  RMS [m]"]
    base = runs[speedups[0]]
    for s, r in runs.items():
        loop = r.get("loop", {})
        ticks = loop.get("ticks") or 0
        skipped = loop.get("skipped_ticks", 0) / max(1, ticks + loop.get("skipped_ticks", 0))
        ratio = loop.get("realtime_ratio")
        rms = r.get("metrics", {}).get("rms_error_m")
        data[f"{s:g}"] = {"exit_reason": r.get("exit_reason"), "run_wall_s": r["run_wall_s"], "mission_ratio": ratio,
                          "skipped_share": skipped, "jitter_p99_ms": loop.get("jitter_p99_ms"), "rms_error_m": rms}
        ok = r.get("exit_reason") == "completed" and skipped <= RELIABLE_SKIPPED
        rows.append(row(f"speed-up {s:g}: mission x real time", ratio, "x", baseline="speed-up 1",
                        baseline_value=base.get("loop", {}).get("realtime_ratio"),
                        target=f"completed, <= {RELIABLE_SKIPPED:.0%} ticks skipped", met=ok,
                        note=f"skipped {skipped:.1%}, RMS {rms if rms is None else round(rms, 3)} m"))
        lines.append(f"{s:8g}  {r.get('exit_reason')!s:10.10}  {r['run_wall_s']:12.1f}  "
                     f"{(ratio or float('nan')):9.2f}  {skipped:7.1%}  {loop.get('jitter_p99_ms', float('nan')):15.1f}"
                     f"  {(rms if rms is not None else float('nan')):7.3f}  {met_text(ok)}")
    reliable = [s for s, r in runs.items() if data[f"{s:g}"]["exit_reason"] == "completed"
                and data[f"{s:g}"]["skipped_share"] <= RELIABLE_SKIPPED]
    data["fastest_reliable"] = max(reliable) if reliable else None
    lines.append(f"fastest reliable speed-up here: {data['fastest_reliable']} (load {os.getloadavg()[0]:.1f})")
    emit(document("firmware", args.quick, data, rows), "\n".join(lines), args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
