"""The firmware EKF's tilt and horizontal errors, from ArduCopter SITL dataflash logs (issue 13.4).

What ``sitl/copter/ardupilot_emulation/ekf.py`` (``TILT_PROFILE``, ``VELOCITY_GAIN_1_S``,
``POSITION_GAIN_1_S``) was measured with.  Fly the firmware with its full dataflash log, e.g.::

    printf 'LOG_BITMASK 176127\\nLOG_DISARMED 0\\n' > /tmp/log.parm
    EXTRA_PARM=/tmp/log.parm INSTANCE=3 ../shared/arducopter/run /tmp/fw
    gcs fly --connect tcp:127.0.0.1:5790 --controller nlsoc --config outdoor-circle --duration 20
    kill "$(cat /tmp/fw/arducopter.pid)"

then ``python benchmarks/ekf_dataflash_fit.py /tmp/fw/logs/00000001.BIN [more.BIN ...]``.  Per log it
prints the AHRS tilt error (``ATT`` minus the simulator's ``SIM`` roll and pitch, 2 s means from the
first ``ATT`` record, which is at arming with ``LOG_DISARMED 0``); then it fits, over all logs,
``de_v/dt = a - k_v e_v``, ``de_p/dt = e_v - k_p e_p`` per north/east axis to ``XKF1`` (the EKF) minus
``SIM2`` (the truth), with ``a`` the false acceleration of that tilt (N ``-g e_E``, E ``+g e_N``), and
prints k_v, k_p and the RMS of the data, the model and their difference; and per log the lag of the
EKF's height (``XKF1.PD``) behind the truth (``SIM2.PD``) in windows of the outdoor-circle flight
(seconds from arming: the climb, its stop, the landing).  Needs pymavlink and scipy.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

G = 9.81
HEADING_DEG = -4.8  # the firmware SITL's heading (--home ... 353, then its EKF)


def load(path: str) -> dict[str, np.ndarray]:
    from pymavlink import DFReader

    if not Path(path).is_file():
        raise SystemExit(f"{path}: no such dataflash log")
    log = DFReader.DFReader_binary(path)
    rows: dict[str, list] = {"ekf": [], "truth": [], "att": [], "sim": []}
    while (m := log.recv_msg()) is not None:
        t = m.get_type()
        if t == "XKF1" and m.C == 0:
            rows["ekf"].append((m.TimeUS * 1e-6, m.PN, m.PE, m.VN, m.VE, m.PD))
        elif t == "SIM2":
            rows["truth"].append((m.TimeUS * 1e-6, m.PN, m.PE, m.VN, m.VE, m.PD))
        elif t == "ATT":
            rows["att"].append((m.TimeUS * 1e-6, m.Roll, m.Pitch))
        elif t == "SIM":
            rows["sim"].append((m.TimeUS * 1e-6, m.Roll, m.Pitch))
    out = {k: np.array(v) for k, v in rows.items()}
    if any(len(v) == 0 for v in out.values()):
        raise SystemExit(f"{path}: needs XKF1, SIM2, ATT and SIM records (LOG_BITMASK 176127)")
    return out


def tilt_error_deg(d: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time since the first ATT record [s], reported minus true roll and pitch [deg]."""
    att, sim = d["att"], d["sim"]
    roll = att[:, 1] - np.interp(att[:, 0], sim[:, 0], sim[:, 1])
    pitch = att[:, 2] - np.interp(att[:, 0], sim[:, 0], sim[:, 2])
    return att[:, 0] - att[0, 0], roll, pitch


def prepare(d: dict):
    """Times, EKF-minus-truth (pN, pE, vN, vE) with the origin offset removed, false accelerations N, E."""
    ekf, truth = d["ekf"], d["truth"]
    t = ekf[:, 0]
    err = ekf[:, 1:5] - np.column_stack([np.interp(t, truth[:, 0], truth[:, k]) for k in range(1, 5)])
    err[:, 0:2] -= err[:3, 0:2].mean(axis=0)  # the EKF origin is not the simulator's
    _, roll, pitch = tilt_error_deg(d)
    c, s = math.cos(math.radians(HEADING_DEG)), math.sin(math.radians(HEADING_DEG))
    north, east = np.radians(c * roll - s * pitch), np.radians(s * roll + c * pitch)
    at = d["att"][:, 0]
    return t, err, -G * np.interp(t, at, east), G * np.interp(t, at, north)


HEIGHT_WINDOWS_S = ((4.5, 7.0), (7.0, 10.5), (10.5, 13.5), (24.0, 27.5))


def height_lags(d: dict) -> list[tuple[tuple[float, float], float, float]]:
    """Per window (s from arming): the lag [s] of the EKF's down position behind the truth (-0.1..0.4 s,
    an offset removed) and the RMS left [m]."""
    ekf, truth = d["ekf"], d["truth"]
    t = ekf[:, 0] - d["att"][0, 0]
    out = []
    for lo, hi in HEIGHT_WINDOWS_S:
        k = (t >= lo) & (t < hi)
        if k.sum() < 10:
            continue
        best = None
        for lag in np.arange(-0.1, 0.405, 0.005):
            e = ekf[k, 5] - np.interp(ekf[k, 0] - lag, truth[:, 0], truth[:, 5])
            rms = float(np.sqrt(np.mean((e - e.mean()) ** 2)))
            if best is None or rms < best[1]:
                best = (float(lag), rms)
        out.append(((lo, hi), *best))
    return out


def simulate(t, acc, kv, kp, v0, p0, h=0.0025):
    ev, ep, out = v0, p0, np.zeros((len(t), 2))
    for i in range(len(t)):
        out[i] = ep, ev
        if i + 1 < len(t):
            n = max(1, int((t[i + 1] - t[i]) / h))
            dt = (t[i + 1] - t[i]) / n
            for _ in range(n):
                ev, ep = ev + dt * (acc[i] - kv * ev), ep + dt * (ev - kp * ep)
    return out


def main(argv=None) -> int:
    from scipy.optimize import least_squares

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("logs", nargs="+", help="dataflash .BIN files")
    args = ap.parse_args(argv)
    data = [load(p) for p in args.logs]
    for path, d in zip(args.logs, data):
        t, roll, pitch = tilt_error_deg(d)
        print(f"{path}: tilt error roll/pitch [deg], 2 s means from arming")
        print("  " + "  ".join(f"{a:g}s {roll[k].mean():.3f}/{pitch[k].mean():.3f}"
                               for a in range(0, int(t[-1]) - 1, 2) for k in [(t >= a) & (t < a + 2)]))
    prepared = [prepare(d) for d in data]

    def residuals(theta):
        kv, kp = theta
        res = []
        for t, err, an, ae in prepared:
            for axis, acc in ((0, an), (1, ae)):
                o = simulate(t, acc, kv, kp, err[0, 2 + axis], err[0, axis])
                res += [o[:, 0] - err[:, axis], o[:, 1] - err[:, 2 + axis]]
        return np.concatenate(res)

    fit = least_squares(residuals, [1.5, 0.3], bounds=([0.0, 0.0], [50.0, 10.0]))
    kv, kp = fit.x
    print(f"fit: k_v {kv:.2f} 1/s, k_p {kp:.2f} 1/s (residual RMS {math.sqrt(np.mean(fit.fun ** 2)):.4f})")
    print("log  axis  position RMS data/model/diff [m]   velocity RMS data/model/diff [m/s]")
    for path, (t, err, an, ae) in zip(args.logs, prepared):
        for axis, acc, name in ((0, an, "N"), (1, ae, "E")):
            o = simulate(t, acc, kv, kp, err[0, 2 + axis], err[0, axis])
            rms = [math.sqrt(np.mean(x ** 2)) for x in (err[:, axis], o[:, 0], o[:, 0] - err[:, axis],
                                                         err[:, 2 + axis], o[:, 1], o[:, 1] - err[:, 2 + axis])]
            print(f"{path[-24:]}  {name}  " + " / ".join(f"{v:.4f}" for v in rms[:3]) + "   "
                  + " / ".join(f"{v:.4f}" for v in rms[3:]))
    for path, d in zip(args.logs, data):
        print(f"{path[-24:]} height lag behind the truth: " + "; ".join(
            f"{lo:g}-{hi:g} s {lag:.3f} s (RMS left {rms * 1000:.1f} mm)" for (lo, hi), lag, rms in height_lags(d)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
