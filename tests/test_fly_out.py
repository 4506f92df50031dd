"""``gcs fly --out URL``: other ground stations beside the flight (:mod:`gcs.link.forward`).

Unit tests of :class:`~gcs.link.forward.Forwarder` on loopback sockets with pymavlink (URLs, the
vehicle's frames to a client byte for byte, a client's frames to the vehicle, setpoints dropped,
garbage counted, TCP both ways, ACKs of a client's commands), then ``gcs fly`` on the built-in SITL
with a pymavlink client and with MAVProxy itself on ``--out``.
"""

from __future__ import annotations

import os
import select
import shutil
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.cli import main as gcs_main
from gcs.flight.spec import FlightSpec
from gcs.link.forward import BadOutUrl, Forwarder, parse_out_url
from gcs.link.mavlink import MavlinkLink
from gcs.log import topics as T
from gcs.log.mcap.reader import read_log
from quadrotor.errors import ConfigError
from test_fly import gcs_fly

sys.path.insert(0, str(Path(__file__).resolve().parent / "hostile"))
from hostile_kit.procs import free_udp_port, stop_process


def encoder(system: int, component: int) -> mavlink.MAVLink:
    return mavlink.MAVLink(None, srcSystem=system, srcComponent=component)


def frame(mav: mavlink.MAVLink, msg) -> bytes:
    return bytes(msg.pack(mav))


def parse(data: bytes) -> list:
    p = mavlink.MAVLink(None)
    p.robust_parsing = True
    return p.parse_buffer(data) or []


class Recorder:
    def __init__(self) -> None:
        self.events: list[tuple[str, str]] = []
        self.written: list[bytes] = []
        self.streams = 0

    def texts(self) -> str:
        return "\n".join(t for _, t in self.events)


def udp_client() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(2.0)
    return s


def vehicle_msgs() -> list:
    """Frames as the link accepts them from the vehicle (system 1): parsed from the wire, so with their bytes."""
    v = encoder(1, 1)
    data = (frame(v, v.heartbeat_encode(2, 3, 81, 4, 3)) + frame(v, v.attitude_encode(1234, 0.1, -0.2, 0.3, 0, 0, 0))
            + frame(v, v.local_position_ned_encode(1234, 1.0, 2.0, -3.0, 0, 0, 0)))
    return parse(data)


def poll_until(fwd: Forwarder, rec: Recorder, cond, timeout_s: float = 2.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond() and time.monotonic() < deadline:
        fwd.poll(rec.written.append)
        time.sleep(0.005)
    assert cond(), rec.texts()


# ---------------------------------------------------------------------------------------------- URLs
@pytest.mark.parametrize("url, reason", [
    ("udp:127.0.0.1:14550", "unknown scheme 'udp'"), ("udpout:127.0.0.1", "expected SCHEME:HOST:PORT"),
    ("udpout::14550", "no host"), ("tcp:127.0.0.1:x", "port 'x' is not a number"),
    ("udpout:127.0.0.1:0", "outside 1..65535"), ("tcpin:0.0.0.0:70000", "outside 0..65535"), ("", "expected")])
def test_bad_out_urls_are_refused_naming_out_and_the_reason(url, reason):
    with pytest.raises(BadOutUrl, match=reason) as exc:
        parse_out_url(url)
    assert str(exc.value).startswith("--out ")
    with pytest.raises(ConfigError, match=f"--out.*{reason}"):
        FlightSpec(controller="pd", out=(url,))


def test_good_out_urls_and_spec_round_trip():
    for url in ("udpout:127.0.0.1:14551", "udpin:0.0.0.0:0", "tcpin:127.0.0.1:5770", "tcp:localhost:5760"):
        assert parse_out_url(url).text == url
    spec = FlightSpec(controller="pd", out=("udpout:127.0.0.1:14551", "tcpin:0.0.0.0:5770"))
    assert FlightSpec.from_json(spec.to_json()) == spec
    assert spec.command_line()[-4:] == ["--out", "udpout:127.0.0.1:14551", "--out", "tcpin:0.0.0.0:5770"]
    with pytest.raises(ConfigError, match="twice"):
        FlightSpec(out=("udpout:127.0.0.1:1", "udpout:127.0.0.1:1"))
    with pytest.raises(ConfigError, match="rig"):
        FlightSpec(vehicle="rig", out=("udpout:127.0.0.1:1",))


def test_cli_refuses_a_bad_out_before_anything_starts(capsys):
    with pytest.raises(SystemExit) as exc:
        gcs_main(["fly", "--no-log", "--out", "udpout:127.0.0.1:99999"])
    assert exc.value.code == 2
    assert "--out" in capsys.readouterr().err


def test_a_port_in_use_is_an_oserror_naming_out():
    taken = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    taken.bind(("127.0.0.1", 0))
    taken.listen(1)
    try:
        with pytest.raises(OSError, match=r"--out 'tcpin:127\.0\.0\.1:\d+': cannot open"):
            Forwarder([f"tcpin:127.0.0.1:{taken.getsockname()[1]}"])
    finally:
        taken.close()


# ---------------------------------------------------------------------------------------------- UDP
def test_vehicle_frames_reach_a_udpout_client_byte_identical_and_its_frames_reach_the_vehicle():
    client = udp_client()
    rec = Recorder()
    fwd = Forwarder([f"udpout:127.0.0.1:{client.getsockname()[1]}"], on_event=lambda k, t: rec.events.append((k, t)),
                    on_streams=lambda: setattr(rec, "streams", rec.streams + 1))
    try:
        msgs = vehicle_msgs()
        for m in msgs:
            fwd.from_vehicle(m)
        got, addr = [], None
        while len(got) < len(msgs):
            data, addr = client.recvfrom(65535)
            got.append(data)
        assert got == [bytes(m.get_msgbuf()) for m in msgs]  # one datagram per frame, the vehicle's own bytes

        c = encoder(255, 0)
        sent = [frame(c, c.heartbeat_encode(6, 8, 0, 0, 0)),
                frame(c, c.command_long_encode(1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, 4, 0, 0, 0, 0, 0)),
                frame(c, c.request_data_stream_encode(1, 1, mavlink.MAV_DATA_STREAM_ALL, 1, 1))]
        setpoints = [frame(c, c.set_attitude_target_encode(0, 1, 1, 7, [1, 0, 0, 0], 0, 0, 0, 0.9)),
                     frame(c, c.manual_control_encode(1, 0, 0, 1000, 0, 0)),
                     frame(c, c.set_attitude_target_encode(0, 1, 1, 7, [1, 0, 0, 0], 0, 0, 0, 0.9))]
        for data in sent[:2] + setpoints[:1] + [b"\xfd\x09garbage-bytes-not-a-frame\x00\x01"] + setpoints[1:] \
                + sent[2:]:
            client.sendto(data, addr)
        poll_until(fwd, rec, lambda: len(rec.written) >= 3)
        assert rec.written == sent  # verbatim: the client's ids, sequence numbers and CRCs
        c_ = fwd.counters
        assert c_.dropped == {"SET_ATTITUDE_TARGET": 2, "MANUAL_CONTROL": 1}
        assert c_.garbled >= 1 and c_.to_vehicle == 3 and c_.stream_requests == 1
        assert rec.streams == 1
        texts = rec.texts()
        assert "dropped SET_ATTITUDE_TARGET from 255/0" in texts and "gcs flies the vehicle" in texts
        assert texts.count("dropped SET_ATTITUDE_TARGET") == 1  # one event per kind, then counted
        assert "(255/0) sent DO_SET_MODE (1, 4): forwarded" in texts
        assert fwd.client_sent_recently(mavlink.MAV_CMD_DO_SET_MODE)
        assert not fwd.client_sent_recently(mavlink.MAV_CMD_COMPONENT_ARM_DISARM)
    finally:
        summary = fwd.close()
        client.close()
    assert summary["dropped"]["SET_ATTITUDE_TARGET"] == 2
    assert "setpoints dropped" in rec.events[-1][1]


def test_a_clients_param_set_of_a_flight_parameter_is_dropped_others_forwarded():
    client = udp_client()
    rec = Recorder()
    fwd = Forwarder([f"udpout:127.0.0.1:{client.getsockname()[1]}"], on_event=lambda k, t: rec.events.append((k, t)))
    fwd.protected = lambda: {"GUID_OPTIONS": 0.0, "GUID_TIMEOUT": 3.0}  # what gcs set for the flight
    try:
        fwd.from_vehicle(vehicle_msgs()[0])
        _, addr = client.recvfrom(65535)
        c = encoder(255, 0)
        ours = frame(c, c.param_set_encode(1, 1, b"GUID_OPTIONS", 0, mavlink.MAV_PARAM_TYPE_INT32))
        theirs = frame(c, c.param_set_encode(1, 1, b"SR0_EXTRA1", 4, mavlink.MAV_PARAM_TYPE_INT16))
        for data in (ours, theirs):
            client.sendto(data, addr)
        poll_until(fwd, rec, lambda: len(rec.written) >= 1)
        assert rec.written == [theirs] and fwd.counters.dropped == {"PARAM_SET": 1}
        texts = rec.texts()
        assert "dropped PARAM_SET GUID_OPTIONS = 0 from 255/0" in texts and "restores it after" in texts
        assert "sent PARAM_SET SR0_EXTRA1 = 4: forwarded" in texts
    finally:
        fwd.close()
        client.close()


def test_udpin_answers_every_address_heard_and_warns_of_our_own_ids():
    rec = Recorder()
    fwd = Forwarder(["udpin:127.0.0.1:0"], on_event=lambda k, t: rec.events.append((k, t)))
    a, b = udp_client(), udp_client()
    try:
        port = fwd.endpoints[0].port
        ours = encoder(255, 190)
        a.sendto(frame(ours, ours.heartbeat_encode(6, 8, 0, 0, 0)), ("127.0.0.1", port))
        other = encoder(254, 0)
        b.sendto(frame(other, other.heartbeat_encode(6, 8, 0, 0, 0)), ("127.0.0.1", port))
        poll_until(fwd, rec, lambda: len(rec.written) == 2)
        assert "uses gcs's own ids 255/190" in rec.texts()
        m = vehicle_msgs()[1]
        fwd.from_vehicle(m)
        assert a.recv(65535) == b.recv(65535) == bytes(m.get_msgbuf())
    finally:
        fwd.close()
        a.close()
        b.close()


# ---------------------------------------------------------------------------------------------- TCP
def test_tcpin_clients_and_a_client_that_goes_away():
    rec = Recorder()
    fwd = Forwarder(["tcpin:127.0.0.1:0"], on_event=lambda k, t: rec.events.append((k, t)))
    port = fwd.endpoints[0].port
    c1, c2 = socket.create_connection(("127.0.0.1", port)), socket.create_connection(("127.0.0.1", port))
    try:
        enc = encoder(255, 0)
        hb = frame(enc, enc.heartbeat_encode(6, 8, 0, 0, 0))
        c1.sendall(hb[:5])                     # a frame split across reads: the stream parser keeps it
        poll_until(fwd, rec, lambda: len(fwd.endpoints[0].conns) == 2)
        c1.sendall(hb[5:] + hb)
        poll_until(fwd, rec, lambda: len(rec.written) == 2)
        assert rec.written == [hb, hb]
        msgs = vehicle_msgs()
        for m in msgs:
            fwd.from_vehicle(m)
        want = b"".join(bytes(m.get_msgbuf()) for m in msgs)
        for c in (c1, c2):
            c.settimeout(2.0)
            got = b""
            while len(got) < len(want):
                got += c.recv(65535)
            assert got == want
        c2.close()
        poll_until(fwd, rec, lambda: fwd.counters.clients_gone == 1)
        for m in msgs:
            fwd.from_vehicle(m)                # never raises, the remaining client still served
        assert "went away" in rec.texts()
    finally:
        fwd.close()
        c1.close()


def test_tcp_connects_out_and_retries_quietly():
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    port = server.getsockname()[1]
    server.close()                             # nobody listens yet: a refusal said once, retried
    rec = Recorder()
    now = [0.0]
    fwd = Forwarder([f"tcp:127.0.0.1:{port}"], on_event=lambda k, t: rec.events.append((k, t)), clock=lambda: now[0])
    try:
        poll_until(fwd, rec, lambda: "cannot connect" in rec.texts())
        server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        server.bind(("127.0.0.1", port))
        server.listen(1)
        now[0] += 5.0
        fwd.poll(rec.written.append)
        conn, _ = server.accept()
        conn.settimeout(2.0)
        m = vehicle_msgs()[0]
        time.sleep(0.05)
        fwd.from_vehicle(m)
        assert conn.recv(65535) == bytes(m.get_msgbuf())
        assert rec.texts().count("cannot connect") == 1
        conn.close()
    finally:
        fwd.close()
        server.close()


# ---------------------------------------------------------------------------------------------- ACKs
def test_an_ack_not_addressed_to_us_is_a_clients_when_it_sent_that_command():
    link = MavlinkLink("udpin:127.0.0.1:0")
    now = [100.0]
    fwd = Forwarder([], clock=lambda: now[0])
    link.forwarder = fwd
    v = encoder(1, 1)
    try:
        def ack(ts, tc):
            return parse(frame(v, v.command_ack_encode(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0, 0, 0, ts, tc)))[0]
        cmd = mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
        assert link.is_our_ack(ack(0, 0), cmd)               # no client sent it: an old autopilot's ACK
        fwd._client_commands[cmd] = now[0]                    # as _inspect records a client's command
        assert not link.is_our_ack(ack(0, 0), cmd) and not link.is_our_ack(ack(255, 0), cmd)
        assert link.is_our_ack(ack(255, 190), cmd)            # addressed to us exactly: ours
        now[0] += 3.5
        assert link.is_our_ack(ack(0, 0), cmd)
    finally:
        fwd.close()
        link.close()


# ---------------------------------------------------------------------------------------------- gcs fly
class Client(threading.Thread):
    """A pymavlink ground station (255/0) on ``--out udpout``: once the vehicle is armed, REQUEST_DATA_STREAM(ALL,
    1 Hz) as MAVProxy does and a SET_ATTITUDE_TARGET every second, with a HEARTBEAT."""

    def __init__(self, land: bool = False) -> None:
        super().__init__(daemon=True)
        self.land = land  # instead: a DO_SET_MODE to LAND once armed, as a pilot's "mode land"
        self.sock = udp_client()
        self.port = self.sock.getsockname()[1]
        self.stop = threading.Event()
        self.counts: dict[str, int] = {}
        self.sent = 0

    def run(self) -> None:
        parser, enc, addr, next_s = mavlink.MAVLink(None), encoder(255, 0), None, 0.0
        parser.robust_parsing = True
        while not self.stop.is_set():
            if select.select([self.sock], [], [], 0.05)[0]:
                data, addr = self.sock.recvfrom(65535)
                for m in parser.parse_buffer(data) or []:
                    t = m.get_type()
                    self.counts[t] = self.counts.get(t, 0) + 1
                    if t == "HEARTBEAT" and m.get_srcSystem() == 1 and m.base_mode & 128:
                        self.counts["armed"] = 1
            if addr is not None and self.counts.get("armed") and time.monotonic() >= next_s:
                next_s = time.monotonic() + 1.0
                if self.land:
                    if not self.sent:
                        self.sock.sendto(frame(enc, enc.command_long_encode(1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1,
                                                                            9, 0, 0, 0, 0, 0)), addr)
                        self.sent = 1
                    continue
                for msg in (enc.heartbeat_encode(6, 8, 0, 0, 0),
                            enc.request_data_stream_encode(1, 1, mavlink.MAV_DATA_STREAM_ALL, 1, 1),
                            enc.set_attitude_target_encode(0, 1, 1, 7, [0.96, 0.28, 0, 0], 0, 0, 0, 1.0)):
                    self.sock.sendto(frame(enc, msg), addr)
                self.sent += 1


def test_gcs_fly_out_with_a_pymavlink_client(tmp_path):
    client = Client()
    client.start()
    try:
        p, doc = gcs_fly("--controller", "pd", "--duration", "6", "--log", str(tmp_path / "f.mcap"),
                         "--out", f"udpout:127.0.0.1:{client.port}", timeout=120)
    finally:
        client.stop.set()
        client.join(5)
        client.sock.close()
    assert p.returncode == 0, p.stderr[-3000:]
    assert client.counts.get("ATTITUDE", 0) > 300 and client.sent >= 2, client.counts
    fwd = doc["link"]["forward"]
    assert fwd["dropped"]["SET_ATTITUDE_TARGET"] >= 2 and fwd["stream_requests"] >= 2, fwd
    texts = [e["text"] for e in doc["events"]]
    assert any(t.startswith("dropped SET_ATTITUDE_TARGET from 255/0") for t in texts), texts
    assert sum("dropped SET_ATTITUDE_TARGET" in t for t in texts) == 1
    assert "landed and disarmed" in texts
    assert doc["link"]["stream_rates_hz"]["ATTITUDE"] > 80, doc["link"]
    logged = [d["text"] for _, d in read_log(tmp_path / "f.mcap", [T.EVENTS]).decoded(T.EVENTS)]
    assert any(t.startswith("dropped SET_ATTITUDE_TARGET from 255/0") for t in logged)
    assert any("setpoints dropped" in t for t in logged)  # the forwarder's summary, before the log closed


def test_a_clients_mode_change_is_the_pilots(tmp_path):
    """A client's DO_SET_MODE LAND reaches the vehicle; the flight sees the vehicle leave guided control (exit 9)."""
    client = Client(land=True)
    client.start()
    try:
        p, doc = gcs_fly("--controller", "pd", "--sitl", "lockstep", "--duration", "20", "--no-log",
                         "--out", f"udpout:127.0.0.1:{client.port}", timeout=120)
    finally:
        client.stop.set()
        client.join(5)
        client.sock.close()
    assert p.returncode == 9, p.stderr[-3000:]
    texts = [e["text"] for e in doc["events"]]
    assert any("(255/0) sent DO_SET_MODE (1, 9): forwarded" in t for t in texts), texts
    assert client.counts.get("COMMAND_ACK", 0) >= 1  # the vehicle's answer went back to the client
    assert doc["link"]["forward"]["commands"] == 1


def test_gcs_fly_out_with_mavproxy(tmp_path):
    exe = shutil.which("mavproxy.py")
    if exe is None:
        pytest.skip("mavproxy.py is not installed")
    port = free_udp_port()
    state = tmp_path / "mavproxy"
    state.mkdir()
    mp = subprocess.Popen([exe, f"--master=udpin:127.0.0.1:{port}", "--daemon", "--non-interactive",
                           f"--state-basedir={state}"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                          stdin=subprocess.DEVNULL, text=True, cwd=state, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    try:
        p, doc = gcs_fly("--controller", "pd", "--duration", "6", "--no-log", "--out", f"udpout:127.0.0.1:{port}",
                         timeout=120)
    finally:
        stop_process(mp)
        out = mp.stdout.read() if mp.stdout else ""
    assert p.returncode == 0, p.stderr[-3000:] + "\nMAVProxy:\n" + out[-3000:]
    fwd = doc["link"]["forward"]
    assert fwd["from_clients"] > 10 and fwd["to_vehicle"] == fwd["from_clients"], fwd
    assert "Detected vehicle 1:1" in out, out[-3000:]
    texts = [e["text"] for e in doc["events"]]
    assert "landed and disarmed" in texts
