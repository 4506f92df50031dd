"""How late ArduCopter's height estimate is, in the takeoff window and after it (docs/FIDELITY.md).

Fits a first-order lag (time constant tau, free offset) of the simulator's truth (``SIM.Alt``) to
EKF3's estimate (``XKF1.PD``, core 0) of a firmware dataflash log, separately over the takeoff window
(truth liftoff until 0.5 m above the ground or 5 s: where ArduCopter's "takeoff expected" mode gives the
barometer 4x its noise) and over the 8 s after it.  Without ``--bin`` it flies one: ArduCopter SITL at
speed-up 2 (``--arducopter PATH`` or ``$GCS_ARDUCOPTER``), ``gcs fly --controller nlsoc --duration 10``.

    python benchmarks/fidelity_height_lag.py [--bin LOG.BIN] [--arducopter PATH]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

TAUS_S = (0.0, 0.05, 0.08, 0.10, 0.12, 0.15, 0.20, 0.30)
STEP_S = 0.0025


def fly(arducopter: str | None, workdir: Path) -> Path:
    from gcs.vehicles.arducopter_sitl import ArduCopterSitl

    sitl = ArduCopterSitl(arducopter, speedup=2, workdir=workdir).start()
    try:
        p = subprocess.run([sys.executable, "-m", "gcs.cli", "fly", "--connect", sitl.url, "--speedup", "2",
                            "--controller", "nlsoc", "--duration", "10", "--no-log", "-q"],
                           capture_output=True, text=True, timeout=600)
        if p.returncode != 0:
            raise SystemExit(f"gcs fly exited {p.returncode}: {p.stderr[-1500:]}")
    finally:
        sitl.stop()
    logs = sorted(workdir.rglob("*.BIN"))
    if not logs:
        raise SystemExit(f"no dataflash log under {workdir}")
    return logs[-1]


def read(path: Path) -> tuple[np.ndarray, np.ndarray]:
    from pymavlink import DFReader

    log = DFReader.DFReader_binary(str(path))
    sim, ekf = [], []
    while (m := log.recv_match(type=["SIM", "XKF1"])) is not None:
        if m.get_type() == "SIM":
            sim.append((m.TimeUS * 1e-6, m.Alt))
        elif m.C == 0:
            ekf.append((m.TimeUS * 1e-6, m.PD))
    return np.array(sim), np.array(ekf)


def lagged(h: np.ndarray, tau_s: float) -> np.ndarray:
    if tau_s <= 0.0:
        return h.copy()
    a, s, out = 1.0 - np.exp(-STEP_S / tau_s), h[0], np.empty_like(h)
    for i, v in enumerate(h):
        s += (v - s) * a
        out[i] = s
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", type=Path, help="a firmware dataflash log (default: fly one)")
    ap.add_argument("--arducopter", help="the ArduCopter SITL binary or its directory")
    args = ap.parse_args(argv)
    tmp = None
    if args.bin is None:
        tmp = Path(tempfile.mkdtemp(prefix="height-lag-"))
    try:
        sim, ekf = read(args.bin if args.bin is not None else fly(args.arducopter, tmp))
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    h = sim[:, 1] - np.median(sim[:50, 1])
    t_lift = sim[np.argmax(h > 0.01), 0]
    t_end = min(sim[np.argmax(h > 0.5), 0], t_lift + 5.0)
    t_est, h_est = ekf[:, 0], -(ekf[:, 1] - np.median(ekf[ekf[:, 0] < t_lift - 1.0, 1]))
    grid = np.arange(sim[0, 0], sim[-1, 0], STEP_S)
    truth = np.interp(grid, sim[:, 0], h)
    windows = {"takeoff": (t_lift - 0.2, t_end), "after": (t_end, t_end + 8.0)}
    print(f"takeoff window {t_end - t_lift:.2f} s (truth liftoff to 0.5 m); residual RMS [mm] / offset [mm]")
    for tau in TAUS_S:
        model = np.interp(t_est, grid, lagged(truth, tau))
        cells = []
        for name, (a, b) in windows.items():
            r = (h_est - model)[(t_est >= a) & (t_est < b)]
            cells.append(f"{name} {np.sqrt(np.mean((r - r.mean()) ** 2)) * 1e3:5.1f} / {r.mean() * 1e3:+5.1f}")
        print(f"tau {tau:4.2f} s: " + "   ".join(cells))
    late = t_est[np.argmax((h_est > 0.05) & (t_est > t_lift - 1.0))] - sim[np.argmax(h > 0.05), 0]
    print(f"the estimate crossed 5 cm {late:.2f} s after the truth")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
