"""The rig emulator through its serial port: a scripted PC client (pyserial) flies it in lockstep and real time."""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from itertools import pairwise

import pytest
import serial

from quadrotor import rig_protocol as rp
from quadrotor.clock import MonotonicClock
from quadrotor.rig_protocol import AckResult, RigFlags, RigState
from sitl.cli import main
from sitl.errors import UsageError
from sitl.net.pty import PtyTransport
from sitl.net.radio import RadioParams
from sitl.rig.server import RigServer

HOVER = 9.81


class RigClient:
    """A small PC side: pyserial, the shared decoder, lockstep steps and an altitude autopilot."""

    def __init__(self, device: str, baud: int = 115200) -> None:
        self.port = serial.Serial(device, baud, timeout=0)
        self.dec = rp.RigDecoder(rp.TO_PC)
        self.telemetry: list[rp.Telemetry] = []
        self.status: list[rp.Status] = []
        self.acks: list[rp.Ack] = []
        self.seq = 0
        self.timeouts = 0
        # alpha-beta altitude estimate driven by the commanded acceleration
        self.z_hat = self.v_hat = 0.0
        self.thrust = 0.0
        self.step_timeout = 0.5

    def close(self) -> None:
        self.port.close()

    def send(self, msg: rp.Message) -> None:
        self.port.write(rp.encode(msg))

    def poll(self, timeout: float) -> list[rp.Message]:
        r, _, _ = select.select([self.port.fileno()], [], [], max(0.0, timeout))
        if not r:
            return []
        out = self.dec.feed(self.port.read(self.port.in_waiting or 1))
        for m in out:
            {rp.Telemetry: self.telemetry, rp.Status: self.status, rp.Ack: self.acks}[type(m)].append(m)
        return out

    def wait_for(self, pred, timeout: float = 3.0):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for m in self.poll(end - time.monotonic()):
                if pred(m):
                    return m
        return None

    def hello(self) -> rp.Status:
        self.send(rp.Heartbeat(42))
        st = self.wait_for(lambda m: isinstance(m, rp.Status) and m.heartbeat_echo_us == 42)
        assert st is not None, "no STATUS from the rig"
        return st

    def command(self, msg: rp.Arm | rp.Disarm, timeout: float = 3.0) -> rp.Ack | None:
        self.send(msg)
        return self.wait_for(lambda m: isinstance(m, rp.Ack) and m.acked_type == msg.TYPE and m.seq == msg.seq,
                             timeout)

    def step(self, thrust: float, roll: float = 0.0, pitch: float = 0.0) -> rp.Telemetry | None:
        """Lockstep: one CONTROL, then the step's last TELEMETRY (stamped on a 10 ms boundary)."""
        self.seq = (self.seq + 1) & 0xFFFF
        seq = self.seq
        self.send(rp.Control(seq, thrust, roll, pitch, 0.0))
        end = time.monotonic() + self.step_timeout
        while time.monotonic() < end:
            for m in self.poll(end - time.monotonic()):
                if isinstance(m, rp.Telemetry) and m.control_seq == seq:
                    if m.time_us % 10_000 == 0:
                        return m
                    end = min(end, time.monotonic() + 0.02)   # the step's second frame follows at once
        self.timeouts += 1
        return None

    def autopilot(self, t: rp.Telemetry | None, z_ref: float) -> tuple[float, float, float]:
        """Thrust and levelling accelerations from the last telemetry (None: predict only)."""
        a = self.thrust - HOVER
        if t is not None and RigFlags.LANDED in t.flags and self.thrust < HOVER:
            a = 0.0
        self.z_hat += 0.01 * self.v_hat
        self.v_hat += 0.01 * a
        if t is None:
            return self.thrust, 0.0, 0.0
        r = t.altitude_m - self.z_hat
        self.z_hat += 0.08 * r
        self.v_hat += 0.4 * r
        self.thrust = min(24.5, max(0.0, HOVER + 12.0 * (z_ref - self.z_hat) - 6.0 * self.v_hat))
        return (self.thrust, -100.0 * t.roll_rad - 20.0 * t.roll_rate_rad_s,
                -100.0 * t.pitch_rad - 20.0 * t.pitch_rate_rad_s)

    def fly_profile(self, rig: RigServer) -> list[float]:
        """Up to 0.3 m in 1 s, hold 0.8 s, down in 1 s, settle; returns the true altitude per step."""
        z_true = []
        cmd = (0.0, 0.0, 0.0)
        for k in range(1, 351):
            t = k * 0.01
            ref = (0.3 * min(t, 1.0) if t < 1.8 else max(-0.05, 0.3 - 0.3 * (t - 1.8)))
            tel = self.step(*cmd)
            cmd = self.autopilot(tel, ref)
            z_true.append(rig.snapshot()["plant"].z)
        return z_true


@pytest.fixture
def rig_factory():
    made: list[tuple[RigServer, RigClient]] = []

    def make(**kwargs) -> tuple[RigServer, RigClient]:
        clock = MonotonicClock()
        kwargs.setdefault("lockstep", True)
        rig = RigServer(PtyTransport(clock.now_ns), clock=clock, **kwargs).start()
        client = RigClient(rig.connection_string)
        made.append((rig, client))
        return rig, client

    yield make
    for rig, client in made:
        client.close()
        rig.stop()


def test_lockstep_flight_through_the_pty_at_115200_baud(rig_factory):
    rig, pc = rig_factory(radio=RadioParams(baud=115200), seed=3)
    assert rig.connection_string.startswith("/dev/")
    st = pc.hello()
    assert st.state == RigState.DISARMED and RigFlags.LANDED in st.flags and st.time_us == 0
    assert pc.command(rp.Arm(1)).result == AckResult.ACCEPTED
    t0 = time.monotonic()
    z = pc.fly_profile(rig)
    wall = time.monotonic() - t0
    snap = rig.snapshot()
    assert max(z) == pytest.approx(0.3, abs=0.06)
    assert z[-1] < 0.02 and snap["state"] == RigState.ARMED and snap["cutoffs"] == 0
    assert pc.timeouts == 0 and snap["steps"] == 350 and snap["time_s"] == pytest.approx(3.5)
    # Two TELEMETRY frames per step, 5 ms apart, each echoing the step's CONTROL.
    tel = pc.telemetry
    assert len(tel) == 700 and [t.time_us for t in tel] == [5000 * (i + 1) for i in range(700)]
    assert [t.control_seq for t in tel[::2]] == list(range(1, 351))
    assert snap["rx"]["frames"] == 352 and rp.DecoderCounters(**snap["rx"]).errors == 0
    assert pc.dec.counters.errors == 0
    # The 115200-baud line paces the exchange: about 8 ms of wire time per step.
    wire_s = snap["link"]["tx_bytes"] * 10 / 115200
    assert wire_s > 2.5 and wall >= 0.95 * wire_s
    assert pc.command(rp.Disarm(2)).result == AckResult.ACCEPTED


def test_bit_errors_on_the_link_are_survived(rig_factory):
    rig, pc = rig_factory(bit_error_rate=2e-4, seed=11)
    for _ in range(5):                                   # the hello itself may be hit
        pc.send(rp.Heartbeat(42))
        if pc.wait_for(lambda m: isinstance(m, rp.Status), 0.3) is not None:
            break
    ack = None
    for seq in range(1, 6):
        ack = pc.command(rp.Arm(seq), timeout=0.3)
        if ack is not None:
            break
    assert ack is not None and ack.result == AckResult.ACCEPTED
    pc.step_timeout = 0.05                               # a lost CONTROL: no step, send the next one
    z = pc.fly_profile(rig)
    snap = rig.snapshot()
    assert snap["cutoffs"] == 0 and snap["state"] == RigState.ARMED
    assert max(z) == pytest.approx(0.3, abs=0.08) and z[-1] < 0.05
    assert snap["link"]["bits_flipped_in"] > 0 and snap["link"]["bits_flipped_out"] > 0
    rx = rp.DecoderCounters(**snap["rx"])
    assert rx.errors > 0 and rx.frames >= 300, "corrupted CONTROL frames were dropped, the rest flew"
    assert pc.dec.counters.errors > 0 and len(pc.telemetry) > 550


def test_real_time_mode_streams_200_hz_and_the_watchdog_lands_it(rig_factory):
    rig, pc = rig_factory(lockstep=False, radio=RadioParams(baud=115200))
    pc.hello()
    assert pc.command(rp.Arm(1)).result == AckResult.ACCEPTED
    n0 = len(pc.telemetry)
    t0 = time.monotonic()
    seq = 0
    next_send = t0
    while time.monotonic() - t0 < 1.0:                  # 100 Hz CONTROL, lifting a little
        now = time.monotonic()
        if now >= next_send:
            seq += 1
            pc.send(rp.Control(seq, 11.0 if now - t0 < 0.4 else 9.3))
            next_send += 0.01
        pc.poll(max(0.0, next_send - time.monotonic()))
    wall = time.monotonic() - t0
    got = pc.telemetry[n0:]
    rate = len(got) / wall
    assert 120 < rate < 230, rate                       # 200 Hz, loose for a busy machine
    gaps = sum(b.time_us - a.time_us != 5000 for a, b in pairwise(got))
    assert gaps <= 2, "every tick sends one frame (a stalled machine may overflow the radio queue)"
    assert max(t.altitude_m for t in got) >= 0.04
    assert pc.wait_for(lambda m: isinstance(m, rp.Telemetry) and m.control_seq == seq, 1.0) is not None
    # Stop sending: after 0.5 s the rig descends on its own and disarms on the ground.
    m = pc.wait_for(lambda m: isinstance(m, rp.Telemetry) and RigFlags.WATCHDOG in m.flags, 2.0)
    assert m is not None
    m = pc.wait_for(lambda m: isinstance(m, rp.Telemetry) and RigFlags.ARMED not in m.flags, 5.0)
    assert m is not None and RigFlags.LANDED in m.flags
    snap = rig.snapshot()
    assert snap["watchdog_trips"] == 1 and snap["state"] == RigState.DISARMED and snap["cutoffs"] == 0


def test_excessive_command_over_the_link_cuts_off(rig_factory):
    rig, pc = rig_factory()
    pc.hello()
    pc.command(rp.Arm(1))
    for _ in range(30):
        pc.step(12.0)
    t = pc.step(40.0)
    assert RigFlags.CUTOFF in t.flags and RigFlags.CUT_COMMAND in t.flags
    assert pc.command(rp.Arm(2)).result == AckResult.DENIED_CUTOFF
    for _ in range(60):
        t = pc.step(12.0)
    assert RigFlags.LANDED in t.flags and rig.snapshot()["plant"].z == 0.0
    assert pc.command(rp.Disarm(3)).result == AckResult.ACCEPTED
    assert pc.command(rp.Arm(4)).result == AckResult.ACCEPTED


def test_bad_arguments():
    with pytest.raises(UsageError, match="multiple"):
        RigServer(PtyTransport(time.monotonic_ns), control_period_s=0.007)
    with pytest.raises(UsageError, match="bit error rate"):
        RigServer(PtyTransport(time.monotonic_ns), bit_error_rate=1.0)


# ---------------------------------------------------------------------------------------------- CLI
@pytest.mark.parametrize("args, words", [
    (["--rig", "4dof", "--udp", "127.0.0.1:9"], "--udp: not available with --rig"),
    (["--rig", "4dof", "--vehicle", "talon-550"], "--vehicle"),
    (["--rig", "4dof", "--param", "GUID_OPTIONS=8"], "--param"),
    (["--rig", "4dof", "--bit-error-rate", "2"], "--bit-error-rate"),
    (["--rig", "4dof", "--period", "0.012"], "multiple"),
    (["--bit-error-rate", "0.001"], "only with --rig"),
    (["--rig", "6dof"], "invalid choice"),
])
def test_rig_cli_errors_are_one_line(capsys, args, words):
    try:
        code = main(args)
    except SystemExit as e:
        code = e.code
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith("sitl: error: ") and words in err


def test_rig_cli_describe(capsys):
    assert main(["--rig", "4dof", "--describe"]) == 0
    out = capsys.readouterr().out
    assert "roll +-15 deg, pitch +-60 deg" in out and "thrust 0..24.5 N" in out


def test_rig_cli_serves_a_pty_and_stops_cleanly():
    proc = subprocess.Popen([sys.executable, "-m", "sitl.cli", "--rig", "4dof", "--lockstep", "--seed", "2"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        device = proc.stdout.readline().strip()
        assert device.startswith("/dev/") and os.path.exists(device), proc.stderr.read()
        pc = RigClient(device)
        try:
            st = pc.hello()
            assert st.protocol_version == rp.PROTOCOL_VERSION
            assert pc.command(rp.Arm(9)).result == AckResult.ACCEPTED
            t = None
            for _ in range(20):
                t = pc.step(HOVER + 1.0)
            assert t is not None and t.time_us == 200_000 and RigFlags.ARMED in t.flags
            # Idle in lockstep: a STATUS every wall-clock second, and no time passes.
            st = pc.wait_for(lambda m: isinstance(m, rp.Status) and m.heartbeat_echo_us == 42, 1.5)
            assert st is not None and st.time_us == 200_000
        finally:
            pc.close()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0 and "Traceback" not in err and "rig 4dof" in err
