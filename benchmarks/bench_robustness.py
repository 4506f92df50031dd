"""Non-nominal vehicles and autopilots: the paper's laws beside the autopilot's own position controller.

Run: ``python benchmarks/bench_robustness.py [--quick] [--json] [--firmware arducopter,px4] [--cells a,b]
[--controllers nlsoc,loc,pd] [--outputs attitude,rates] [--speedup S]``

A matrix of variations of the vehicle and its autopilot (:data:`CELLS`: each motor weak by 10-25 %, the
mass +-20 % where the simulator allows, the hover throttle parameter and the rate-loop gains altered,
wind with turbulence, the vehicle's clock at 0.95 and 1.05 of the ground station's), on ArduCopter SITL
and PX4 SITL + SIH.  Per cell: every controller with the attitude and the rates output flies the whole
outdoor-circle mission (``gcs fly --connect`` to the firmware the benchmark started with the cell's
parameters, at ``--speedup``; the clock cells in real time, the firmware's clock running at the cell's
rate), and beside them **the autopilot's own position controller flies the same circle**
(:mod:`position_baseline`: ArduCopter GUIDED / PX4 OFFBOARD with position, velocity and acceleration
targets).  Both are measured the same way (:func:`position_baseline.window_errors`): the RMS of the
vehicle's estimate (LOCAL_POSITION_NED) to the reference over the circle; beside it gcs's whole-mission
RMS (its summary), the altitude steady-state error, the largest tilt and the exit.

Targets per cell (issue 26): RMS <= 1.2 x the autopilot's own controller on the same cell and <= 1.25 x
the same controller on the nominal cell; |altitude steady-state error| <= 0.01 m; tilt <= 15 deg.
``--quick``: nominal and motor 1 weak by 15 %, nlsoc and pd, ArduCopter only.
Where a firmware's simulator cannot make a variation the cell says so (n/a) and is not flown.
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
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from benchlib import document, emit, row
from position_baseline import fly_arducopter, fly_px4, window_errors

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from gcs.config import load_config
from gcs.config.parse import resolve_config_path
from gcs.errors import GcsError
from gcs.log.mcap.reader import read_log
from gcs.mission import Mission
from gcs.vehicles.arducopter_sitl import ArduCopterSitl, locate_arducopter
from gcs.vehicles.px4_sitl import Px4Sitl, locate_px4

ROOT = Path(__file__).resolve().parents[1]
CONFIG = "outdoor-circle"
#: ArduCopter SITL's X frame (SIM_Frame.cpp default_model): 3 kg, hover at 0.39.  Its motors are scaled
#: to the frame's mass (max thrust per motor ~ mass / hoverThrOut), so a heavier vehicle with the same
#: motors is mass x F with hoverThrOut 0.39 x F.
AC_MASS_KG, AC_HOVER = 3.0, 0.39
#: PX4's defaults the cells scale: CA_ROTORn_CT (the allocator's model of rotor n), SIH_MASS, MPC_THR_HOVER.
PX4_CT, PX4_MASS_KG, PX4_HOVER = 6.5, 1.0, 0.5
RP_RATE = {"ATC_RAT_RLL_P": 0.135, "ATC_RAT_RLL_I": 0.135, "ATC_RAT_RLL_D": 0.0036,
           "ATC_RAT_PIT_P": 0.135, "ATC_RAT_PIT_I": 0.135, "ATC_RAT_PIT_D": 0.0036}
#: What a firmware that does not start or a flight that fails raises: reported in the matrix, not raised.
START_ERRORS = (RuntimeError, OSError, GcsError)
TARGETS = {"vs_autopilot": 1.2, "vs_nominal": 1.25, "steady_m": 0.01, "tilt_deg": 15.0}


@dataclass(frozen=True)
class Cell:
    """One variation: its ArduCopter parameters (None: the simulator cannot), frame JSON, PX4 parameters,
    and the vehicle clock's rate (None: the flight runs at ``--speedup`` on the vehicle's clock)."""

    name: str
    what: str
    arducopter: dict | None = field(default_factory=dict)
    frame: dict | None = None
    px4: dict | None = field(default_factory=dict)
    clock_rate: float | None = None


def _weak(motor: int, weakness: float) -> Cell:
    return Cell(f"motor{motor}-{round(weakness * 100)}", f"motor {motor} {round(weakness * 100)} % weak",
                {"SIM_ENGINE_FAIL": 1 << (motor - 1), "SIM_ENGINE_MUL": 1.0 - weakness},
                px4={f"CA_ROTOR{motor - 1}_CT": round(PX4_CT / (1.0 - weakness), 3)})


CELLS = (
    Cell("nominal", "nominal vehicle and autopilot"),
    _weak(1, 0.15), _weak(1, 0.10), _weak(2, 0.15), _weak(3, 0.20), _weak(4, 0.25),
    Cell("mass+20", "mass +20 % (same motors)", frame={"mass": AC_MASS_KG * 1.2, "hoverThrOut": AC_HOVER * 1.2},
         px4={"SIH_MASS": PX4_MASS_KG * 1.2}),
    Cell("mass-20", "mass -20 % (same motors)", frame={"mass": AC_MASS_KG * 0.8, "hoverThrOut": AC_HOVER * 0.8},
         px4={"SIH_MASS": PX4_MASS_KG * 0.8}),
    Cell("hover+20", "hover-throttle parameter 20 % high", {"MOT_THST_HOVER": AC_HOVER * 1.2},
         px4={"MPC_THR_HOVER": PX4_HOVER * 1.2}),
    Cell("hover-20", "hover-throttle parameter 20 % low", {"MOT_THST_HOVER": AC_HOVER * 0.8},
         px4={"MPC_THR_HOVER": PX4_HOVER * 0.8}),
    Cell("rate-gains-x0.6", "roll/pitch rate-loop gains x 0.6", {k: v * 0.6 for k, v in RP_RATE.items()},
         px4={"MC_ROLLRATE_K": 0.6, "MC_PITCHRATE_K": 0.6}),
    Cell("rate-gains-x1.4", "roll/pitch rate-loop gains x 1.4", {k: v * 1.4 for k, v in RP_RATE.items()},
         px4={"MC_ROLLRATE_K": 1.4, "MC_PITCHRATE_K": 1.4}),
    Cell("wind", "wind 3 m/s from 45 deg, turbulence 1 m/s", {"SIM_WIND_SPD": 3.0, "SIM_WIND_DIR": 45.0,
                                                             "SIM_WIND_TURB": 1.0}, px4=None),
    Cell("clock-0.95", "vehicle clock at 0.95 of the ground station's (real time)", clock_rate=0.95),
    Cell("clock-1.05", "vehicle clock at 1.05 of the ground station's (real time)", clock_rate=1.05),
)
QUICK_CELLS = ("nominal", "motor1-15")


def frame_model(cell: Cell, folder: str) -> str:
    """ArduCopter's ``--model`` for the cell: ``x``, or ``x:FILE`` with the cell's frame values written to FILE."""
    if not cell.frame:
        return "x"
    path = Path(folder) / "frame.json"
    path.write_text(json.dumps(cell.frame))
    return f"x:{path}"


def _start_firmware(firmware: str, path: str, cell: Cell, speedup: float, folder: str):
    """The firmware SITL for a cell, started (the caller stops it)."""
    rate = cell.clock_rate or speedup
    if firmware == "arducopter":
        sitl = ArduCopterSitl(path, speedup=rate, model=frame_model(cell, folder))
        if cell.arducopter:
            parm = Path(folder) / "cell.parm"
            parm.write_text("".join(f"{k} {v:g}\n" for k, v in cell.arducopter.items()))
            sitl.defaults.append(parm)
    else:
        sitl = Px4Sitl(path, speedup=rate, params=cell.px4 or {})
    return sitl.start()


def log_figures(log_path: Path, mission: Mission) -> dict:
    """:func:`window_errors` of a ``gcs fly`` log (LOCAL_POSITION_NED at its arrival against the reference
    then), and the largest tilt during the mission."""
    log = read_log(log_path, lambda t: t in ("/control/reference", "/mavlink/in/LOCAL_POSITION_NED",
                                             "/mavlink/in/ATTITUDE"))
    ref = np.array([(ns, d["x"], d["y"], d["z"]) for ns, d in log.decoded("/control/reference")])
    lpn = np.array([(ns, d["x"], d["y"], -d["z"]) for ns, d in log.decoded("/mavlink/in/LOCAL_POSITION_NED")])
    if len(ref) < 2 or not len(lpn):
        return {}
    lpn = lpn[(lpn[:, 0] >= ref[0, 0]) & (lpn[:, 0] <= ref[-1, 0])]
    err = np.stack([lpn[:, i] - np.interp(lpn[:, 0], ref[:, 0], ref[:, i]) for i in (1, 2, 3)], axis=1)
    out = window_errors((lpn[:, 0] - ref[0, 0]) / 1e9, err, mission)
    tilts = [max(abs(d["roll"]), abs(d["pitch"])) for ns, d in log.decoded("/mavlink/in/ATTITUDE")
             if ref[0, 0] <= ns <= ref[-1, 0]]
    out["tilt_max_deg"] = math.degrees(max(tilts)) if tilts else None
    return out


def fly_gcs(firmware: str, path: str, cell: Cell, controller: str, output: str, speedup: float,
            mission: Mission) -> dict:
    """One ``gcs fly --connect`` flight of the cell; its figures."""
    with tempfile.TemporaryDirectory(prefix="bench_rob_") as d:
        t0 = time.monotonic()
        try:
            sitl = _start_firmware(firmware, path, cell, speedup, d)
        except START_ERRORS as exc:
            return {"exit_reason": f"firmware did not start: {exc}", "wall_s": time.monotonic() - t0}
        try:
            summary, log = Path(d) / "s.json", Path(d) / "f.mcap"
            argv = [sys.executable, "-m", "gcs.cli", "fly", "--connect", sitl.url, "--config", CONFIG,
                    "--controller", controller, "--output", output, "-q", "--summary", str(summary),
                    "--log", str(log), "--ready-timeout", "120"]
            if cell.clock_rate is None:
                argv += ["--speedup", f"{speedup:g}"]
            p = subprocess.run(argv, env=dict(os.environ, GCS_STATE_DIR=d, PYTHONPATH=str(ROOT)),
                               capture_output=True, text=True, timeout=1200)
        finally:
            sitl.stop()
        try:
            s = json.loads(summary.read_text())
        except (OSError, ValueError):
            tail = (p.stderr.strip().splitlines() or [""])[-1]
            return {"exit_reason": f"no summary (exit {p.returncode}): {tail}", "wall_s": time.monotonic() - t0}
        m = s.get("metrics") or {}
        out = {"exit_reason": s["exit_reason"], "wall_s": time.monotonic() - t0, "rms_mission_m": m.get("rms_error_m"),
               "summary_steady_m": m.get("steady_state_error_m"), "overshoot_m": m.get("overshoot_m")}
        if log.exists():
            out.update(log_figures(log, mission))
        return out


def fly_own(firmware: str, path: str, cell: Cell, speedup: float, mission: Mission) -> dict:
    """The autopilot's own position controller on the cell (a failure is reported, not raised)."""
    t0 = time.monotonic()
    try:
        with tempfile.TemporaryDirectory(prefix="bench_rob_own_") as d:
            if firmware == "arducopter":
                fig = fly_arducopter(path, mission, speedup=cell.clock_rate or speedup, params=cell.arducopter,
                                     model=frame_model(cell, d))
            else:
                fig = fly_px4(path, mission, speedup=cell.clock_rate or speedup, params=cell.px4)
        fig["exit_reason"] = "completed"
    except START_ERRORS as exc:
        fig = {"exit_reason": f"failed: {exc}"}
    fig["wall_s"] = time.monotonic() - t0
    return fig


def _fmt(v, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def verdict(r: dict, own: dict | None, nominal: dict | None) -> tuple[list[str], bool]:
    """The targets a flight misses (names) and whether it met all."""
    miss = []
    rms = r.get("rms_circle_m")
    if r.get("exit_reason") != "completed" or rms is None:
        return ["completed"], False
    if own and own.get("rms_circle_m") and rms > TARGETS["vs_autopilot"] * own["rms_circle_m"]:
        miss.append("vs autopilot")
    if nominal and nominal.get("rms_circle_m") and rms > TARGETS["vs_nominal"] * nominal["rms_circle_m"]:
        miss.append("vs nominal")
    steady = r.get("summary_steady_m")
    if steady is not None and abs(steady) > TARGETS["steady_m"]:
        miss.append("steady")
    if (r.get("tilt_max_deg") or 0.0) > TARGETS["tilt_deg"]:
        miss.append("tilt")
    return miss, not miss


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="nominal and motor1-15, nlsoc and pd, ArduCopter")
    ap.add_argument("--json", action="store_true", help="text on stderr, one JSON document on stdout")
    ap.add_argument("--firmware", default=None, help="of arducopter,px4 (default both; --quick: arducopter)")
    ap.add_argument("--cells", default=None, help=f"comma-separated, of {','.join(c.name for c in CELLS)}")
    ap.add_argument("--controllers", default=None, help="default nlsoc,loc,pd (--quick: nlsoc,pd)")
    ap.add_argument("--outputs", default=None, help="default attitude,rates (--quick: both)")
    ap.add_argument("--speedup", type=float, default=4.0, help="firmware speed-up of the paced cells (default 4)")
    args = ap.parse_args(argv)
    firmwares = (args.firmware or ("arducopter" if args.quick else "arducopter,px4")).split(",")
    names = args.cells.split(",") if args.cells else (QUICK_CELLS if args.quick else [c.name for c in CELLS])
    unknown = set(names) - {c.name for c in CELLS}
    if unknown or not set(firmwares) <= {"arducopter", "px4"}:
        ap.error(f"unknown cells {sorted(unknown)} or firmware {firmwares}")
    cells = [c for c in CELLS if c.name in names]
    controllers = (args.controllers or ("nlsoc,pd" if args.quick else "nlsoc,loc,pd")).split(",")
    outputs = (args.outputs or "attitude,rates").split(",")
    config = load_config(resolve_config_path(CONFIG))
    mission = Mission(config.mission, zero_velocity=config.experiment.zero_velocity_reference)
    paths = {"arducopter": locate_arducopter(ROOT.parent / "shared" / "arducopter"),
             "px4": os.environ.get("GCS_PX4") or locate_px4(ROOT.parent / "shared" / "px4")}
    lines = [f"{'firmware':10} {'cell':16} {'flyer':16} {'RMS circle':>10} {'x own':>6} {'x nominal':>9} "
             f"{'RMS mission':>11} {'alt steady':>10} {'tilt':>6} {'wall':>6}  exit / missed"]
    results, rows, nominal = [], [], {}
    for fw in firmwares:
        if paths[fw] is None:
            lines.append(f"{fw:10} skipped: firmware not found")
            continue
        for cell in cells:
            params = cell.arducopter if fw == "arducopter" else cell.px4
            if params is None:
                lines.append(f"{fw:10} {cell.name:16} n/a: {fw}'s simulator cannot make this variation")
                print(lines[-1], file=sys.stderr, flush=True)
                continue
            own = fly_own(fw, paths[fw], cell, args.speedup, mission)
            own.update(firmware=fw, cell=cell.name, flyer="autopilot")
            results.append(own)
            lines.append(f"{fw:10} {cell.name:16} {'autopilot':16} {_fmt(own.get('rms_circle_m'), '10.4f')} "
                         f"{'':6} {'':9} {'':11} {_fmt(own.get('steady_state_error_m'), '10.4f')} "
                         f"{_fmt(own.get('tilt_max_deg'), '6.1f')} {own['wall_s']:6.0f}  {own['exit_reason']}")
            print(lines[-1], file=sys.stderr, flush=True)
            for controller in controllers:
                for output in outputs:
                    r = fly_gcs(fw, paths[fw], cell, controller, output, args.speedup, mission)
                    flyer = f"{controller}/{output}"
                    r.update(firmware=fw, cell=cell.name, flyer=flyer)
                    if cell.name == "nominal":
                        nominal[(fw, flyer)] = r
                    base = nominal.get((fw, flyer))
                    miss, ok = verdict(r, own, base)
                    r.update(missed=miss, met=ok)
                    results.append(r)
                    rms = r.get("rms_circle_m")
                    x_own = rms / own["rms_circle_m"] if rms and own.get("rms_circle_m") else None
                    x_nom = rms / base["rms_circle_m"] if rms and base and base.get("rms_circle_m") else None
                    lines.append(f"{fw:10} {cell.name:16} {flyer:16} {_fmt(rms, '10.4f')} {_fmt(x_own, '6.2f')} "
                                 f"{_fmt(x_nom, '9.2f')} {_fmt(r.get('rms_mission_m'), '11.4f')} "
                                 f"{_fmt(r.get('summary_steady_m'), '10.4f')} {_fmt(r.get('tilt_max_deg'), '6.1f')} "
                                 f"{r['wall_s']:6.0f}  {r['exit_reason']}" + (f" / {', '.join(miss)}" if miss else ""))
                    print(lines[-1], file=sys.stderr, flush=True)
                    if rms is not None:
                        rows.append(row(f"{fw} {cell.name} {flyer} RMS circle", rms, "m",
                                        baseline=f"{fw} {cell.name} autopilot's own",
                                        baseline_value=own.get("rms_circle_m"),
                                        target=f"<= {TARGETS['vs_autopilot']} x own, <= {TARGETS['vs_nominal']} x "
                                               "nominal, steady <= 0.01 m, tilt <= 15 deg", met=ok))
    flown = [r for r in results if r["flyer"] != "autopilot"]
    lines.append(f"targets met: {sum(r['met'] for r in flown)} of {len(flown)} flights")
    emit(document("bench_robustness", args.quick, {"flights": results, "speedup": args.speedup,
                                                  "targets": TARGETS}, rows), "\n".join(lines), args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
