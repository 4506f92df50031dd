"""Flight safety of ``gcs fly``: hostile telemetry, faults in the loop, the output guard, a shared link.

In-process flights against the lockstep SITL through a relay that can corrupt what the
vehicle sends, inject into what it receives (a second ground station on the same link)
and records every frame the ground station sent, so that "nothing non-finite ever reached
the wire" is checked on the wire itself.
"""

from __future__ import annotations

import dataclasses
import json
import math
import select
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.config import load_config
from gcs.flight.flight import Flight
from gcs.flight.validate import TelemetryValidator
from gcs.link.guard import GuardLimits, OutputGuard
from gcs.link.mavlink import MavlinkLink
from gcs.vehicles.mavlink import MavlinkSession
from gcs.vehicles.streams import StreamMonitor
from sitl.copter.server import SitlServer
from sitl.net.udp import UdpTransport

M = mavlink


class Relay:
    """A UDP relay between the ground station and the SITL.

    ``mutate(msg) -> msg or None`` may rewrite (or drop) each decoded downlink message,
    which is then re-encoded as the vehicle (a valid frame with whatever fields it got);
    ``inject_up`` frames go to the vehicle as if the ground station sent them (one shared
    link).  Every uplink frame is decoded into ``uplink``.
    """

    def __init__(self, sitl_addr: tuple[str, int], mutate=None) -> None:
        self.sitl_addr = sitl_addr
        self.mutate = mutate
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.up = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.up.bind(("127.0.0.1", 0))
        self.gcs_addr = None
        self.stop = threading.Event()
        self.uplink: list = []
        self.inject_up: list[bytes] = []
        self._lock = threading.Lock()
        self._up_parser = M.MAVLink(None)
        self._up_parser.robust_parsing = True
        self._down_parser = M.MAVLink(None)
        self._down_parser.robust_parsing = True
        self._vehicle = M.MAVLink(None, srcSystem=1, srcComponent=1)
        self.thread = threading.Thread(target=self.run, daemon=True)

    @property
    def port(self) -> int:
        return self.sock.getsockname()[1]

    def run(self) -> None:
        while not self.stop.is_set():
            with self._lock:
                pending, self.inject_up = self.inject_up, []
            for data in pending:
                self.up.sendto(data, self.sitl_addr)
            ready, _, _ = select.select([self.sock, self.up], [], [], 0.01)
            for s in ready:
                data, addr = s.recvfrom(65535)
                if s is self.sock:
                    self.gcs_addr = addr
                    self.uplink.extend(m for m in (self._up_parser.parse_buffer(data) or [])
                                       if m.get_type() != "BAD_DATA")
                    self.up.sendto(data, self.sitl_addr)
                elif self.gcs_addr is not None:
                    self.sock.sendto(self._down(data), self.gcs_addr)

    def _down(self, data: bytes) -> bytes:
        if self.mutate is None:
            return data
        out = b""
        for m in self._down_parser.parse_buffer(data) or []:
            if m.get_type() == "BAD_DATA":
                continue
            m2 = self.mutate(m)
            if m2 is None:
                continue
            for extra in (m2 if isinstance(m2, list) else [m2]):
                if isinstance(extra, tuple):  # (message, sender): a frame of another system or component
                    out += extra[0].pack(extra[1])
                elif extra is m:
                    out += bytes(m.get_msgbuf())
                else:
                    self._vehicle.seq = m.get_seq()
                    out += extra.pack(self._vehicle)
        return out

    def inject(self, msg, src_system: int = 255, src_component: int = 230) -> None:
        w = M.MAVLink(None, srcSystem=src_system, srcComponent=src_component)
        with self._lock:
            self.inject_up.append(msg.pack(w))

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join(2)
        self.sock.close()
        self.up.close()


def short_config(name: str = "outdoor-altitude", takeoff_s: float = 3.0, hold_s: float = 4.0):
    config = load_config(name)
    takeoff, hold = config.mission[:2]
    return dataclasses.replace(config, mission=(dataclasses.replace(takeoff, duration_s=takeoff_s, z_m=1.0),
                                                dataclasses.replace(hold, kind="hold", duration_s=hold_s)))


def fly_through(relay_mutate=None, *, config=None, controller="pd", seed=11, during=None, flight_hook=None):
    """Preflight and fly through a :class:`Relay`; ``during(relay, server)`` runs in a thread."""
    config = config or short_config()
    with SitlServer(UdpTransport(("127.0.0.1", 0)), lockstep=True, seed=seed) as server:
        port = int(server.connection_string.rsplit(":", 1)[1])
        with Relay(("127.0.0.1", port), relay_mutate) as relay:
            link = MavlinkLink(f"udpout:127.0.0.1:{relay.port}")
            flight = Flight(config, controller, MavlinkSession(config, link), console=lambda s: None)
            if flight_hook is not None:
                flight_hook(flight)
            stop = threading.Event()
            if during is not None:
                threading.Thread(target=during, args=(relay, server, stop), daemon=True).start()
            try:
                flight.preflight()
                result = flight.fly()
                flight.restore()
            finally:
                stop.set()
                link.close()
            snap = server.snapshot()
            params = {k: server.sim.params[k] for k in ("GUID_OPTIONS", "ATC_ANGLE_BOOST")}
    return result, snap, relay.uplink, params


def assert_wire_clean(uplink: list) -> None:
    """Every setpoint and command the ground station sent was finite and within the limits."""
    n = 0
    for m in uplink:
        t = m.get_type()
        if t == "SET_ATTITUDE_TARGET":
            n += 1
            vals = [*m.q, m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate, m.thrust]
            assert all(math.isfinite(v) for v in vals), vals
            assert abs(math.sqrt(sum(q * q for q in m.q)) - 1.0) < 1e-3
            assert 0.0 <= m.thrust <= 1.0
            assert max(abs(m.body_roll_rate), abs(m.body_pitch_rate), abs(m.body_yaw_rate)) <= 35.0
        elif t == "COMMAND_LONG":
            assert all(math.isfinite(getattr(m, f"param{i}")) for i in range(1, 8))
    assert n > 100


def assert_landed(result, snap, params) -> None:
    assert any(e["text"] == "landed and disarmed" for e in result.events), [e["text"] for e in result.events[-6:]]
    assert not snap["armed"] and snap["on_ground"]
    assert params == {"GUID_OPTIONS": 0, "ATC_ANGLE_BOOST": 1}, params


# ---------------------------------------------------------------------- hostile telemetry

def _poison(every: int, value: float):
    count = [0]

    def mutate(m):
        if m.get_type() in ("ATTITUDE", "LOCAL_POSITION_NED"):
            count[0] += 1
            if count[0] % every == 0:
                field = "roll" if m.get_type() == "ATTITUDE" else "z"
                setattr(m, field, value)
                return m.__class__(*[getattr(m, f) for f in m.fieldnames])
        return m
    return mutate


@pytest.mark.parametrize("value", [math.nan, math.inf, -1e38])
def test_poisoned_telemetry_is_rejected_and_never_reaches_the_wire(value):
    result, snap, uplink, params = fly_through(_poison(7, value))
    assert result.exit_reason == "completed", [e["text"] for e in result.events if e["kind"] == "failsafe"]
    rejected = result.link["telemetry_rejected"]
    assert sum(rejected.values()) > 100, rejected
    assert any(k.startswith("ATTITUDE") for k in rejected) and any(k.startswith("LOCAL_POSITION_NED") for k in rejected)
    assert abs(result.metrics["steady_state_error_m"]) < 0.05
    assert_wire_clean(uplink)
    assert_landed(result, snap, params)


def test_other_systems_and_components_on_the_vehicles_own_address_are_ignored():
    other = M.MAVLink(None, srcSystem=2, srcComponent=1)
    companion = M.MAVLink(None, srcSystem=1, srcComponent=191)

    def mutate(m):
        if m.get_type() != "ATTITUDE":
            return m
        return [m, (M.MAVLink_attitude_message(m.time_boot_ms + 1, 1.0, -1.0, 2.0, 5.0, 5.0, 5.0), other),
                (M.MAVLink_heartbeat_message(2, 3, 0, 9, 4, 3), other),
                (M.MAVLink_attitude_message(m.time_boot_ms + 1, 0.5, 0.5, 0.5, 1.0, 1.0, 1.0), companion),
                (M.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3), companion)]

    result, snap, uplink, params = fly_through(mutate)
    assert result.exit_reason == "completed"
    assert result.link["other_system"] > 500
    assert abs(result.metrics["steady_state_error_m"]) < 0.05
    assert_wire_clean(uplink)
    assert_landed(result, snap, params)


def test_telemetry_validator_reasons():
    v = TelemetryValidator(wall_ns=lambda: 0)
    assert v.attitude(0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 10)
    assert not v.attitude(math.nan, 0.0, 0.0, 0.0, 0.0, 0.0, 20)
    assert not v.attitude(0.1, 0.0, 0.0, 0.0, 99.0, 0.0, 30)
    assert not v.attitude(0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 5)       # older than the last one
    assert not v.attitude(0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 10)      # a duplicate
    assert not v.attitude(0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 10_000_000)  # leapt hours ahead
    assert not v.position(0.0, 0.0, math.inf, 0.0, 0.0, 0.0, 10)
    assert not v.position(1e6, 0.0, 0.0, 0.0, 0.0, 0.0, 10)
    assert not v.voltage(math.nan)
    assert v.rejected == {"ATTITUDE: non-finite value": 1, "ATTITUDE: rate out of range": 1,
                          "ATTITUDE: time stamp went backwards": 1, "ATTITUDE: duplicate time stamp": 1,
                          "ATTITUDE: time stamp leapt ahead": 1, "LOCAL_POSITION_NED: non-finite value": 1,
                          "LOCAL_POSITION_NED: position out of range": 1,
                          "SYS_STATUS: battery voltage out of range": 1}


# ---------------------------------------------------------------------- faults in the loop

def test_an_exception_in_the_controller_lands_and_restores():
    def hook(flight):
        step = flight.controller.step

        def failing(k, state, ref, **kw):
            if k == 250:
                raise ZeroDivisionError("injected")
            return step(k, state, ref, **kw)
        flight.controller.step = failing

    result, snap, uplink, params = fly_through(flight_hook=hook)
    assert result.exit_reason == "internal_error" and result.exit_code == 11
    fs = [e for e in result.events if e["kind"] == "failsafe"]
    assert "ZeroDivisionError: injected" in fs[0]["text"] and "Traceback" in fs[0]["traceback"]
    assert_wire_clean(uplink)
    assert_landed(result, snap, params)


def test_a_non_finite_controller_output_is_never_sent():
    def hook(flight):
        step = flight.controller.step

        def nan_after(k, state, ref, **kw):
            cmd = step(k, state, ref, **kw)
            return cmd._replace(thrust_n=math.nan) if k >= 250 else cmd
        flight.controller.step = nan_after

    result, snap, uplink, params = fly_through(flight_hook=hook)
    assert result.exit_reason == "unsafe_command" and result.exit_code == 10
    assert_wire_clean(uplink)
    assert_landed(result, snap, params)


def test_the_output_guard_replaces_a_bad_setpoint_and_fails_safe():
    def hook(flight):
        def bad_fields(state, cmd, **_kw):
            return {"message": "SET_ATTITUDE_TARGET", "type_mask": 0, "q": [math.nan, 0.0, 0.0, 0.0],
                    "body_rates": [0.0, 0.0, 0.0], "thrust": 0.4}

        orig_preflight = flight.preflight

        def preflight():
            orig_preflight()
            fields = flight.session.adapter.fields
            flight.session.adapter.fields = (lambda state, cmd, *a, **kw: bad_fields(state, cmd)
                                             if flight.stats.ticks >= 250 else fields(state, cmd, *a, **kw))
        flight.preflight = preflight

    result, snap, uplink, params = fly_through(flight_hook=hook)
    assert result.exit_reason == "unsafe_command"
    assert result.link["blocked"] >= 1 and "SET_ATTITUDE_TARGET: non-finite field" in result.link["guard_blocked"]
    assert_wire_clean(uplink)
    assert_landed(result, snap, params)


def test_output_guard_limits():
    g = OutputGuard(GuardLimits(max_body_rate_rad_s=10.0))
    mk = M.MAVLink(None)
    ok = M.MAVLink_set_attitude_target_message(0, 1, 1, 0, [1, 0, 0, 0], 0.1, 0.0, 0.0, 0.4)
    assert g.check(ok) is None
    for msg, why in [
        (M.MAVLink_set_attitude_target_message(0, 1, 1, 0, [1, 0, 0, 0], math.nan, 0, 0, 0.4), "non-finite field"),
        (M.MAVLink_set_attitude_target_message(0, 1, 1, 0, [0.5, 0, 0, 0], 0, 0, 0, 0.4), "quaternion not unit"),
        (M.MAVLink_set_attitude_target_message(0, 1, 1, 0, [1, 0, 0, 0], 0, 0, 0, 1.5), "thrust outside 0..1"),
        (M.MAVLink_set_attitude_target_message(0, 1, 1, 0, [1, 0, 0, 0], 0, 11, 0, 0.4), "body rate beyond limit"),
        (M.MAVLink_set_actuator_control_target_message(0, 0, 1, 1, [0, 0, 2, 0, 0, 0, 0, 0]), "control outside -1..1"),
        (M.MAVLink_command_long_message(1, 1, 176, 0, math.inf, 0, 0, 0, 0, 0, 0), "non-finite parameter"),
    ]:
        assert g.check(msg) is not None and g.check(msg).endswith(why)
    del mk


# ---------------------------------------------------------------------- a second ground station on the same link

def test_stream_clobbering_on_the_same_link_is_undone():
    """MAVProxy-style REQUEST_DATA_STREAM(ALL, 4 Hz) every 2 s of vehicle time, on the ground station's own link."""
    def clobber(relay, server, stop):
        next_t = 0.0
        while not stop.is_set():
            if server.time_s >= next_t:
                relay.inject(M.MAVLink_request_data_stream_message(1, 1, M.MAV_DATA_STREAM_ALL, 4, 1))
                next_t = server.time_s + 2.0
            time.sleep(0.002)

    config = short_config(takeoff_s=3.0, hold_s=9.0)
    result, snap, uplink, params = fly_through(config=config, during=clobber, controller="nlsoc")
    assert result.exit_reason == "completed", [e["text"] for e in result.events if e["kind"] in ("failsafe", "warning")]
    assert result.link["stream_rerequests"] >= 3
    assert any("asking for 100 Hz again" in e["text"] for e in result.events)
    assert abs(result.metrics["steady_state_error_m"]) < 0.05 and result.metrics["overshoot_m"] < 0.15
    assert not any(e["kind"] == "failsafe" for e in result.events)
    assert_landed(result, snap, params)


def test_stream_monitor_rerequests_then_fails():
    mon = StreamMonitor({"ATTITUDE": 100.0}, min_rate_hz=25.0, window_s=0.25, grace_s=1.0)
    counts = {"ATTITUDE": 0}
    t = 0
    verdicts = []
    for k in range(300):  # 3 s at 100 Hz: fine for 1 s, then 4 Hz
        t = k * 10_000_000
        if k < 100 or k % 25 == 0:
            counts["ATTITUDE"] += 1
        verdicts.append(mon.update(t, counts))
    rereq = [k for k, v in enumerate(verdicts) if v.rerequest]
    failed = [k for k, v in enumerate(verdicts) if v.failure]
    assert rereq and 100 <= rereq[0] <= 130
    assert failed and 200 <= failed[0] <= 235
    assert "ATTITUDE 4.0 Hz" in verdicts[failed[0]].failure


def test_an_ack_for_another_ground_station_is_not_ours():
    link = MavlinkLink("udpin:127.0.0.1:0")
    try:
        other = M.MAVLink_command_ack_message(176, 0, 0, 0, 255, 230)
        ours = M.MAVLink_command_ack_message(176, 0, 0, 0, 255, 190)
        legacy = M.MAVLink_command_ack_message(176, 0, 0, 0, 0, 0)
        for m, expect in ((other, False), (ours, True), (legacy, True)):
            m.pack(M.MAVLink(None, srcSystem=1, srcComponent=1))
            m._header.srcComponent = 1
            assert link.is_our_ack(m, 176) is expect
    finally:
        link.close()


# ---------------------------------------------------------------------- the UDP link itself

def _udp_pair():
    link = MavlinkLink("udpin:127.0.0.1:0")
    port = link.conn.port.getsockname()[1]
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    return link, port, vehicle


def _drain_for(link, seconds: float) -> list:
    out = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        out += link.drain()
        link.wait_readable(0.01)
    return out + link.drain()


def test_each_udp_datagram_is_parsed_on_its_own():
    link, port, vehicle = _udp_pair()
    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    try:
        for _ in range(20):
            vehicle.sendto(b"\xfd", ("127.0.0.1", port))            # a stray start-of-frame byte
            vehicle.sendto(mav.heartbeat_encode(2, 3, 0, 0, 3).pack(mav), ("127.0.0.1", port))
        msgs = _drain_for(link, 0.3)
        assert sum(m.get_type() == "HEARTBEAT" for m in msgs) == 20
        assert link.counters.truncated == 20
    finally:
        link.close()
        vehicle.close()


def test_datagrams_from_other_addresses_are_dropped_once_the_vehicle_is_known():
    link, port, vehicle = _udp_pair()
    stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    try:
        vehicle.sendto(mav.heartbeat_encode(2, 3, 0, 0, 3).pack(mav), ("127.0.0.1", port))
        assert len(_drain_for(link, 0.2)) == 1
        for _ in range(50):
            stranger.sendto(mav.attitude_encode(1, 1.0, 1.0, 1.0, 0, 0, 0).pack(mav), ("127.0.0.1", port))
            stranger.sendto(b"\x01", ("127.0.0.1", port))
        vehicle.sendto(mav.heartbeat_encode(2, 3, 0, 0, 3).pack(mav), ("127.0.0.1", port))
        msgs = _drain_for(link, 0.3)
        assert [m.get_type() for m in msgs] == ["HEARTBEAT"]
        assert link.counters.other_address == 100
    finally:
        link.close()
        vehicle.close()
        stranger.close()


class _FakeVehicle(threading.Thread):
    """Answers PARAM_SET with a stale (duplicated) PARAM_VALUE of the old value, then the real echo."""

    def __init__(self, port: int) -> None:
        super().__init__(daemon=True)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = port
        self.mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
        self.parser = M.MAVLink(None)
        self.stop = threading.Event()

    def send(self, msg) -> None:
        self.sock.sendto(msg.pack(self.mav), ("127.0.0.1", self.port))

    def run(self) -> None:
        self.send(self.mav.heartbeat_encode(2, 3, 0, 0, 3))
        while not self.stop.is_set():
            r, _, _ = select.select([self.sock], [], [], 0.05)
            if not r:
                continue
            data, _ = self.sock.recvfrom(65535)
            for m in self.parser.parse_buffer(data) or []:
                if m.get_type() == "PARAM_SET":
                    old = M.MAVLink_param_value_message(b"GUID_OPTIONS", 0.0, M.MAV_PARAM_TYPE_REAL32, 40, 5)
                    self.send(old)
                    self.send(old)
                    time.sleep(0.05)
                    self.send(M.MAVLink_param_value_message(b"GUID_OPTIONS", m.param_value,
                                                            M.MAV_PARAM_TYPE_REAL32, 40, 5))


def test_a_duplicated_param_value_is_not_taken_for_the_echo():
    link = MavlinkLink("udpin:127.0.0.1:0")
    v = _FakeVehicle(link.conn.port.getsockname()[1])
    v.start()
    try:
        link.wait_heartbeat(timeout_s=3.0)
        assert link.param_set("GUID_OPTIONS", 8.0, timeout_s=1.0) == 8.0
    finally:
        v.stop.set()
        v.join(2)
        link.close()


# ---------------------------------------------------------------------- the command line

def gcs(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gcs.cli", *args], capture_output=True, text=True, timeout=timeout)


@pytest.mark.parametrize("args, key", [
    (["--target-system", "300"], "--target-system"),
    (["--target-component", "0"], "--target-component"),
    (["--seed", "-1"], "--seed"),
    (["--summary", "/no/such/dir/s.json"], "--summary"),
    (["--signing-key", "/no/such/key"], "--signing-key"),
    (["--duration", "0.001"], "--duration"),
    (["--telemetry-rate", "1e-40"], "telemetry_rate_hz"),
    (["--telemetry-rate", "1e300"], "telemetry_rate_hz"),
])
def test_bad_options_are_refused_before_anything_flies(args, key):
    p = gcs("fly", "--sitl", "lockstep", *args)
    assert p.returncode == 2, p.stderr
    assert key in p.stderr and "Traceback" not in p.stderr
    assert "armed" not in p.stdout


def test_the_built_in_sitl_dying_in_flight_is_noticed_at_once(tmp_path):
    summary = tmp_path / "s.json"
    proc = subprocess.Popen([sys.executable, "-m", "gcs.cli", "fly", "--sitl", "realtime", "--summary", str(summary),
                             "--no-log"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        for line in proc.stdout:  # type: ignore[union-attr]
            if line.startswith("[phase] takeoff ("):
                break
        children = subprocess.run(["pgrep", "-P", str(proc.pid)], capture_output=True, text=True).stdout.split()
        sitl = [int(c) for c in children
                if "sitl.cli" in Path(f"/proc/{c}/cmdline").read_bytes().decode(errors="replace")]
        assert sitl, children
        t_kill = time.monotonic()
        for pid in sitl:
            subprocess.run(["kill", "-9", str(pid)])
        out, err = proc.communicate(timeout=30)
        elapsed = time.monotonic() - t_kill
    finally:
        if proc.poll() is None:
            proc.kill()
    doc = json.loads(summary.read_text())
    assert proc.returncode == 6 and doc["exit_reason"] == "link_error"
    assert elapsed < 5.0
    assert any("the built-in SITL exited" in e["text"] for e in doc["events"])
    assert "Traceback" not in err


def test_a_log_on_a_device_is_refused_without_a_traceback():
    p = gcs("fly", "--sitl", "lockstep", "--log", "/dev/full")
    assert p.returncode == 7, p.stderr
    assert "not a regular file" in p.stderr and "Traceback" not in p.stderr
