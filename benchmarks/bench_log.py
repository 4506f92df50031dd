"""MCAP logging cost (issue: logging and log review).

Run: ``python benchmarks/bench_log.py [--quick] [--json]``.  Prints

* the logging cost of one control tick (``FlightLog.control_tick``): median over
  batches of the time per tick, for the 6-message tick (state, reference, error,
  command, horizon, truth) and for a flight-like 13-message tick (plus limited
  command, cost, loop timing, 2 MAVLink messages in and 1 out with their raw frames);
  target <= 50 us for the 6-message tick;
* the simulation speed without a log, with the log written in-process and with the
  background writer process (what ``gcs sim`` uses), in simulated seconds per wall second;
* ``gcs log metrics`` on a 10-minute 100 Hz flight log (the library call, and the
  whole command in a fresh interpreter): target <= 3 s; and the log size per tick.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from gcs.config import load_config
from gcs.control import make_controller
from gcs.log import FlightLog
from gcs.log.meta import write_run_header
from gcs.log.review import log_metrics
from gcs.log.simlog import BackgroundSimLog
from gcs.model import Command, State
from gcs.sim import SimOptions, simulate

TARGET_TICK_US = 50.0
TARGET_METRICS_S = 3.0


class _Msg:
    """Stands in for a pymavlink message."""

    def __init__(self, mtype: str, fields: dict, size: int) -> None:
        self.t, self.f, self.b = mtype, fields, bytes(range(size))

    def get_type(self) -> str:
        return self.t

    def to_dict(self) -> dict:
        return dict(self.f)

    def get_msgbuf(self) -> bytes:
        return self.b


def _inputs(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    states = [State(*v) for v in rng.normal(size=(n, 12)).tolist()]
    refs = [State(*v) for v in rng.normal(size=(n, 12)).tolist()]
    cmds = [Command(*v) for v in rng.normal(size=(n, 4)).tolist()]
    return states, refs, cmds


def bench_tick(path: Path, batches: int, per_batch: int, flight_like: bool) -> tuple[float, float]:
    """Median microseconds of logging one control tick: wall time, and this thread's CPU time
    (less sensitive to other processes on a shared machine)."""
    states, refs, cmds = _inputs(per_batch)
    att = _Msg("ATTITUDE", {"time_boot_ms": 1, "roll": 0.01, "pitch": -0.02, "yaw": 1.5, "rollspeed": 0.001,
                            "pitchspeed": 0.002, "yawspeed": 0.0}, 40)
    pos = _Msg("LOCAL_POSITION_NED", {"time_boot_ms": 1, "x": 1.0, "y": 2.0, "z": -1.5, "vx": 0.1, "vy": 0.0,
                                      "vz": -0.01}, 40)
    sat = _Msg("SET_ATTITUDE_TARGET", {"time_boot_ms": 1, "target_system": 1, "target_component": 1,
                                       "type_mask": 0, "q": [1.0, 0.0, 0.0, 0.0], "body_roll_rate": 0.0,
                                       "body_pitch_rate": 0.0, "body_yaw_rate": 0.0, "thrust": 0.39}, 51)
    times, cpu = [], []
    t_ns = 0
    with FlightLog(path) as log:
        for _ in range(batches):
            c0 = time.thread_time()
            t0 = time.perf_counter()
            for i in range(per_batch):
                t_ns += 10_000_000
                if flight_like:
                    log.mavlink(t_ns, "in", att)
                    log.mavlink(t_ns, "in", pos)
                    log.control_tick(t_ns, state=states[i], reference=refs[i], command=cmds[i],
                                     command_limited=cmds[i], k=i, steps_to_go=100, cost=(1.0, 2.0, 3.0))
                    log.mavlink(t_ns, "out", sat)
                    log.loop_timing(t_ns, k=i, jitter_s=1e-4, tick_s=3e-4, deadline_missed=False)
                else:
                    log.control_tick(t_ns, state=states[i], reference=refs[i], command=cmds[i], k=i,
                                     steps_to_go=100, truth=states[i])
            times.append((time.perf_counter() - t0) / per_batch * 1e6)
            cpu.append((time.thread_time() - c0) / per_batch * 1e6)
    return statistics.median(times), statistics.median(cpu)


def bench_sim(config, duration_s: float, repeats: int, mode: str, tmp: Path) -> float:
    """Median simulated seconds per wall second of one nlsoc flight, without / with a log."""
    designed = make_controller("nlsoc", config)
    ratios = []
    for r in range(repeats):
        path = tmp / f"sim_{mode}_{r}.mcap"
        t0 = time.perf_counter()
        if mode == "none":
            simulate(config, "nlsoc", run=r, options=SimOptions(duration_s=duration_s), designed=designed)
        elif mode == "inline":
            with FlightLog(path) as log:
                simulate(config, "nlsoc", run=r, options=SimOptions(duration_s=duration_s), designed=designed, log=log)
        else:
            with BackgroundSimLog(path) as log:
                simulate(config, "nlsoc", run=r, options=SimOptions(duration_s=duration_s), designed=designed, log=log)
        ratios.append(duration_s / (time.perf_counter() - t0))
    return statistics.median(ratios)


def bench_sim_runs(config, duration_s: float, runs: int, tmp: Path) -> tuple[float, float]:
    """Wall seconds of ``runs`` flights of three controllers (as ``gcs sim``) without and with the background log."""
    from gcs.sim import run_experiment

    ctls = ("nlsoc", "loc", "pd")
    opts = SimOptions(duration_s=duration_s)
    t0 = time.perf_counter()
    run_experiment(config, ctls, runs=runs, options=opts)
    plain = time.perf_counter() - t0
    t0 = time.perf_counter()
    with BackgroundSimLog(tmp / "runs.mcap") as log:
        run_experiment(config, ctls, runs=runs, options=opts, log=log)
    logged = time.perf_counter() - t0
    return plain, logged


def make_flight_log(path: Path, config, minutes: float) -> int:
    """A flight-like log (estimates only, limited commands, timing, MAVLink) of ``minutes`` at 100 Hz."""
    n = int(minutes * 60 * 100)
    states, refs, cmds = _inputs(1000, seed=1)
    att = _Msg("ATTITUDE", {"roll": 0.01, "pitch": -0.02, "yaw": 1.5}, 40)
    with FlightLog(path) as log:
        write_run_header(log, config, ["loc"], {}, source="flight")
        log.flight_start(0, controller="loc", experiment=config.experiment.name, ts_s=0.01)
        for k in range(n):
            t = k * 10_000_000
            i = k % 1000
            log.mavlink(t, "in", att)
            log.control_tick(t, state=states[i], reference=refs[i], command=cmds[i], command_limited=cmds[i], k=k,
                             steps_to_go=max(0, 60000 - k), cost=(1.0, 2.0, 3.0))
            log.loop_timing(t, k=k, jitter_s=1e-4, tick_s=3e-4, deadline_missed=False)
    return n


def time_metrics(path: Path, repeats: int) -> tuple[float, float]:
    """Median seconds of log_metrics(path) in this process, and of ``gcs log metrics`` in a fresh one."""
    lib, cli = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        log_metrics(path)
        lib.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        p = subprocess.run([sys.executable, "-m", "gcs.cli", "log", "metrics", str(path), "--json"],
                           capture_output=True, text=True)
        cli.append(time.perf_counter() - t0)
        if p.returncode != 0:
            raise SystemExit(f"gcs log metrics failed: {p.stderr}")
    return statistics.median(lib), statistics.median(cli)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="fewer repetitions, shorter flights")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    batches, per_batch, repeats = (5, 1000, 1) if args.quick else (15, 2000, 3)
    sim_s = 20.0 if args.quick else 60.0
    out: dict = {}
    with tempfile.TemporaryDirectory(prefix="bench_log_") as d:
        tmp = Path(d)
        out["tick_6msg_median_us"], out["tick_6msg_cpu_us"] = bench_tick(tmp / "tick6.mcap", batches, per_batch,
                                                                         flight_like=False)
        out["tick_13msg_median_us"], out["tick_13msg_cpu_us"] = bench_tick(tmp / "tick13.mcap", batches, per_batch,
                                                                           flight_like=True)
        circle = load_config("outdoor-circle")
        for mode in ("none", "inline", "background"):
            out[f"sim_realtime_ratio_{mode}"] = bench_sim(circle, sim_s, repeats, mode, tmp)
        altitude = load_config("outdoor-altitude")
        run_s = 120.0 if args.quick else 600.0
        plain, logged = bench_sim_runs(altitude, run_s, 1, tmp)
        out["sim_runs_flight_s"] = run_s
        out["sim_runs_wall_s_no_log"], out["sim_runs_wall_s_background_log"] = plain, logged

        sim_path = tmp / "sim10min.mcap"
        minutes = 2.0 if args.quick else 10.0
        with FlightLog(sim_path) as log:
            write_run_header(log, altitude, ["nlsoc"], {})
            simulate(altitude, "nlsoc", options=SimOptions(duration_s=minutes * 60), log=log)
        ticks = int(minutes * 6000)
        out["sim_log_minutes"] = minutes
        out["sim_log_bytes_per_tick"] = sim_path.stat().st_size / ticks
        out["metrics_sim_log_s"], out["metrics_sim_log_cli_s"] = time_metrics(sim_path, repeats)
        flight_path = tmp / "flight10min.mcap"
        n = make_flight_log(flight_path, altitude, minutes)
        out["flight_log_bytes_per_tick"] = flight_path.stat().st_size / n
        out["metrics_flight_log_s"], out["metrics_flight_log_cli_s"] = time_metrics(flight_path, repeats)
    if args.json:
        print(json.dumps(out))
        return 0
    ok = lambda v, target: "ok" if v <= target else "MISSED"
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} CPU(s); medians")
    print(f"log one control tick, 6 messages (state, reference, error, command, horizon, truth): "
          f"{out['tick_6msg_median_us']:.1f} us ({out['tick_6msg_cpu_us']:.1f} us CPU)  (target <= {TARGET_TICK_US:g} us: "
          f"{ok(out['tick_6msg_median_us'], TARGET_TICK_US)})")
    print(f"log one flight-like tick, 13 messages (+ limited command, cost, timing, 3 MAVLink + raw): "
          f"{out['tick_13msg_median_us']:.1f} us ({out['tick_13msg_cpu_us']:.1f} us CPU)")
    print(f"simulation x real time, outdoor-circle {sim_s:g} s nlsoc flight: no log "
          f"{out['sim_realtime_ratio_none']:.0f}, log in-process {out['sim_realtime_ratio_inline']:.0f}, "
          f"background writer {out['sim_realtime_ratio_background']:.0f}")
    print(f"gcs sim-like run (outdoor-altitude, nlsoc + loc + pd, {out['sim_runs_flight_s']:g} s each): "
          f"{out['sim_runs_wall_s_no_log']:.2f} s without log, "
          f"{out['sim_runs_wall_s_background_log']:.2f} s with the background log "
          f"(+{(out['sim_runs_wall_s_background_log'] / out['sim_runs_wall_s_no_log'] - 1) * 100:.0f} %)")
    print(f"log size: {out['sim_log_bytes_per_tick']:.0f} B per simulated tick, "
          f"{out['flight_log_bytes_per_tick']:.0f} B per flight-like tick (zstd)")
    for kind in ("sim", "flight"):
        lib, cli = out[f"metrics_{kind}_log_s"], out[f"metrics_{kind}_log_cli_s"]
        print(f"gcs log metrics, {minutes:g}-minute 100 Hz {kind} log: {lib:.2f} s (library), {cli:.2f} s (command) "
              f"(target <= {TARGET_METRICS_S:g} s: {ok(cli, TARGET_METRICS_S)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
