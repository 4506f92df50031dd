"""SITL benchmarks: simulated seconds per wall second (not timed tests).

Run::

    python benchmarks/bench_sitl.py [--repeat N] [--quick] [--json]

Prints the median of ``N`` repetitions for:

* ``physics``: :func:`sitl.rigid_body.step` alone at a 1 ms step (target >= 150x real time);
* ``simulation``: world + sensors + autopilot at 400 Hz, no link (for reference);
* ``lockstep-thread``: a pymavlink client flying a scripted takeoff/hover at 100 Hz
  against :class:`sitl.server.SitlServer` in lockstep over UDP, server in a
  background thread of the same process (target >= 30x real time);
* ``lockstep-process``: the same against ``sitl --lockstep`` in a subprocess;
* ``...-1cpu``: the two lockstep cases with client and server pinned to one CPU
  (``os.sched_setaffinity``, like ``taskset -c 0``).  Lockstep is a ping-pong:
  on a VM, waking a thread on another CPU costs tens of microseconds per
  message, so one CPU is the faster (and steadier) configuration for CI;
* ``in-process`` (the baseline of every lockstep case): the same kind of flight, a
  climb and a hover over the same simulated time, flown by :func:`gcs.sim.simulate`
  in one process with no link (outdoor-altitude config: takeoff ramp to 2 m and hold,
  NLSOC, the reduced plant at 1 ms, sensors and estimator).  Each lockstep case is
  reported as a ratio to it.  ``bench_fly.py`` compares a whole ``gcs fly --sitl
  lockstep`` flight with :func:`gcs.sim.simulate` of exactly the same mission.

``--json``: the text on stderr, one JSON document on stdout (see ``benchlib.py``).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

from pymavlink import mavutil

from benchlib import document, emit, row

from sitl.copter import rigid_body
from sitl.copter.server import SitlServer
from sitl.copter.simulation import Simulation
from sitl.copter.vehicle_file import load_vehicle
from sitl.net.udp import UdpTransport


def bench_physics(sim_seconds: float) -> float:
    vehicle = load_vehicle()
    model = rigid_body.RigidBodyModel(vehicle)
    hover = vehicle.mass_kg * vehicle.gravity_m_s2 / 4.0
    state = rigid_body.initial_state(1000.0)._replace(on_ground=False, t1=hover, t2=hover, t3=hover, t4=hover)
    cmd = (hover * 1.0005, hover * 0.9995, hover, hover)
    wind = (1.0, 0.5, 0.0)
    n = int(sim_seconds / 0.001)
    step = rigid_body.step
    t0 = time.perf_counter()
    for _ in range(n):
        state = step(state, cmd, 0.001, model, wind)
    wall = time.perf_counter() - t0
    assert not state.on_ground
    return n * 0.001 / wall


def bench_simulation(sim_seconds: float) -> float:
    sim = Simulation(load_vehicle(), seed=1)
    ap = sim.autopilot
    ap.set_mode(20, 0)
    ap.arm(0)
    ticks = int(sim_seconds * 400)
    t0 = time.perf_counter()
    for k in range(ticks):
        if k % 4 == 0:
            thrust = 0.6 if k < ticks // 2 else 0.5
            ap.set_attitude_target(7, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), thrust, sim.time_ns)
        sim.tick()
    wall = time.perf_counter() - t0
    return sim.time_s / wall


def fly(conn, sim_seconds: float) -> float:
    """Scripted lockstep flight at 100 Hz; returns simulated seconds per wall second."""
    conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    if conn.wait_heartbeat(timeout=10) is None:
        raise RuntimeError("no heartbeat")
    for msg_id in (30, 32):
        conn.mav.command_long_send(1, 1, 511, 0, msg_id, 10000, 0, 0, 0, 0, 0)
        conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=5)
    conn.mav.command_long_send(1, 1, 176, 0, 1, 20, 0, 0, 0, 0, 0)
    conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=5)
    conn.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=5)
    if ack is None or ack.result != 0:
        raise RuntimeError(f"arming failed: {ack}")
    steps = int(sim_seconds * 100)
    last = None
    t0 = time.perf_counter()
    for k in range(steps):
        thrust = 0.7 if k < steps // 3 else 0.5
        conn.mav.set_attitude_target_send(0, 1, 1, 0b111, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, thrust)
        while True:
            m = conn.recv_match(blocking=True, timeout=5)
            if m is None:
                raise RuntimeError(f"no telemetry at step {k}")
            if m.get_type() == "LOCAL_POSITION_NED":
                last = m
                break
    wall = time.perf_counter() - t0
    if last is None or -last.z < 1.0:
        raise RuntimeError("the vehicle did not climb")
    return steps * 0.01 / wall


def bench_lockstep_thread(sim_seconds: float) -> float:
    server = SitlServer(UdpTransport(("127.0.0.1", 0)), lockstep=True, seed=1).start()
    conn = mavutil.mavlink_connection(server.connection_string, source_system=255)
    try:
        return fly(conn, sim_seconds)
    finally:
        conn.close()
        server.stop()


def bench_lockstep_process(sim_seconds: float) -> float:
    cmd = [sys.executable, "-m", "sitl.cli", "--udp-listen", "127.0.0.1:0", "--lockstep", "--seed", "1"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        cs = proc.stdout.readline().strip()
        conn = mavutil.mavlink_connection(cs, source_system=255)
        try:
            return fly(conn, sim_seconds)
        finally:
            conn.close()
    finally:
        proc.terminate()
        proc.wait(10)


def pinned(fn):
    """Run ``fn`` with this process (and the threads/processes it starts) on one CPU."""
    def run(seconds: float) -> float:
        if not hasattr(os, "sched_setaffinity"):
            return float("nan")
        old = os.sched_getaffinity(0)
        os.sched_setaffinity(0, {min(old)})
        try:
            return fn(seconds)
        finally:
            os.sched_setaffinity(0, old)
    return run


def bench_in_process(sim_seconds: float) -> float:
    """gcs.sim.simulate: a climb to 2 m and a hover, NLSOC, no link; simulated seconds per wall second."""
    from gcs.config import load_config
    from gcs.control import make_controller
    from gcs.sim import SimOptions, simulate

    config = load_config("outdoor-altitude")
    designed = make_controller("nlsoc", config)  # designed once, outside the timing (as gcs sim does)
    t0 = time.perf_counter()
    simulate(config, "nlsoc", options=SimOptions(duration_s=sim_seconds), designed=designed)
    return sim_seconds / (time.perf_counter() - t0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=None, help="repetitions (median reported; default 5, 3 with --quick)")
    ap.add_argument("--quick", action="store_true", help="shorter runs, 3 repetitions")
    ap.add_argument("--json", action="store_true", help="text on stderr, one JSON document on stdout")
    args = ap.parse_args(argv)
    repeat = args.repeat or (3 if args.quick else 5)
    scale = 0.25 if args.quick else 1.0
    seconds = 20.0 * scale
    cases = [
        ("physics", bench_physics, 150.0),
        ("simulation", bench_simulation, None),
        ("in-process", bench_in_process, None),
        ("lockstep-thread", bench_lockstep_thread, 30.0),
        ("lockstep-process", bench_lockstep_process, 30.0),
        ("lockstep-thread-1cpu", pinned(bench_lockstep_thread), 30.0),
        ("lockstep-process-1cpu", pinned(bench_lockstep_process), 30.0),
    ]
    results = {}
    lines = [f"{seconds:g} simulated s per run, median of {repeat}",
             f"{'benchmark':<22} {'median x RT':>11} {'min':>8} {'max':>8} {'target':>8} {'median/target':>14} "
             f"{'/in-process':>12}"]
    if not args.json:
        print("\n".join(lines), flush=True)
    for name, fn, target in cases:
        vals = [fn(seconds) for _ in range(repeat)]
        med = statistics.median(vals)
        results[name] = {"median": med, "min": min(vals), "max": max(vals), "target": target}
        tgt = f"{target:.0f}x" if target else "-"
        ratio = f"{med / target:.2f}" if target else "-"
        base = f"{med / results['in-process']['median']:.2f}" if name.startswith("lockstep") else "-"
        lines.append(f"{name:<22} {med:>10.1f}x {min(vals):>7.1f}x {max(vals):>7.1f}x {tgt:>8} {ratio:>14} {base:>12}")
        if not args.json:
            print(lines[-1], flush=True)
    base = results["in-process"]["median"]
    rows = []
    for name, r in results.items():
        lock = name.startswith("lockstep")
        rows.append(row(f"{name} (x real time)", r["median"], "x",
                        baseline="in-process gcs.sim.simulate" if lock else None, baseline_value=base if lock else None,
                        target=f">= {r['target']:g}x" if r["target"] else None,
                        met=(r["median"] >= r["target"]) if r["target"] else None))
    doc = document("sitl", args.quick, {"sim_seconds": seconds, "repeat": repeat, "cases": results}, rows)
    if args.json:
        emit(doc, "\n".join(lines), True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
