"""The firmware EKF's tilt and horizontal errors, from ArduCopter SITL dataflash logs (issue 13.4).

What ``sitl/copter/ardupilot_emulation/ekf.py`` (``TILT_PROFILE``, ``VELOCITY_GAIN_1_S``,
``POSITION_GAIN_1_S``, ``GROUND_VELOCITY_GAIN_1_S``, ``POSITION_LAG_S``) was measured with.
Fly the firmware with its full dataflash log, e.g.::

    printf 'LOG_BITMASK 176127\\nLOG_DISARMED 0\\n' > /tmp/log.parm
    EXTRA_PARM=/tmp/log.parm INSTANCE=3 ../shared/arducopter/run /tmp/fw
    gcs fly --connect tcp:127.0.0.1:5790 --controller nlsoc --config outdoor-circle --duration 20
    kill "$(cat /tmp/fw/arducopter.pid)"

then ``python benchmarks/ekf_dataflash_fit.py /tmp/fw/logs/00000001.BIN [more.BIN ...]``.  Per log it
prints the AHRS tilt error (``ATT`` minus the simulator's ``SIM`` roll and pitch, 2 s means from the
first ``ATT`` record, which is at arming with ``LOG_DISARMED 0``), the liftoff and ``k_g`` of the
velocity error on the ground (``e_v = a / k_g``); then it fits, over all logs from the liftoff on,
``de_v/dt = a - k_v e_v``, ``de_p/dt = e_v - k_p e_p`` plus a first-order lag of the position behind the
truth, per north/east axis, to ``XKF1`` (the EKF) minus ``SIM2`` (the truth), with ``a`` the false
acceleration of that tilt (N ``-g e_E``, E ``+g e_N``), and prints k_v, k_p, the lag and the RMS of the
data, the model and their difference; and per log the lag of the
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


def liftoff_time(d: dict, climb_m: float = 0.005) -> float:
    """Log time [s] the truth's down position first leaves its value at arming by ``climb_m``."""
    truth, t_arm = d["truth"], d["att"][0, 0]
    after = truth[truth[:, 0] >= t_arm]
    moved = np.abs(after[:, 5] - after[0, 5]) > climb_m
    if not moved.any():
        raise SystemExit("the vehicle never left the ground in this log")
    return float(after[moved.argmax(), 0])


def prepare(d: dict):
    """From the liftoff on: times, EKF-minus-truth (pN, pE, vN, vE) with the error at the liftoff removed
    from the positions, false accelerations N, E.

    On the ground the firmware's position error stays within a few millimetres while its velocity
    reading is 4-10 mm/s off (the land detector holds it); so the model starts at the liftoff.
    """
    ekf, truth = d["ekf"], d["truth"]
    keep = ekf[:, 0] >= liftoff_time(d)
    t = ekf[keep, 0]
    err = ekf[keep, 1:5] - np.column_stack([np.interp(t, truth[:, 0], truth[:, k]) for k in range(1, 5)])
    err[:, 0:2] -= err[0, 0:2]  # the EKF origin is not the simulator's
    return (t, err, *false_acceleration(d, t))


def false_acceleration(d: dict, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The false acceleration (N ``-g e_E``, E ``+g e_N``) [m/s^2] of the AHRS's tilt error at times ``t``."""
    _, roll, pitch = tilt_error_deg(d)
    c, s = math.cos(math.radians(HEADING_DEG)), math.sin(math.radians(HEADING_DEG))
    north, east = np.radians(c * roll - s * pitch), np.radians(s * roll + c * pitch)
    at = d["att"][:, 0]
    return -G * np.interp(t, at, east), G * np.interp(t, at, north)


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


def lag_error(truth: np.ndarray, col: int, lag_s: float, t: np.ndarray) -> np.ndarray:
    """First-order lag (time constant ``lag_s``) of the truth's column ``col`` minus the truth, at ``t``."""
    x = truth[:, col]
    if lag_s <= 0.0:
        return np.zeros(len(t))
    y = np.empty_like(x)
    y[0] = x[0]
    a = 1.0 - np.exp(-np.diff(truth[:, 0], prepend=truth[0, 0]) / lag_s)
    for i in range(1, len(x)):
        y[i] = y[i - 1] + a[i] * (x[i] - y[i - 1])
    return np.interp(t, truth[:, 0], y - x)


def model(theta, t, err, acc_ne, truth):
    """Per axis N, E: the model's (position, velocity) errors for ``theta`` = (k_v, k_p, position lag)."""
    kv, kp, lag = theta
    out = []
    for axis, acc in enumerate(acc_ne):
        lp = lag_error(truth, 1 + axis, lag, t)
        o = simulate(t, acc, kv, kp, err[0, 2 + axis], 0.0)
        out.append((o[:, 0] + lp - lp[0], o[:, 1]))
    return out


def ground_velocity_gain(d: dict) -> float:
    """``k_g`` of ``e_v = a / k_g`` on the ground between arming and liftoff (least squares over N and E)."""
    ekf, truth = d["ekf"], d["truth"]
    k = (ekf[:, 0] >= d["att"][0, 0]) & (ekf[:, 0] < liftoff_time(d))
    t = ekf[k, 0]
    ev = ekf[k, 3:5] - np.column_stack([np.interp(t, truth[:, 0], truth[:, c]) for c in (3, 4)])
    a = np.column_stack(false_acceleration(d, t))
    return float((a * ev).sum() / (ev * ev).sum())


def fit_horizontal(prepared) -> tuple[tuple[float, float, float], float, float]:
    """Least-squares (k_v, k_p, position lag) over ``prepared`` [(t, err, (a_N, a_E), truth), ...];
    with the residual RMS and the RMS of the same k_v, k_p without the lag."""
    from scipy.optimize import least_squares

    def residuals(theta):
        res = []
        for t, err, acc, truth in prepared:
            for axis, (p, v) in enumerate(model(theta, t, err, acc, truth)):
                res += [p - err[:, axis], v - err[:, 2 + axis]]
        return np.concatenate(res)

    fit = least_squares(residuals, [1.5, 1.0, 0.04], bounds=([0.0, 0.0, 0.0], [50.0, 10.0, 0.5]))
    kv, kp, lag = (float(x) for x in fit.x)
    return (kv, kp, lag), math.sqrt(np.mean(fit.fun ** 2)), math.sqrt(np.mean(residuals((kv, kp, 0.0)) ** 2))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("logs", nargs="+", help="dataflash .BIN files")
    args = ap.parse_args(argv)
    data = [load(p) for p in args.logs]
    for path, d in zip(args.logs, data):
        t, roll, pitch = tilt_error_deg(d)
        print(f"{path}: tilt error roll/pitch [deg], 2 s means from arming")
        print("  " + "  ".join(f"{a:g}s {roll[k].mean():.3f}/{pitch[k].mean():.3f}"
                               for a in range(0, int(t[-1]) - 1, 2) for k in [(t >= a) & (t < a + 2)]))
        print(f"  liftoff {liftoff_time(d) - d['att'][0, 0]:.2f} s after arming; on the ground e_v = a / k_g with "
              f"k_g {ground_velocity_gain(d):.2f} 1/s")
    prepared = [(t, err, (an, ae), d["truth"]) for d in data for t, err, an, ae in [prepare(d)]]
    (kv, kp, lag), rms, no_lag = fit_horizontal(prepared)
    print(f"fit from the liftoff: k_v {kv:.2f} 1/s, k_p {kp:.2f} 1/s, position lag {lag:.3f} s (residual RMS "
          f"{rms:.4f}; without the lag {no_lag:.4f})")
    print("log  axis  position RMS data/model/diff [m]   velocity RMS data/model/diff [m/s]")
    for path, (t, err, acc, truth) in zip(args.logs, prepared):
        for axis, (p, v) in enumerate(model((kv, kp, lag), t, err, acc, truth)):
            rms = [math.sqrt(np.mean(x ** 2)) for x in (err[:, axis], p, p - err[:, axis],
                                                         err[:, 2 + axis], v, v - err[:, 2 + axis])]
            print(f"{path[-24:]}  {'NE'[axis]}  " + " / ".join(f"{v:.4f}" for v in rms[:3]) + "   "
                  + " / ".join(f"{v:.4f}" for v in rms[3:]))
    for path, d in zip(args.logs, data):
        print(f"{path[-24:]} height lag behind the truth: " + "; ".join(
            f"{lo:g}-{hi:g} s {lag:.3f} s (RMS left {rms * 1000:.1f} mm)" for (lo, hi), lag, rms in height_lags(d)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
