"""4-DOF rig link benchmarks: decoder/encoder throughput, link budget, emulator speed (not timed tests).

Run::

    python benchmarks/bench_rig.py [--repeat N] [--quick] [--json]

Prints the median of ``N`` repetitions for:

* ``decode``: :class:`quadrotor.rig_protocol.RigDecoder` on a recorded stream of
  TELEMETRY frames from an emulated hover (noisy sensors), fed in 64-byte
  chunks (a serial read) and as one 64 kB block, in frames per second;
* ``encode``: :func:`quadrotor.rig_protocol.encode` of the same messages;
* ``link``: the share of the 115200-baud line (10 bits per byte) used by the
  100 Hz exchange, from the actual encoded sizes (escaping included):
  TELEMETRY at 200 Hz plus STATUS at 1 Hz down, CONTROL (or CONTROL_PWM)
  at 100 Hz plus HEARTBEAT at 1 Hz up;
* ``emulator``: :class:`sitl.rig_firmware.RigFirmware` alone, simulated
  seconds per wall second;
* ``lockstep``: a pyserial client stepping :class:`sitl.rig.RigServer` over a
  pseudo-terminal in lockstep, unlimited and at 115200 baud, in steps per second
  (baselines: the emulator alone, and the unlimited line).

``--json``: the text on stderr, one JSON document on stdout (see ``benchlib.py``).
"""

from __future__ import annotations

import argparse
import random
import select
import statistics
import time

import serial

from benchlib import document, emit, row
from quadrotor import rig_protocol as rp
from quadrotor.clock import MonotonicClock
from sitl.net.pty import PtyTransport
from sitl.net.radio import RadioParams
from sitl.rig.firmware import RigFirmware
from sitl.rig.server import RigServer

BAUD = 115200


def hover_messages(seconds: float, seed: int = 1) -> tuple[list[rp.Message], list[rp.Control]]:
    """Telemetry/status of an emulated hover at 0.3 m, and the CONTROL frames that flew it."""
    fw = RigFirmware(seed=seed)
    fw.handle(rp.Arm(1))
    rng = random.Random(seed)
    down: list[rp.Message] = []
    controls: list[rp.Control] = []
    for k in range(int(seconds * 100)):
        s = fw.plant
        c = rp.Control((k + 1) & 0xFFFF, 9.81 + 8.0 * (0.3 - s.z) - 5.0 * s.vz + rng.gauss(0.0, 0.05),
                       -100.0 * s.roll - 20.0 * s.roll_rate + rng.gauss(0.0, 0.2),
                       -100.0 * s.pitch - 20.0 * s.pitch_rate + rng.gauss(0.0, 0.2), 0.0)
        controls.append(c)
        fw.handle(c)
        down.extend(fw.tick())
        down.extend(fw.tick())
    return down, controls


def median_rate(fn, count: int, repeat: int) -> float:
    rates = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        rates.append(count / (time.perf_counter() - t0))
    return statistics.median(rates)


def bench_codec(msgs: list[rp.Message], repeat: int) -> dict[str, float]:
    stream = b"".join(rp.encode(m) for m in msgs)
    chunks64 = [stream[i:i + 64] for i in range(0, len(stream), 64)]
    blocks = [stream[i:i + 65536] for i in range(0, len(stream), 65536)]

    def decode(chunks):
        def run():
            dec = rp.RigDecoder(rp.TO_PC)
            n = 0
            for c in chunks:
                n += len(dec.feed(c))
            assert n == len(msgs) and dec.counters.errors == 0
        return run

    def encode():
        for m in msgs:
            rp.encode(m)

    return {"decode_64": median_rate(decode(chunks64), len(msgs), repeat),
            "decode_block": median_rate(decode(blocks), len(msgs), repeat),
            "encode": median_rate(encode, len(msgs), repeat),
            "stream_bytes": len(stream)}


def link_budget(down: list[rp.Message], controls: list[rp.Control]) -> dict[str, float]:
    tel = [len(rp.encode(m)) for m in down if isinstance(m, rp.Telemetry)]
    status = [len(rp.encode(m)) for m in down if isinstance(m, rp.Status)] or [rp.frame_size(rp.Status)]
    ctrl = [len(rp.encode(c)) for c in controls]
    rng = random.Random(2)
    pwm = [len(rp.encode(rp.ControlPwm(i & 0xFFFF, tuple(rng.randint(350, 470) for _ in range(4)))))
           for i in range(len(controls))]
    hb = len(rp.encode(rp.Heartbeat(123456)))
    t, s, c, p = (statistics.fmean(v) for v in (tel, status, ctrl, pwm))
    line = BAUD / 10.0
    return {"telemetry_b": t, "status_b": s, "control_b": c, "pwm_b": p, "heartbeat_b": hb,
            "down_Bps": 200 * t + s, "up_Bps": 100 * c + hb, "up_pwm_Bps": 100 * p + hb,
            "down_share": (200 * t + s) / line, "up_share": (100 * c + hb) / line,
            "up_pwm_share": (100 * p + hb) / line, "line_Bps": line}


def bench_emulator(sim_seconds: float, repeat: int) -> float:
    def run():
        fw = RigFirmware(seed=3)
        fw.handle(rp.Arm(1))
        fw.handle(rp.Control(1, 10.5, 0.0, 0.0, 0.0))
        for k in range(int(sim_seconds * 200)):
            if k % 2 == 0:
                fw.handle(rp.Control(k, 9.81 + 8.0 * (0.3 - fw.plant.z) - 5.0 * fw.plant.vz))
            fw.tick()
    return median_rate(run, sim_seconds, repeat)


def bench_lockstep(steps: int, baud: int) -> float:
    clock = MonotonicClock()
    radio = RadioParams(baud=baud) if baud else None
    with RigServer(PtyTransport(clock.now_ns), lockstep=True, radio=radio, clock=clock) as rig:
        port = serial.Serial(rig.connection_string, BAUD, timeout=0)
        dec = rp.RigDecoder(rp.TO_PC)
        try:
            def wait(pred):
                end = time.monotonic() + 2.0
                while time.monotonic() < end:
                    select.select([port.fileno()], [], [], 0.1)
                    for m in dec.feed(port.read(port.in_waiting or 1)):
                        if pred(m):
                            return m
                raise RuntimeError("the rig did not answer")

            port.write(rp.encode(rp.Heartbeat(1)))
            wait(lambda m: isinstance(m, rp.Status) and m.heartbeat_echo_us == 1)
            port.write(rp.encode(rp.Arm(1)))
            wait(lambda m: isinstance(m, rp.Ack))
            t0 = time.perf_counter()
            for k in range(1, steps + 1):
                port.write(rp.encode(rp.Control(k, 9.9)))
                wait(lambda m, k=k: isinstance(m, rp.Telemetry) and m.control_seq == k and m.time_us % 10_000 == 0)
            return steps / (time.perf_counter() - t0)
        finally:
            port.close()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="shorter runs")
    ap.add_argument("--json", action="store_true", help="text on stderr, one JSON document on stdout")
    args = ap.parse_args(argv)
    repeat = 3 if args.quick else args.repeat
    seconds = 5.0 if args.quick else 20.0
    down, controls = hover_messages(seconds)
    codec = bench_codec(down, repeat)
    lb = link_budget(down, controls)
    emu = bench_emulator(2.0 if args.quick else 10.0, repeat)
    steps = 100 if args.quick else 300
    ls_free = bench_lockstep(steps, 0)
    ls_baud = bench_lockstep(steps, BAUD)
    lines = [
        f"rig protocol (median of {repeat}; {len(down)} frames, {codec['stream_bytes']} bytes of a "
        f"{seconds:g} s emulated hover)",
        f"  decode, 64-byte chunks   {codec['decode_64']:>10.0f} frames/s",
        f"  decode, 64 kB blocks     {codec['decode_block']:>10.0f} frames/s",
        f"  encode                   {codec['encode']:>10.0f} frames/s",
        f"link budget at {BAUD} baud ({lb['line_Bps']:.0f} B/s each way, 10 bits/byte; mean escaped sizes)",
        f"  down: TELEMETRY {lb['telemetry_b']:.2f} B x 200 Hz + STATUS {lb['status_b']:.1f} B x 1 Hz "
        f"= {lb['down_Bps']:.0f} B/s = {100 * lb['down_share']:.1f} %",
        f"  up:   CONTROL {lb['control_b']:.2f} B x 100 Hz + HEARTBEAT {lb['heartbeat_b']} B x 1 Hz "
        f"= {lb['up_Bps']:.0f} B/s = {100 * lb['up_share']:.1f} %",
        f"  up:   CONTROL_PWM {lb['pwm_b']:.2f} B x 100 Hz + HEARTBEAT "
        f"= {lb['up_pwm_Bps']:.0f} B/s = {100 * lb['up_pwm_share']:.1f} %",
        f"  busier direction: {100 * max(lb['down_share'], lb['up_share']):.1f} % of the line",
        f"emulator (200 Hz loop, no link)  {emu:>8.1f} x real time",
        f"lockstep over a pty, unlimited   {ls_free:>8.0f} steps/s ({ls_free / 100:.1f} x real time)",
        f"lockstep over a pty, {BAUD} baud {ls_baud:>6.0f} steps/s ({ls_baud / 100:.2f} x real time)",
    ]
    data = {"frames": len(down), "codec": codec, "link_budget": lb, "emulator_ratio": emu,
            "lockstep_steps_s_unlimited": ls_free, "lockstep_steps_s_baud": ls_baud, "baud": BAUD}
    busier = max(lb["down_share"], lb["up_share"])
    rows = [
        row("rig TELEMETRY decode, 64-byte chunks", 1e6 / codec["decode_64"], "us/frame",
            baseline="64 kB blocks", baseline_value=1e6 / codec["decode_block"]),
        row("rig encode (TELEMETRY and STATUS frames)", 1e6 / codec["encode"], "us/frame"),
        row(f"busier direction of the {BAUD}-baud line", 100 * busier, "%", target="< 100 %", met=busier < 1.0),
        row("emulator alone (x real time)", emu, "x"),
        row("lockstep over a pty, unlimited (x real time)", ls_free / 100, "x",
            baseline="emulator alone", baseline_value=emu),
        row(f"lockstep over a pty, {BAUD} baud (x real time)", ls_baud / 100, "x",
            baseline="unlimited line", baseline_value=ls_free / 100),
    ]
    emit(document("rig", args.quick, data, rows), "\n".join(lines), args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
