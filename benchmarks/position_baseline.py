"""The baseline of the paper's laws on a real firmware: the same mission flown by the autopilot's *own* position
controller.

Run: ``python benchmarks/position_baseline.py [--autopilot arducopter|px4] [--config outdoor-circle]
[--speedup S] [--flights N] [--param NAME=VALUE ...] [--json]``

The mission's reference (position, velocity and the circle's acceleration, :class:`gcs.mission.Mission`,
from the take-off point) goes to the autopilot as SET_POSITION_TARGET_LOCAL_NED at 50 Hz, one per
LOCAL_POSITION_NED sample (streamed at 50 Hz), timed on the vehicle's own clock (its ``time_boot_ms``),
so the flight is the same at any speed-up and on a loaded machine:

* **ArduCopter** (GUIDED): armed, MAV_CMD_NAV_TAKEOFF to the mission's height, then — once it holds
  there — the targets from the start of the phase after the take-off; after the mission LAND.
  ArduCopter's position controller (PSC_*: feed-forward of the velocity and acceleration targets,
  PID on the velocity) does the rest.
* **PX4** (OFFBOARD): targets streamed from the ground (PX4 takes off on them), armed; NAV_LAND after.

Per flight: the RMS error of the vehicle's estimate (LOCAL_POSITION_NED) to the reference at the sample's
time over the circle phase (the issue's "same circle", the window :func:`window_errors` measures for
``gcs fly`` flights too) and from the circle to the end, the altitude steady-state error (the mean of
reference z - z over the last second of the last hold/circle phase, as ``gcs fly``'s
``steady_state_error_m``), the largest tilt (ATTITUDE).  It talks MAVLink with pymavlink directly (nothing
of gcs's flight code): a reference, not a product.  The firmware is found as the tests find it
(``$GCS_ARDUCOPTER`` / ``$GCS_PX4`` or ``../shared``).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
from pymavlink import mavutil

from benchlib import document, emit, row

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from gcs.config import load_config
from gcs.config.parse import resolve_config_path
from gcs.mission import Mission
from gcs.vehicles.arducopter_sitl import ArduCopterSitl, locate_arducopter
from gcs.vehicles.px4_sitl import Px4Sitl, locate_px4

ROOT = Path(__file__).resolve().parents[1]
GUIDED, LAND_AC = 4, 9
OFFBOARD = 6 << 16
POS_VEL_ACC = 0b0000_1100_0000_0000          # type_mask: position, velocity, acceleration; no yaw
LOCAL_POSITION_NED, ATTITUDE = 32, 30
RATE_HZ = 50.0


def window_errors(t_s, err_xyz, mission: Mission) -> dict:
    """Figures of position errors ``err_xyz`` (N x 3, estimate - reference, z up) at mission times ``t_s``.

    ``rms_circle_m``: RMS of the error's norm over the circle phases; ``rms_from_circle_m``: from the
    first circle to the end of the mission; ``steady_state_error_m``: the mean of reference z - z over
    :meth:`Mission.hold_window` (gcs fly's definition).  Used for the baseline and for ``gcs fly`` logs alike.
    """
    t = np.asarray(t_s, float)
    e = np.asarray(err_xyz, float).reshape(-1, 3)
    circles = [s for s in mission.segments if s.phase.kind == "circle"]
    out: dict = {"samples": int(len(t))}
    if circles and len(t):
        inside = np.zeros(len(t), bool)
        for s in circles:
            inside |= (t >= s.t_start_s) & (t < s.t_end_s)
        if inside.any():
            out["rms_circle_m"] = float(np.sqrt(np.mean(np.sum(e[inside] ** 2, axis=1))))
        later = t >= circles[0].t_start_s
        out["rms_from_circle_m"] = float(np.sqrt(np.mean(np.sum(e[later] ** 2, axis=1))))
    lo, hi = mission.hold_window(1.0)
    hold = (t >= lo) & (t <= hi)
    if hold.any():
        out["steady_state_error_m"] = float(np.mean(-e[hold, 2]))
    return out


class _Flight:
    """One connection to a firmware SITL and the samples of the flight, on the vehicle's clock."""

    def __init__(self, url: str, mission: Mission) -> None:
        self.m = mavutil.mavlink_connection(url, source_system=255, source_component=190)
        self.mission = mission
        self.boot_ms = 0
        self.armed = False
        self.mode = -1
        self.lpn = None
        self.tilt_max_rad = 0.0
        self.samples: list[tuple[float, float, float, float]] = []

    def command(self, cmd: int, *p: float) -> None:
        p = tuple(p) + (0.0,) * (7 - len(p))
        self.m.mav.command_long_send(self.m.target_system, self.m.target_component, cmd, 0, *p)

    def interval(self, msg_id: int, hz: float) -> None:
        self.command(mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)

    def pump(self, timeout_s: float = 0.2):
        """Messages until one LOCAL_POSITION_NED (returned) or ``timeout_s`` of wall time (None)."""
        while True:
            msg = self.m.recv_match(blocking=True, timeout=timeout_s)
            if msg is None:
                return None
            typ = msg.get_type()
            if msg.get_srcComponent() != 1:
                continue
            if typ == "HEARTBEAT":
                self.armed = bool(msg.base_mode & 128)
                self.mode = int(msg.custom_mode)
            elif typ == "ATTITUDE" and self.armed:
                self.tilt_max_rad = max(self.tilt_max_rad, abs(msg.roll), abs(msg.pitch))
            elif typ == "LOCAL_POSITION_NED":
                self.boot_ms = max(self.boot_ms, int(msg.time_boot_ms))
                self.lpn = msg
                return msg

    def wait(self, predicate, vehicle_s: float, what: str, every=None) -> None:
        """Pump until ``predicate()`` or ``vehicle_s`` of the vehicle's time (``every()`` once per vehicle second)."""
        while self.lpn is None:
            if self.pump(30.0) is None:
                raise RuntimeError("no LOCAL_POSITION_NED within 30 s")
        start = last = self.boot_ms
        while not predicate():
            if self.boot_ms - start > vehicle_s * 1000:
                raise RuntimeError(f"{what}: not within {vehicle_s:g} s of the vehicle's time")
            if every is not None and self.boot_ms - last >= 1000:
                last = self.boot_ms
                every()
            if self.pump(10.0) is None and self.lpn is None:
                raise RuntimeError(f"{what}: the vehicle went silent")

    def target(self, t_s: float, origin) -> None:
        ref, acc = self.mission.reference(t_s), self.mission.acceleration(t_s)
        self.m.mav.set_position_target_local_ned_send(
            self.boot_ms, self.m.target_system, self.m.target_component, mavutil.mavlink.MAV_FRAME_LOCAL_NED,
            POS_VEL_ACC, origin[0] + ref.x, origin[1] + ref.y, origin[2] - ref.z, ref.vx, ref.vy, -ref.vz,
            acc[0], acc[1], -acc[2], 0.0, 0.0)

    def fly_mission(self, t0_s: float, origin, boot0_ms: int) -> None:
        """Targets and samples from mission time ``t0_s`` (at vehicle time ``boot0_ms``) to the mission's end."""
        end = self.mission.segments[-1].t_end_s
        while True:
            msg = self.pump(10.0)
            if msg is None:
                raise RuntimeError("the vehicle went silent during the mission")
            t = t0_s + (int(msg.time_boot_ms) - boot0_ms) / 1000.0
            if t > end:
                return
            ref = self.mission.reference(t)
            self.samples.append((t, msg.x - origin[0] - ref.x, msg.y - origin[1] - ref.y,
                                 (origin[2] - msg.z) - ref.z))
            self.target(t + 1.0 / RATE_HZ, origin)

    def figures(self) -> dict:
        s = np.array(self.samples) if self.samples else np.zeros((0, 4))
        out = window_errors(s[:, 0], s[:, 1:4], self.mission)
        out["tilt_max_deg"] = math.degrees(self.tilt_max_rad)
        return out


def _parm_file(params: dict[str, float], folder: str) -> Path:
    p = Path(folder) / "extra.parm"
    p.write_text("".join(f"{k} {v:g}\n" for k, v in params.items()))
    return p


def fly_arducopter(binary: str, mission: Mission, *, speedup: float = 2.0, params: dict | None = None,
                   model: str = "x") -> dict:
    """One GUIDED flight of ArduCopter SITL with ``params`` added to its defaults (SIM_*, MOT_*, ATC_*)."""
    with tempfile.TemporaryDirectory(prefix="baseline_ac_") as d:
        sitl = ArduCopterSitl(binary, speedup=speedup, model=model)
        if params:
            sitl.defaults.append(_parm_file(params, d))
        sitl.start()
        try:
            f = _Flight(sitl.url, mission)
            f.m.wait_heartbeat(timeout=30)
            f.interval(LOCAL_POSITION_NED, RATE_HZ)
            f.interval(ATTITUDE, RATE_HZ)
            f.command(mavutil.mavlink.MAV_CMD_DO_SET_MODE, 1, GUIDED)
            f.wait(lambda: f.mode == GUIDED, 20.0, "GUIDED", every=lambda: f.command(176, 1, GUIDED))
            f.wait(lambda: f.armed, 90.0, "arming", every=lambda: f.command(400, 1))
            ground = (f.lpn.x, f.lpn.y, f.lpn.z)
            takeoff = next(s for s in mission.segments if s.phase.kind == "takeoff")
            height = takeoff.phase.z_m
            f.command(mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, height)
            f.wait(lambda: ground[2] - f.lpn.z >= height - 0.03, 30.0, "take-off",
                   every=lambda: f.command(22, 0, 0, 0, 0, 0, 0, height))
            settle = f.boot_ms + 2000
            f.wait(lambda: f.boot_ms >= settle, 5.0, "settling")
            f.fly_mission(takeoff.t_end_s, ground, f.boot_ms)
            f.command(mavutil.mavlink.MAV_CMD_DO_SET_MODE, 1, LAND_AC)
            f.wait(lambda: not f.armed, 60.0, "landing", every=lambda: f.command(176, 1, LAND_AC))
            return f.figures()
        finally:
            sitl.stop()


def fly_px4(build: str, mission: Mission, *, speedup: float = 1.0, params: dict | None = None) -> dict:
    """One OFFBOARD flight of PX4 SITL + SIH with ``params`` (PX4_PARAM_* at its start)."""
    sitl = Px4Sitl(build, speedup=speedup, params=params or {})
    sitl.start()
    try:
        f = _Flight(sitl.url, mission)
        f.m.wait_heartbeat(timeout=30)
        f.interval(LOCAL_POSITION_NED, RATE_HZ)
        f.interval(ATTITUDE, RATE_HZ)
        f.wait(lambda: f.lpn is not None, 60.0, "a local position")
        ready = f.boot_ms + 3000                     # pre-arm checks settle (~3 s after the estimate)
        f.wait(lambda: f.boot_ms >= ready, 10.0, "settling")
        ground = (f.lpn.x, f.lpn.y, f.lpn.z)

        def offboard_and_arm() -> None:
            f.command(mavutil.mavlink.MAV_CMD_DO_SET_MODE, 1, OFFBOARD >> 16)
            f.command(400, 1)

        def stream_until_armed() -> bool:
            f.target(0.0, ground)
            return f.armed and f.mode == OFFBOARD

        f.wait(stream_until_armed, 30.0, "OFFBOARD and arming", every=offboard_and_arm)
        f.fly_mission(0.0, ground, f.boot_ms)
        f.command(mavutil.mavlink.MAV_CMD_NAV_LAND)
        f.wait(lambda: not f.armed, 60.0, "landing", every=lambda: f.command(21))
        return f.figures()
    finally:
        sitl.stop()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--autopilot", choices=("arducopter", "px4"), default="arducopter")
    ap.add_argument("--config", default="outdoor-circle")
    ap.add_argument("--speedup", type=float, default=2.0)
    ap.add_argument("--flights", type=int, default=3)
    ap.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                    help="a firmware parameter for the flight (repeatable), e.g. SIM_ENGINE_MUL=0.85")
    ap.add_argument("--json", action="store_true", help="text on stderr, one JSON document on stdout")
    args = ap.parse_args(argv)
    params = {}
    for item in args.param:
        name, _, value = item.partition("=")
        try:
            params[name.strip().upper()] = float(value)
        except ValueError:
            ap.error(f"--param: expected NAME=VALUE, got {item!r}")
    if args.autopilot == "arducopter":
        path = locate_arducopter(ROOT.parent / "shared" / "arducopter")
        fly = fly_arducopter
    else:
        path = os.environ.get("GCS_PX4") or locate_px4(ROOT.parent / "shared" / "px4")
        fly = fly_px4
    if path is None:
        print(f"skipped: {args.autopilot} SITL not found", file=sys.stderr)
        return 0
    config = load_config(resolve_config_path(args.config))
    mission = Mission(config.mission, zero_velocity=config.experiment.zero_velocity_reference)
    flights, lines = [], []
    for i in range(args.flights):
        fig = fly(path, mission, speedup=args.speedup, params=params)
        flights.append(fig)
        lines.append(f"flight {i}: " + " ".join(f"{k} {v:.4f}" if isinstance(v, float) else f"{k} {v}"
                                                for k, v in fig.items()))
        print(lines[-1], file=sys.stderr, flush=True)
    rows = []
    for key in ("rms_circle_m", "rms_from_circle_m", "steady_state_error_m", "tilt_max_deg"):
        vals = [f[key] for f in flights if key in f]
        if vals:
            rows.append(row(f"{args.autopilot} position controller {key} (median of {len(vals)})",
                            float(np.median(vals)), "deg" if key.endswith("deg") else "m"))
            lines.append(f"median {key}: {np.median(vals):.4f} (flights: {', '.join(f'{v:.4f}' for v in vals)})")
    emit(document("position_baseline", False, {"autopilot": args.autopilot, "flights": flights,
                                               "params": params}, rows), "\n".join(lines), args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
