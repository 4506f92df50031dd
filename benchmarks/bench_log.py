"""MCAP logging cost (issue: logging and log review).

Run: ``python benchmarks/bench_log.py [--quick] [--json]`` (``--json``: the text on
stderr, one JSON document on stdout, see ``benchlib.py``).  Prints

* the logging cost of one control tick (``FlightLog.control_tick``): median over
  batches of the time per tick, for the 6-message tick (state, reference, error,
  command, horizon, truth) and for a flight-like 13-message tick (plus limited
  command, cost, loop timing, 2 MAVLink messages in and 1 out with their raw frames);
  target <= 50 us for the 6-message tick;
* the simulation speed without a log, with the log written in-process and with the
  background writer process (what ``gcs sim`` uses), in simulated seconds per wall second;
* what ``gcs fly`` pays per control tick to log it (:class:`gcs.log.recorder.FlightRecorder`
  into the writer process, real pymavlink frames: ATTITUDE and LOCAL_POSITION_NED in,
  SET_ATTITUDE_TARGET out, plus the tick): median us back to back and paced at 100 Hz (a
  sleep between ticks, as in flight; on this VM cold caches after a sleep slow every piece of
  Python, so the same pacing is measured for the estimator + controller step as a baseline);
  target <= 50 us;
* ``gcs log metrics`` on a 10-minute 100 Hz flight log (the library call, and the
  whole command in a fresh interpreter): target <= 3 s; and the log size per tick.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchlib import document, emit, row
from gcs.config import load_config
from gcs.control import make_controller
from gcs.log.writer import FlightLog
from gcs.log.meta import write_run_header
from gcs.log.review import log_metrics
from gcs.log.records import LoopTiming
from gcs.log.sink import BackgroundSink
from quadrotor.state import Command, State
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
            with BackgroundSink(path, overflow="wait") as log:
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
    with BackgroundSink(tmp / "runs.mcap", overflow="wait") as log:
        run_experiment(config, ctls, runs=runs, options=opts, log=log)
    logged = time.perf_counter() - t0
    return plain, logged


def _mavlink_frames():
    """Real pymavlink messages as gcs fly sees them each tick (packed, so they have their bytes)."""
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    m = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    att = m.attitude_encode(100, 0.01, -0.02, 1.5, 0.001, 0.002, 0.0)
    pos = m.local_position_ned_encode(100, 1.0, 2.0, -1.5, 0.1, 0.0, -0.01)
    sat = m.set_attitude_target_encode(100, 1, 1, 0, (1.0, 0.0, 0.0, 0.0), 0.0, 0.0, 0.0, 0.39)
    for msg in (att, pos, sat):
        msg.pack(m)
    return att, pos, sat


def _fly_tick(rec, k: int, frames, state, ref, cmd) -> None:
    att, pos, sat = frames
    t = k * 10_000_000
    rec.mavlink(t, "in", att)
    rec.mavlink(t, "in", pos)
    rec.mavlink(t, "out", sat)
    rec.tick(t, k, state, ref, cmd, cmd, max(0, 60000 - k), "horizon",
             LoopTiming(1e-5, 3e-4, False, 1e-4, 1e-5, 2e-5, 1e-4, 3e-5))


def bench_fly_tick(tmp: Path, ticks: int, paced_ticks: int) -> dict:
    """Median and p99 us of what gcs fly's loop pays to log one tick, and the paced baseline."""
    from gcs.config import load_config as _load
    from gcs.estimate import StateEstimator
    from gcs.log.recorder import FlightRecorder
    from gcs.model import ModelParams

    frames = _mavlink_frames()
    states, refs, cmds = _inputs(1000, seed=2)
    out = {}
    for label, n, pause in (("back_to_back", ticks, 0.0), ("paced_100hz", paced_ticks, 0.0097)):
        rec = FlightRecorder(BackgroundSink(tmp / f"fly_{label}.mcap"))
        rec.flight_start(0, controller="nlsoc", experiment="x", ts_s=0.01, steps=n, cost=None)
        samples = []
        for k in range(n):
            i = k % 1000
            t0 = time.perf_counter_ns()
            _fly_tick(rec, k, frames, states[i], refs[i], cmds[i])
            samples.append(time.perf_counter_ns() - t0)
            if pause:
                time.sleep(pause)
        rec.close()
        samples.sort()
        out[f"fly_log_{label}_median_us"] = samples[len(samples) // 2] / 1000
        out[f"fly_log_{label}_p99_us"] = samples[int(len(samples) * 0.99)] / 1000
        out[f"fly_log_{label}_dropped"] = rec.stats.get("dropped", 0)
    # Baseline at the same pacing: the estimator predict + the controller step of a tick.
    cfg = _load("outdoor-circle")
    ctl = make_controller("nlsoc", cfg)
    est = StateEstimator(0.01, ModelParams(1.0, 9.81), (0.05,) * 3, 1.0)
    est.correct_position((0.0, 0.0, 1.0))
    samples = []
    for k in range(paced_ticks):
        t0 = time.perf_counter_ns()
        est.predict(0.01, cmds[k % 1000])
        ctl.step(k, est.state(), refs[k % 1000])
        samples.append(time.perf_counter_ns() - t0)
        time.sleep(0.0097)
    samples.sort()
    out["paced_100hz_estimate_control_median_us"] = samples[len(samples) // 2] / 1000
    return out


def make_flight_log(path: Path, config, minutes: float) -> int:
    """A gcs fly log of ``minutes`` at 100 Hz as the flight loop writes it (recorder -> writer process):
    per tick the control topics, timing and three MAVLink frames decoded and raw."""
    from gcs.log.meta import run_attachments, run_metadata
    from gcs.log.recorder import FlightRecorder
    from gcs.metrics import controller_cost

    n = int(minutes * 60 * 100)
    states, refs, cmds = _inputs(1000, seed=1)
    frames = _mavlink_frames()
    rec = FlightRecorder(BackgroundSink(path))
    rec.header(run_metadata(config, ["loc"], source="flight"), run_attachments(config, {}))
    rec.flight_start(0, controller="loc", experiment=config.experiment.name, ts_s=0.01, steps=n,
                     cost=controller_cost("loc", config).to_dict(1.0, 9.81))
    for k in range(n):
        i = k % 1000
        _fly_tick(rec, k, frames, states[i], refs[i], cmds[i])
    rec.flight_end(n * 10_000_000, states[0], refs[0])
    rec.close()
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
        out.update(bench_fly_tick(tmp, 2000 if args.quick else 10000, 300 if args.quick else 1000))
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
    lines = []
    print_ = lines.append

    def ok(v, target):
        return "ok" if v <= target else "MISSED"

    print_(f"python {sys.version.split()[0]}, {os.cpu_count()} CPU(s); medians")
    print_(f"log one control tick, 6 messages (state, reference, error, command, horizon, truth): "
           f"{out['tick_6msg_median_us']:.1f} us ({out['tick_6msg_cpu_us']:.1f} us CPU)  "
           f"(target <= {TARGET_TICK_US:g} us: "
           f"{ok(out['tick_6msg_median_us'], TARGET_TICK_US)})")
    print_(f"log one flight-like tick, 13 messages (+ limited command, cost, timing, 3 MAVLink + raw): "
           f"{out['tick_13msg_median_us']:.1f} us ({out['tick_13msg_cpu_us']:.1f} us CPU)")
    print_(f"gcs fly: logging one control tick (recorder -> writer process; 3 MAVLink frames + the tick): "
           f"median {out['fly_log_back_to_back_median_us']:.1f} us back to back "
           f"(p99 {out['fly_log_back_to_back_p99_us']:.0f}), "
           f"{out['fly_log_paced_100hz_median_us']:.1f} us paced at 100 Hz "
           f"(p99 {out['fly_log_paced_100hz_p99_us']:.0f}) "
           f"(target <= {TARGET_TICK_US:g} us: {ok(out['fly_log_paced_100hz_median_us'], TARGET_TICK_US)}); "
           f"baseline at 100 Hz: estimator + nlsoc step {out['paced_100hz_estimate_control_median_us']:.1f} us; "
           f"records dropped {out['fly_log_back_to_back_dropped'] + out['fly_log_paced_100hz_dropped']}")
    print_(f"simulation x real time, outdoor-circle {sim_s:g} s nlsoc flight: no log "
           f"{out['sim_realtime_ratio_none']:.0f}, log in-process {out['sim_realtime_ratio_inline']:.0f}, "
           f"background writer {out['sim_realtime_ratio_background']:.0f}")
    print_(f"gcs sim-like run (outdoor-altitude, nlsoc + loc + pd, {out['sim_runs_flight_s']:g} s each): "
           f"{out['sim_runs_wall_s_no_log']:.2f} s without log, "
           f"{out['sim_runs_wall_s_background_log']:.2f} s with the background log "
           f"(+{(out['sim_runs_wall_s_background_log'] / out['sim_runs_wall_s_no_log'] - 1) * 100:.0f} %)")
    print_(f"log size: {out['sim_log_bytes_per_tick']:.0f} B per simulated tick, "
           f"{out['flight_log_bytes_per_tick']:.0f} B per flight-like tick (zstd)")
    for kind in ("sim", "flight"):
        lib, cli = out[f"metrics_{kind}_log_s"], out[f"metrics_{kind}_log_cli_s"]
        print_(f"gcs log metrics, {minutes:g}-minute 100 Hz {kind} log: {lib:.2f} s (library), {cli:.2f} s (command) "
               f"(target <= {TARGET_METRICS_S:g} s: {ok(cli, TARGET_METRICS_S)})")
    emit(document("log", args.quick, out, _rows(out, minutes)), "\n".join(lines), args.json)
    return 0


def _rows(out: dict, minutes: float) -> list[dict]:
    """The report's rows: each figure beside its baseline."""
    rows = [
        row("log one control tick, 6 messages (in-process FlightLog)", out["tick_6msg_median_us"], "us",
            baseline="its CPU time", baseline_value=out["tick_6msg_cpu_us"], target=f"<= {TARGET_TICK_US:g} us",
            met=out["tick_6msg_median_us"] <= TARGET_TICK_US),
        row("gcs fly: log one tick, paced at 100 Hz", out["fly_log_paced_100hz_median_us"], "us",
            baseline="estimator + nlsoc step, same pacing",
            baseline_value=out["paced_100hz_estimate_control_median_us"],
            target=f"<= {TARGET_TICK_US:g} us", met=out["fly_log_paced_100hz_median_us"] <= TARGET_TICK_US,
            note=f"p99 {out['fly_log_paced_100hz_p99_us']:.0f} us"),
        row("gcs fly: log one tick, back to back", out["fly_log_back_to_back_median_us"], "us",
            baseline="estimator + nlsoc step, paced", baseline_value=out["paced_100hz_estimate_control_median_us"],
            note=f"dropped {out['fly_log_back_to_back_dropped'] + out['fly_log_paced_100hz_dropped']}"),
        row("simulation with background log (x real time)", out["sim_realtime_ratio_background"], "x",
            baseline="no log", baseline_value=out["sim_realtime_ratio_none"]),
        row("simulation with in-process log (x real time)", out["sim_realtime_ratio_inline"], "x",
            baseline="no log", baseline_value=out["sim_realtime_ratio_none"]),
        row(f"gcs sim-like run, 3 x {out['sim_runs_flight_s']:g} s, background log",
            out["sim_runs_wall_s_background_log"], "s",
            baseline="no log", baseline_value=out["sim_runs_wall_s_no_log"]),
    ]
    full = minutes >= 10.0
    for kind in ("sim", "flight"):
        cli = out[f"metrics_{kind}_log_cli_s"]
        rows.append(row(f"gcs log metrics, {minutes:g}-minute {kind} log (command)", cli, "s",
                        baseline="library call (no interpreter start)", baseline_value=out[f"metrics_{kind}_log_s"],
                        target=f"<= {TARGET_METRICS_S:g} s (10-minute log)",
                        met=(cli <= TARGET_METRICS_S) if full else None,
                        note="" if full else f"--quick: not judged; x{10.0 / minutes:g} for 10 minutes: "
                                             f"~{cli + (10.0 / minutes - 1) * out[f'metrics_{kind}_log_s']:.1f} s"))
    return rows

if __name__ == "__main__":
    sys.exit(main())
