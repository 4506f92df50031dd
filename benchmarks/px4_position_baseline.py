"""Baseline for PX4 SIH: the same mission flown by PX4's *own* position controller.

Run: ``python benchmarks/px4_position_baseline.py [--config outdoor-circle] [--duration S] [--speedup S]
[--flights N] [--json]``

What the paper's laws are measured against on PX4 SITL + SIH.  The mission's reference (position,
velocity and the circle's acceleration, from :class:`gcs.mission.Mission`, flown from the take-off
point as ``gcs fly`` flies it) goes to PX4 as SET_POSITION_TARGET_LOCAL_NED at 50 Hz in OFFBOARD:
PX4's multicopter position and attitude controllers do the rest.  Per flight it prints the RMS
position error two ways:

* against PX4's own estimate (LOCAL_POSITION_NED), the figure ``gcs fly`` reports for the laws;
* against SIH's ground truth (HIL_STATE_QUATERNION, which PX4 streams from its simulator's true
  state), and how far PX4's estimate itself is from the truth.

It talks MAVLink with pymavlink directly (nothing of gcs's flight code): a reference, not a product.
The firmware is found as ``bench_autopilots.py`` finds it (``$GCS_PX4`` or ``../shared/px4``).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
from pymavlink import mavutil

from benchlib import document, emit, row

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from gcs.config import load_config
from gcs.config.parse import resolve_config_path
from gcs.mission import Mission
from gcs.vehicles.px4_sitl import Px4Sitl, locate_px4

ROOT = Path(__file__).resolve().parents[1]
OFFBOARD = 6 << 16
EARTH_RADIUS_M = 6371000.0
HIL_STATE_QUATERNION, LOCAL_POSITION_NED = 115, 32


def _interval(m, msg_id: int, hz: float) -> None:
    m.mav.command_long_send(m.target_system, m.target_component, mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                            0, msg_id, 1e6 / hz, 0, 0, 0, 0, 0)


def _send_target(m, boot_ms: int, ref, acc) -> None:
    # paper (x, y, z up) -> NED
    m.mav.set_position_target_local_ned_send(boot_ms, m.target_system, m.target_component,
                                             mavutil.mavlink.MAV_FRAME_LOCAL_NED, 0b0000_1100_0000_0000 | 0,
                                             ref[0], ref[1], -ref[2], ref[3], ref[4], -ref[5],
                                             acc[0], acc[1], -acc[2], 0.0, 0.0)


def fly_once(build: str, mission: Mission, duration_s: float, speedup: float) -> dict:
    """One flight; returns the RMS figures (m) and the sample counts."""
    sitl = Px4Sitl(build, speedup=speedup).start()
    try:
        m = mavutil.mavlink_connection(sitl.url, source_system=255)
        m.wait_heartbeat(timeout=30)
        _interval(m, LOCAL_POSITION_NED, 50.0)
        _interval(m, HIL_STATE_QUATERNION, 50.0)
        origin, lpn = None, []
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline:          # EKF ready: an origin and a local position
            msg = m.recv_match(type=["GPS_GLOBAL_ORIGIN", "LOCAL_POSITION_NED", "SYS_STATUS"], timeout=0.5)
            if msg is None:
                continue
            if msg.get_type() == "GPS_GLOBAL_ORIGIN":
                origin = msg
            elif msg.get_type() == "LOCAL_POSITION_NED":
                lpn.append(msg)
            if origin is not None and len(lpn) > 100:
                break
        else:
            raise RuntimeError("PX4 gave no origin / local position within 60 s")
        time.sleep(3.0 / speedup)                    # pre-arm checks settle (~3 s after boot)
        start = lpn[-1]
        off = (start.x, start.y, -start.z)
        period_s = 0.02 / speedup
        armed_at, t_mission0, samples = None, None, []
        t_wall0 = time.monotonic()
        while True:
            now = time.monotonic()
            if t_mission0 is None:
                ref, acc = mission.reference(0.0), (0.0, 0.0, 0.0)
            else:
                tm = (now - t_mission0) * speedup
                if tm > duration_s:
                    break
                ref, acc = mission.reference(tm), mission.acceleration(tm)
            r = (ref.x + off[0], ref.y + off[1], ref.z + off[2], ref.vx, ref.vy, ref.vz)
            _send_target(m, int((now - t_wall0) * 1000), r, acc)
            if armed_at is None and now - t_wall0 > 1.0 / speedup:
                m.mav.command_long_send(m.target_system, m.target_component, 176, 0, 1, OFFBOARD >> 16, 0, 0, 0, 0, 0)
                m.mav.command_long_send(m.target_system, m.target_component, 400, 0, 1, 0, 0, 0, 0, 0, 0)
            while True:
                msg = m.recv_match(blocking=False)
                if msg is None:
                    break
                typ = msg.get_type()
                if typ == "HEARTBEAT" and msg.get_srcComponent() == 1:
                    if armed_at is None and msg.base_mode & 128 and msg.custom_mode == OFFBOARD:
                        armed_at = t_mission0 = time.monotonic()
                elif t_mission0 is not None and typ == "LOCAL_POSITION_NED":
                    tm = (time.monotonic() - t_mission0) * speedup
                    ref = mission.reference(tm)
                    samples.append(("e", tm, msg.x - ref.x - off[0], msg.y - ref.y - off[1], -msg.z - ref.z - off[2]))
                elif t_mission0 is not None and typ == "HIL_STATE_QUATERNION" and origin is not None:
                    tm = (time.monotonic() - t_mission0) * speedup
                    lat0, lon0 = math.radians(origin.latitude / 1e7), math.radians(origin.longitude / 1e7)
                    n = (math.radians(msg.lat / 1e7) - lat0) * EARTH_RADIUS_M
                    e = (math.radians(msg.lon / 1e7) - lon0) * EARTH_RADIUS_M * math.cos(lat0)
                    ref = mission.reference(tm)
                    samples.append(("t", tm, n - ref.x - off[0], e - ref.y - off[1], 0.0))
            if armed_at is None and now - t_wall0 > 30.0:
                raise RuntimeError("PX4 did not arm in OFFBOARD within 30 s")
            time.sleep(period_s)
        m.mav.command_long_send(m.target_system, m.target_component, 21, 0, 0, 0, 0, 0, 0, 0, 0)  # NAV_LAND
        time.sleep(1.0)
        m.close()
    finally:
        sitl.stop()
    return _figures(samples)


def _figures(samples) -> dict:
    est = np.array([s[1:] for s in samples if s[0] == "e"])
    tru = np.array([s[1:] for s in samples if s[0] == "t"])
    out = {"n_estimate": len(est), "n_truth": len(tru)}
    if len(est):
        out["rms_estimate_m"] = float(np.sqrt(np.mean(np.sum(est[:, 1:4] ** 2, axis=1))))
        out["rms_estimate_xy_m"] = float(np.sqrt(np.mean(np.sum(est[:, 1:3] ** 2, axis=1))))
    if len(tru) and len(est):
        out["rms_truth_xy_m"] = float(np.sqrt(np.mean(np.sum(tru[:, 1:3] ** 2, axis=1))))
        # PX4's estimate against the truth, both as errors to the same reference, at the truth's times
        ex = np.interp(tru[:, 0], est[:, 0], est[:, 1]) - tru[:, 1]
        ey = np.interp(tru[:, 0], est[:, 0], est[:, 2]) - tru[:, 2]
        out["rms_estimate_vs_truth_xy_m"] = float(np.sqrt(np.mean(ex ** 2 + ey ** 2)))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="outdoor-circle")
    ap.add_argument("--duration", type=float, default=15.0, help="mission seconds per flight (default 15)")
    ap.add_argument("--speedup", type=float, default=2.0)
    ap.add_argument("--flights", type=int, default=3)
    ap.add_argument("--json", action="store_true", help="text on stderr, one JSON document on stdout")
    args = ap.parse_args(argv)
    build = os.environ.get("GCS_PX4") or locate_px4(ROOT.parent / "shared" / "px4")
    if build is None:
        print("skipped: PX4 SITL not found ($GCS_PX4 or ../shared/px4)", file=sys.stderr)
        return 0
    config = load_config(resolve_config_path(args.config))
    mission = Mission(config.mission, zero_velocity=config.experiment.zero_velocity_reference)
    flights, lines = [], []
    for i in range(args.flights):
        f = fly_once(build, mission, args.duration, args.speedup)
        flights.append(f)
        lines.append(f"flight {i}: " + " ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}"
                                                for k, v in f.items()))
        print(lines[-1], file=sys.stderr, flush=True)
    rows = []
    for key in ("rms_estimate_m", "rms_truth_xy_m", "rms_estimate_vs_truth_xy_m"):
        vals = [f[key] for f in flights if key in f]
        if vals:
            rows.append(row(f"PX4 position controller {key} (median of {len(vals)})", float(np.median(vals)), "m"))
            lines.append(f"median {key}: {np.median(vals):.3f} m (flights: {', '.join(f'{v:.3f}' for v in vals)})")
    emit(document("px4_position_baseline", False, {"flights": flights, "duration_s": args.duration}, rows),
         "\n".join(lines), args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
