"""The same flights on three vehicles: the built-in SITL, ArduPilot's ArduCopter SITL and PX4 SITL + SIH.

Run: ``python benchmarks/bench_autopilots.py [--quick] [--json] [--duration S] [--speedup S]``

Every controller (nlsoc, loc, pd) with the attitude and rates outputs flies outdoor-circle for
``--duration`` seconds (default 15: the 8 s take-off and 7 s of circle) on each vehicle: the built-in
SITL in real time (``gcs fly``), ArduCopter and PX4 at ``--speedup`` (default 2) on the vehicle's clock
(``--sitl arducopter`` / ``--sitl px4``; skipped where the firmware is absent: ``$GCS_ARDUCOPTER``,
``$GCS_PX4`` or ``../shared``).  ``--quick``: nlsoc and pd with the attitude output only;
``--vehicles px4,...``: some of the vehicles.
Per flight: RMS position error, J_e, J_u_hover and overshoot (gcs sim's metrics, from the summary)
and the liftoff delay, from the log: how long after the reference first rises 5 cm above the take-off
point the vehicle does (the built-in SITL is the baseline).  The steady-state error is the issues'
"altitude steady error": a second flight per cell, outdoor-altitude for ``--altitude-duration``
seconds (default 25: the 10 s ramp and 15 s of hold), its mean error over the last second.
On PX4 SIH also the RMS against SIH's true position (HIL_STATE_QUATERNION, which PX4 streams from
its simulator and gcs logs), "RMS true xy": what the estimate-relative figure does not show, beside
"EKF vs true", PX4's own estimate against that truth (what no off-board controller can remove).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchlib import document, emit, row

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from gcs.log.mcap.reader import read_log
from gcs.vehicles.arducopter_sitl import locate_arducopter
from gcs.vehicles.px4_sitl import locate_px4

ROOT = Path(__file__).resolve().parents[1]
LIFT_M = 0.05
EARTH_RADIUS_M = 6371000.0


def liftoff_delay_s(log_path: Path) -> float | None:
    """Seconds between the reference and the vehicle first rising :data:`LIFT_M` above the start."""
    log = read_log(log_path, lambda t: t in ("/control/state", "/control/reference"))
    state = list(log.decoded("/control/state"))
    ref = list(log.decoded("/control/reference"))
    if not state or not ref:
        return None
    z0 = state[0][1]["z"]

    def first(rows) -> int | None:
        return next((ns for ns, d in rows if d["z"] > z0 + LIFT_M), None)

    t_ref, t_veh = first(ref), first(state)
    return None if t_ref is None or t_veh is None else (t_veh - t_ref) / 1e9


def true_rms_xy_m(log_path: Path) -> tuple[float, float] | None:
    """Against SIH's true position (HIL_STATE_QUATERNION, north/east of PX4's EKF origin
    GPS_GLOBAL_ORIGIN), over the flight: the RMS horizontal distance [m] of the truth from the
    reference, and of the truth from PX4's own estimate (LOCAL_POSITION_NED: the floor no off-board
    controller can go under); None without ground truth in the log."""
    log = read_log(log_path, lambda t: t in (
        "/mavlink/in/HIL_STATE_QUATERNION", "/mavlink/in/GPS_GLOBAL_ORIGIN", "/mavlink/in/LOCAL_POSITION_NED",
        "/control/reference"))
    origin = list(log.decoded("/mavlink/in/GPS_GLOBAL_ORIGIN"))
    truth = [(ns, d) for ns, d in log.decoded("/mavlink/in/HIL_STATE_QUATERNION") if d.get("lat")]
    ref = np.array([(ns, d["x"], d["y"]) for ns, d in log.decoded("/control/reference")])
    ekf = np.array([(ns, d["x"], d["y"]) for ns, d in log.decoded("/mavlink/in/LOCAL_POSITION_NED")])
    if not origin or not truth or len(ref) < 2 or len(ekf) < 2:
        return None
    o = origin[-1][1]
    lat0, lon0 = math.radians(o["latitude"] / 1e7), math.radians(o["longitude"] / 1e7)
    t = np.array([(ns, (math.radians(d["lat"] / 1e7) - lat0) * EARTH_RADIUS_M,
                   (math.radians(d["lon"] / 1e7) - lon0) * EARTH_RADIUS_M * math.cos(lat0)) for ns, d in truth])
    t = t[(t[:, 0] >= ref[0, 0]) & (t[:, 0] <= ref[-1, 0])]
    if not len(t):
        return None

    def rms_from(a: np.ndarray) -> float:
        dn = t[:, 1] - np.interp(t[:, 0], a[:, 0], a[:, 1])
        de = t[:, 2] - np.interp(t[:, 0], a[:, 0], a[:, 2])
        return float(np.sqrt(np.mean(dn ** 2 + de ** 2)))

    return rms_from(ref), rms_from(ekf)


def fly(vehicle: str, path: str | None, controller: str, output: str, duration_s: float, speedup: float,
        config: str = "outdoor-circle") -> dict:
    with tempfile.TemporaryDirectory(prefix="bench_ap_") as d:
        summary, log = os.path.join(d, "s.json"), Path(d) / "f.mcap"
        env = dict(os.environ, GCS_STATE_DIR=d, PYTHONPATH=str(ROOT))
        argv = [sys.executable, "-m", "gcs.cli", "fly", "--config", config, "--controller", controller,
                "--output", output,
                "--duration", f"{duration_s:g}", "-q", "--summary", summary, "--log", str(log)]
        if vehicle != "builtin":
            argv += ["--sitl", vehicle, f"--{vehicle}", str(path), "--speedup", f"{speedup:g}"]
        t0 = time.monotonic()
        p = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=900)
        try:
            s = json.loads(Path(summary).read_text())
        except (OSError, ValueError):
            tail = (p.stderr.strip().splitlines() or [""])[-1]
            return {"exit_reason": f"no summary (exit {p.returncode}): {tail}", "wall_s": time.monotonic() - t0}
        m = s.get("metrics") or {}
        lift = liftoff_delay_s(log) if log.exists() else None
        truth = (true_rms_xy_m(log) if log.exists() and vehicle == "px4" else None) or (None, None)
        return {"exit_reason": s["exit_reason"], "wall_s": time.monotonic() - t0, "rms_m": m.get("rms_error_m"),
                "J_e": m.get("J_e"), "J_u_hover": m.get("J_u_hover"), "steady_m": m.get("steady_state_error_m"),
                "overshoot_m": m.get("overshoot_m"), "liftoff_s": lift, "true_rms_xy_m": truth[0],
                "ekf_vs_true_xy_m": truth[1]}


def _fmt(v, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="nlsoc and pd, attitude output only")
    ap.add_argument("--json", action="store_true", help="text on stderr, one JSON document on stdout")
    ap.add_argument("--duration", type=float, default=15.0, help="mission seconds per flight (default 15)")
    ap.add_argument("--altitude-duration", type=float, default=25.0,
                    help="mission seconds of the outdoor-altitude flight per cell (default 25; 0: none)")
    ap.add_argument("--speedup", type=float, default=2.0, help="speed-up of the firmware flights (default 2)")
    ap.add_argument("--vehicles", default="builtin,arducopter,px4", help="of builtin,arducopter,px4 (default all)")
    args = ap.parse_args(argv)
    wanted = set(args.vehicles.split(","))
    if not wanted <= {"builtin", "arducopter", "px4"}:
        ap.error(f"--vehicles: unknown {sorted(wanted - {'builtin', 'arducopter', 'px4'})}")
    vehicles = [("builtin", None), ("arducopter", locate_arducopter(ROOT.parent / "shared" / "arducopter")),
                ("px4", locate_px4(ROOT.parent / "shared" / "px4"))]
    vehicles = [v for v in vehicles if v[0] in wanted]
    controllers = ("nlsoc", "pd") if args.quick else ("nlsoc", "loc", "pd")
    outputs = ("attitude",) if args.quick else ("attitude", "rates")
    rows, results = [], []
    header = f"{'controller':10} {'output':8} {'vehicle':10} {'RMS [m]':>8} {'J_e':>7} {'J_u_hover':>9} " \
             f"{'alt steady [m]':>14} {'overshoot':>9} {'liftoff [s]':>11} {'RMS true xy':>11} " \
             f"{'EKF vs true':>11} {'wall [s]':>8}  exit"
    lines = [header]
    for controller in controllers:
        for output in outputs:
            for vehicle, path in vehicles:
                if vehicle != "builtin" and path is None:
                    lines.append(f"{controller:10} {output:8} {vehicle:10} skipped: firmware not found")
                    continue
                r = fly(vehicle, path, controller, output, args.duration, args.speedup)
                if args.altitude_duration > 0:
                    alt = fly(vehicle, path, controller, output, args.altitude_duration, args.speedup,
                              "outdoor-altitude")
                    r.update(steady_m=alt.get("steady_m"), altitude_exit_reason=alt["exit_reason"],
                             wall_s=r["wall_s"] + alt["wall_s"])
                else:
                    r["steady_m"] = None
                r.update(controller=controller, output=output, vehicle=vehicle)
                results.append(r)
                lines.append(f"{controller:10} {output:8} {vehicle:10} {_fmt(r.get('rms_m'), '8.3f')} "
                             f"{_fmt(r.get('J_e'), '7.1f')} {_fmt(r.get('J_u_hover'), '9.0f')} "
                             f"{_fmt(r.get('steady_m'), '14.4f')} {_fmt(r.get('overshoot_m'), '9.3f')} "
                             f"{_fmt(r.get('liftoff_s'), '11.2f')} {_fmt(r.get('true_rms_xy_m'), '11.3f')} "
                             f"{_fmt(r.get('ekf_vs_true_xy_m'), '11.3f')} "
                             f"{r['wall_s']:8.1f}  {r['exit_reason']}")
                print(lines[-1], file=sys.stderr, flush=True)
                base = next((b for b in results if b["vehicle"] == "builtin" and b["controller"] == controller
                             and b["output"] == output), None)
                if r.get("rms_m") is not None:
                    rows.append(row(f"{controller}/{output}/{vehicle} RMS position error", r["rms_m"], "m",
                                    baseline=f"{controller}/{output}/builtin",
                                    baseline_value=None if base is None else base.get("rms_m"),
                                    target="<= 0.10 m", met=r["rms_m"] <= 0.10))
                if r.get("steady_m") is not None:
                    rows.append(row(f"{controller}/{output}/{vehicle} altitude steady-state error", r["steady_m"],
                                    "m", baseline=f"{controller}/{output}/builtin",
                                    baseline_value=None if base is None else base.get("steady_m"),
                                    target="|e| <= 0.01 m", met=abs(r["steady_m"]) <= 0.01))
    text = "\n".join(lines)
    emit(document("bench_autopilots", args.quick, {"flights": results, "duration_s": args.duration,
                                                  "speedup": args.speedup}, rows), text, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
