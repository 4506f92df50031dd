"""Does the built-in SITL predict ArduPilot's firmware?  ``sitl --emulate arducopter`` vs ArduCopter SITL (issue 13.4).

Run: ``python benchmarks/bench_fidelity.py [--quick] [--repeats N] [--json] [--svg docs/fidelity-steps.svg]`` (needs the
ArduCopter SITL binary: ``$GCS_ARDUCOPTER`` or ``../shared/arducopter``; skipped without it).

The same flights (controller, output, outdoor-circle cut at 20 s, calm air) on three vehicles:
the built-in SITL as it is (real time), the built-in SITL with ``--emulate arducopter --ekf-ready-s 3``
(real time; the EKF start-up only delays the boot) and the firmware (``gcs fly --sitl arducopter
--speedup 2``).  Per flight: RMS position error, J_e, J_u_hover, overshoot and the liftoff time (the
first control step after the mission start with the estimated altitude above 5 cm); each emulated
figure beside the firmware's with their ratio and whether it is within 20 % (with ``--repeats N``: medians
of N flights per vehicle, and the firmware's own min-max beside, since one firmware flight's overshoot
varies by +-15 % from the next).  Flights: nlsoc with
the attitude output (``--quick``), and also loc/attitude and nlsoc/rates.  Then a 10 deg roll
step (``fidelity_steps.py``) on the emulation and on the firmware (instance 6, real time): roll and
roll rate at fixed times after the step; ``--svg`` draws both responses overlaid.
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchlib import document, emit, row

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import gcs
from fidelity_steps import roll_step
from gcs.vehicles.arducopter_sitl import ENV_VAR, locate_arducopter

ROOT = Path(__file__).resolve().parents[1]
TOLERANCE = 0.20
METRICS = (("rms_error_m", "RMS [m]"), ("J_e", "J_e"), ("J_u_hover", "J_u_hover [N]"), ("overshoot_m", "overshoot [m]"),
           ("liftoff_s", "liftoff [s]"))
EMULATE = ("--emulate", "arducopter", "--ekf-ready-s", "3")
STEP_INSTANCE = 6
STEP_TIMES_S = (0.02, 0.04, 0.06, 0.1, 0.15, 0.22, 0.3, 0.5, 1.0)


def liftoff_s(record) -> float | None:
    """Mission time [s] of the first step whose altitude estimate is above 5 cm."""
    if record is None:
        return None
    z = record.state[:, 2]
    above = (z > 0.05).nonzero()[0]
    return float(above[0] * record.ts_s) if above.size else None


def fly(controller: str, output: str, vehicle: str, exe: str) -> dict:
    kw: dict = {"controller": controller, "config": "outdoor-circle", "output": output, "duration_s": 20.0,
                "log": False}
    if vehicle == "firmware":
        kw.update(firmware="arducopter", firmware_path=exe, speedup=2.0)
    elif vehicle == "emulated":
        kw.update(sitl_args=EMULATE)
    with tempfile.TemporaryDirectory(prefix="bench_fid_") as d:
        os.environ["GCS_STATE_DIR"] = d
        t0 = time.monotonic()
        r = gcs.fly(gcs.FlightSpec(**kw))
    out = {k: r.metrics.get(k) for k, _ in METRICS if k != "liftoff_s"}
    out.update(liftoff_s=liftoff_s(r.record), exit_reason=r.exit_reason, wall_s=time.monotonic() - t0)
    return out


def step_firmware(exe: str) -> dict:
    with tempfile.TemporaryDirectory(prefix="bench_fid_step_") as d:
        run = Path(exe).parent / "run"
        env = dict(os.environ, INSTANCE=str(STEP_INSTANCE), SPEEDUP="1")
        subprocess.run([str(run), d], env=env, check=True, capture_output=True, timeout=60)
        try:
            return roll_step(f"tcp:127.0.0.1:{5760 + 10 * STEP_INSTANCE}")
        finally:
            os.kill(int(Path(d, "arducopter.pid").read_text()), signal.SIGTERM)


def step_emulated(port: int = 15601) -> dict:
    p = subprocess.Popen([sys.executable, "-m", "sitl.cli", "--udp-listen", f"127.0.0.1:{port}", *EMULATE[:2],
                          "--ekf-ready-s", "1"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                         cwd=ROOT)
    try:
        p.stdout.readline()
        return roll_step(f"udpout:127.0.0.1:{port}", udpout=True)
    finally:
        p.terminate()
        p.wait(timeout=10)


def sample(step: dict, t: float) -> tuple[float, float]:
    ts = step["t_s"]
    i = min(range(len(ts)), key=lambda k: abs(ts[k] - t))
    return step["roll_deg"][i], step["rate_deg_s"][i]


def svg(steps: dict, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a, b) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    for name, st in steps.items():
        a.plot(st["t_s"], st["roll_deg"], label=name)
        b.plot(st["t_s"], st["rate_deg_s"], label=name)
    a.axhline(10.0, color="grey", lw=0.5)
    a.set_ylabel("roll [deg]")
    b.set_ylabel("roll rate [deg/s]")
    b.set_xlabel("time after the 10 deg roll step [s]")
    a.legend()
    a.set_title("Roll step, GUIDED_NOGPS attitude target (ATC_RATE_FF_ENAB 0)")
    fig.tight_layout()
    fig.savefig(path, format="svg")


def median_flight(flights: list[dict]) -> dict:
    """Per metric the median over repeated flights (None where any is None), the exits joined, and
    each metric's (min, max) under ``spread``."""
    out: dict = {"exit_reason": "/".join(sorted({f["exit_reason"] for f in flights})),
                 "wall_s": sum(f["wall_s"] for f in flights), "spread": {}}
    for k, _ in METRICS:
        vals = [f[k] for f in flights]
        if any(v is None for v in vals):
            out[k] = None
            continue
        out[k] = statistics.median(vals)
        out["spread"][k] = (min(vals), max(vals))
    return out


def fmt(v: float | None) -> str:
    return f"{v:10.4g}" if v is not None else f"{'-':>10s}"


def verdict(emu, fw) -> tuple[float | None, bool | None]:
    if emu is None or fw is None:
        return None, None
    if fw == 0:
        return None, abs(emu) < 1e-3
    ratio = emu / fw
    return ratio, abs(ratio - 1.0) <= TOLERANCE


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="nlsoc/attitude only")
    ap.add_argument("--json", action="store_true", help="text on stderr, one JSON document on stdout")
    ap.add_argument("--svg", metavar="PATH", help="write the step-response overlay there")
    ap.add_argument("--no-steps", action="store_true", help="flights only")
    ap.add_argument("--repeats", type=int, default=1, metavar="N",
                    help="fly each case N times per vehicle and compare medians (the firmware's own "
                         "flight-to-flight spread is printed beside); default 1")
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error("--repeats must be >= 1")
    exe = locate_arducopter(ROOT.parent / "shared" / "arducopter")
    if exe is None:
        why = f"no ArduCopter SITL binary (${ENV_VAR} or ../shared/arducopter)"
        emit(document("fidelity", args.quick, {}, [], skipped=why), f"skipped: {why}", args.json)
        return 0
    cases = [("nlsoc", "attitude")] if args.quick else [("nlsoc", "attitude"), ("loc", "attitude"), ("nlsoc", "rates")]
    data: dict = {"flights": {}, "steps": {}}
    rows, lines = [], []
    for controller, output in cases:
        key = f"{controller}/{output}"
        res = {v: median_flight([fly(controller, output, v, str(exe)) for _ in range(args.repeats)])
               for v in ("builtin", "emulated", "firmware")}
        data["flights"][key] = res
        lines.append(f"{key}: exits built-in {res['builtin']['exit_reason']}, emulated "
                     f"{res['emulated']['exit_reason']}, firmware {res['firmware']['exit_reason']}")
        many = args.repeats > 1
        lines.append(f"  {'metric':15s} {'built-in':>10s} {'emulated':>10s} {'firmware':>10s} {'emu/fw':>7s}"
                     "  within 20 %" + (f"   (medians of {args.repeats}; firmware min-max)" if many else ""))
        for k, label in METRICS:
            e, f, b = res["emulated"][k], res["firmware"][k], res["builtin"][k]
            ratio, ok = verdict(e, f)
            spread = res["firmware"]["spread"].get(k) if many else None
            lines.append(f"  {label:15s} {fmt(b)} {fmt(e)} {fmt(f)} {ratio if ratio is not None else float('nan'):7.2f}"
                         f"  {'yes' if ok else 'NO' if ok is not None else '-':3s}"
                         + (f"          {spread[0]:.4g}-{spread[1]:.4g}" if spread else ""))
            rows.append(row(f"{key} {label}: emulated", e, baseline="firmware", baseline_value=f,
                            target="within 20 % of the firmware", met=ok))
    if not args.no_steps:
        steps = {"emulated (sitl --emulate arducopter)": step_emulated(), "ArduCopter SITL": step_firmware(str(exe))}
        data["steps"] = steps
        lines.append("roll step 10 deg: roll [deg] / roll rate [deg/s] after the step")
        lines.append("  t [s]   " + "  ".join(f"{t:>11g}" for t in STEP_TIMES_S))
        for name, st in steps.items():
            lines.append(f"  {name[:8]:8s}" + "  ".join(f"{sample(st, t)[0]:5.2f}/{sample(st, t)[1]:5.0f}"
                                                      for t in STEP_TIMES_S))
        if args.svg:
            svg(steps, args.svg)
            lines.append(f"overlay written to {args.svg}")
    emit(document("fidelity", args.quick, data, rows), "\n".join(lines), args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
