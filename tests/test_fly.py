"""``gcs fly`` end to end against the SITL (lockstep unless said otherwise)."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import select
import signal
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
from gcs.link.mavlink import MavlinkLink
from gcs.vehicles.mavlink import MavlinkSession
from sitl.copter.server import SitlServer
from sitl.net.udp import UdpTransport

CONFIGS = Path(__file__).resolve().parents[1] / "configs"

ALTITUDE_MISSION = """[[mission.phases]]
kind = "takeoff"
z_m = 2.0
duration_s = 5.0

[[mission.phases]]
kind = "hold"
duration_s = 10.0

"""

CIRCLE_MISSION = """[[mission.phases]]
kind = "takeoff"
z_m = 1.5
duration_s = 5.0

[[mission.phases]]
kind = "circle"
radius_m = 1.0
period_s = 20.0
duration_s = 20.0

[[mission.phases]]
kind = "land"
duration_s = 6.0

"""


def write_config(tmp_path: Path, base: str, mission: str, name: str, horizon_s: float) -> Path:
    text = (CONFIGS / f"{base}.toml").read_text()
    start = text.index("[[mission.phases]]")
    end = text.index("# ---- LOC")
    text = text[:start] + mission + text[end:]
    text = re.sub(r"horizon_s = [0-9.]+", f"horizon_s = {horizon_s}", text)
    text = re.sub(r"duration_s = 600.0\n", "duration_s = 15.0\n", text)
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


def gcs_fly(*args: str, timeout: float = 240) -> tuple[subprocess.CompletedProcess, dict | None]:
    summary = Path(os.environ.get("TMPDIR", "/tmp")) / f"fly-summary-{os.getpid()}-{time.monotonic_ns()}.json"
    p = subprocess.run([sys.executable, "-m", "gcs.cli", "fly", *args, "-q", "--summary", str(summary)],
                       capture_output=True, text=True, timeout=timeout)
    doc = json.loads(summary.read_text()) if summary.exists() else None
    summary.unlink(missing_ok=True)
    return p, doc


def assert_landed(doc: dict) -> None:
    texts = [e["text"] for e in doc["events"]]
    assert "landed and disarmed" in texts, texts[-8:]


@pytest.mark.parametrize("controller", ["nlsoc", "loc", "pd", "nlsoc-literal"])
def test_takeoff_hold_land(tmp_path, controller):
    cfg = write_config(tmp_path, "outdoor-altitude", ALTITUDE_MISSION, "alt", 15.0)
    p, doc = gcs_fly("--controller", controller, "--config", str(cfg), "--sitl", "lockstep", "--seed", "3")
    assert p.returncode == 0, p.stderr[-2000:]
    assert doc["exit_reason"] == "completed" and doc["duration_s"] == pytest.approx(15.0)
    m = doc["metrics"]
    if controller == "nlsoc-literal":
        assert 0.06 < m["steady_state_error_m"] < 0.2          # the printed law sags (erratum 8)
    else:
        assert abs(m["steady_state_error_m"]) < 0.05
        assert m["overshoot_m"] < 0.15
    assert doc["loop"]["ticks"] == 1500 and doc["loop"]["deadline_misses"] == 0
    assert_landed(doc)


@pytest.mark.parametrize("controller", ["nlsoc", "loc", "pd"])
def test_takeoff_circle_land(tmp_path, controller):
    cfg = write_config(tmp_path, "outdoor-circle", CIRCLE_MISSION, "circle", 31.0)
    p, doc = gcs_fly("--controller", controller, "--config", str(cfg), "--sitl", "lockstep", "--seed", "4")
    assert p.returncode == 0, p.stderr[-2000:]
    assert doc["metrics"]["rms_error_m"] < 0.25
    assert_landed(doc)


def test_sigint_lands_and_disarms(tmp_path):
    cfg = write_config(tmp_path, "outdoor-circle", CIRCLE_MISSION, "circle", 31.0)
    summary = tmp_path / "s.json"
    proc = subprocess.Popen([sys.executable, "-m", "gcs.cli", "fly", "--config", str(cfg), "--sitl", "lockstep",
                             "--summary", str(summary)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        for line in proc.stdout:  # type: ignore[union-attr]
            if line.startswith("[phase] circle"):
                break
            assert time.monotonic() < deadline
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 5, err[-2000:]
    doc = json.loads(summary.read_text())
    kinds = [e["kind"] for e in doc["events"]]
    assert doc["exit_reason"] == "interrupted"
    assert "interrupt" in kinds and kinds.index("interrupt") < kinds.index("landed")
    assert_landed(doc)
    assert "Traceback" not in err


def test_link_budget_refused_at_57600_before_opening_anything(tmp_path):
    p, doc = gcs_fly("--port", str(tmp_path / "no-such-tty"), "--baud", "57600")
    assert p.returncode == 7
    assert "DOES NOT FIT" in p.stderr and "--baud 115200" in p.stderr
    assert doc["exit_reason"] == "preflight_refused"


def test_serial_flight_through_the_sitl_pty_at_115200(tmp_path):
    cfg = write_config(tmp_path, "outdoor-altitude", ALTITUDE_MISSION.replace("10.0", "3.0"), "alt", 8.0)
    sitl = subprocess.Popen([sys.executable, "-m", "sitl.cli", "--pty", "--lockstep", "--baud", "115200"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ready, _, _ = select.select([sitl.stdout], [], [], 30)
        assert ready, "the SITL printed no device path"
        device = sitl.stdout.readline().strip()  # type: ignore[union-attr]
        assert device.startswith("/dev/")
        p, doc = gcs_fly("--port", device, "--baud", "115200", "--lockstep", "--config", str(cfg))
        assert p.returncode == 0, p.stderr[-2000:]
        assert abs(doc["metrics"]["steady_state_error_m"]) < 0.05
        assert_landed(doc)
        assert doc["link"]["bad_data"] == 0
    finally:
        sitl.send_signal(signal.SIGINT)
        sitl.wait(10)


# ---------------------------------------------------------------------- in-process: link loss, foreign systems


class DownlinkCutter:
    """A UDP relay between the ground station and the SITL that can lose the downlink."""

    def __init__(self, sitl_addr: tuple[str, int]) -> None:
        self.sitl_addr = sitl_addr
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.up = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.up.bind(("127.0.0.1", 0))
        self.gcs_addr = None
        self.cut = threading.Event()
        self.stop = threading.Event()
        self.uplink_frames = 0
        self.thread = threading.Thread(target=self.run, daemon=True)

    @property
    def port(self) -> int:
        return self.sock.getsockname()[1]

    def run(self) -> None:
        while not self.stop.is_set():
            ready, _, _ = select.select([self.sock, self.up], [], [], 0.05)
            for s in ready:
                data, addr = s.recvfrom(65535)
                if s is self.sock:
                    self.gcs_addr = addr
                    self.uplink_frames += 1
                    self.up.sendto(data, self.sitl_addr)
                elif not self.cut.is_set() and self.gcs_addr is not None:
                    self.sock.sendto(data, self.gcs_addr)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join(2)
        self.sock.close()
        self.up.close()


def test_telemetry_loss_triggers_the_failsafe_and_the_vehicle_lands():
    config = load_config("outdoor-altitude")
    config = dataclasses.replace(config, flight=dataclasses.replace(config.flight, land_timeout_s=8.0))
    with SitlServer(UdpTransport(("127.0.0.1", 0)), lockstep=True, seed=5) as server:
        port = int(server.connection_string.rsplit(":", 1)[1])
        with DownlinkCutter(("127.0.0.1", port)) as relay:
            link = MavlinkLink(f"udpout:127.0.0.1:{relay.port}")
            flight = Flight(config, "nlsoc", MavlinkSession(config, link), console=lambda s: None)
            flight.preflight()

            # Lose the downlink 8 s into the simulation (airborne, holding 2 m).
            threading.Thread(target=lambda: (_wait_sim(server, 8.0), relay.cut.set()), daemon=True).start()
            result = flight.fly()
            link.close()
        snap = server.snapshot()
    assert result.exit_reason == "telemetry_lost"
    assert any(e["kind"] == "failsafe" and "telemetry stale" in e["text"] for e in result.events)
    assert snap["mode"] == "LAND" and not snap["armed"] and snap["on_ground"]


def _wait_sim(server: SitlServer, t_s: float) -> None:
    while server.time_s < t_s:
        time.sleep(0.005)


def test_telemetry_from_another_system_is_ignored():
    config = load_config("outdoor-altitude")
    takeoff, hold = config.mission
    cfg = dataclasses.replace(config, mission=(dataclasses.replace(takeoff, duration_s=3.0, z_m=1.0),
                                               dataclasses.replace(hold, duration_s=3.0)))
    with SitlServer(UdpTransport(("127.0.0.1", 0)), lockstep=True, seed=6) as server:
        link = MavlinkLink(server.connection_string)
        link.send_heartbeat()  # binds the udpout socket
        gcs_port = link.conn.port.getsockname()[1]
        stop = threading.Event()

        def intruder():
            # Another vehicle (system 2), and a companion computer of ours (system 1, component
            # 191) claiming to be disarmed in another mode: neither may steer the flight.
            mav = mavlink.MAVLink(None, srcSystem=2, srcComponent=1)
            companion = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            while not stop.is_set():
                for m, w in ((mav.attitude_encode(0, 1.0, -1.0, 2.0, 5.0, 5.0, 5.0), mav),
                             (mav.local_position_ned_encode(0, 30.0, 30.0, -50.0, 3.0, 3.0, 3.0), mav),
                             (mav.heartbeat_encode(2, 3, 0, 20, 4), mav),
                             (companion.heartbeat_encode(18, 8, 0, 0, 4), companion),
                             (companion.attitude_encode(0, 0.5, 0.5, 0.5, 1.0, 1.0, 1.0), companion)):
                    s.sendto(m.pack(w), ("127.0.0.1", gcs_port))
                time.sleep(0.01)  # 500 frames/s: a flood, but not one a busy 2-core machine cannot parse
            s.close()

        t = threading.Thread(target=intruder, daemon=True)
        t.start()
        try:
            flight = Flight(cfg, "pd", MavlinkSession(cfg, link), console=lambda s: None)
            flight.preflight()
            result = flight.fly()
        finally:
            stop.set()
            t.join(2)
            link.close()
    assert result.exit_reason == "completed"
    # From another address than the vehicle's, they are dropped unread once the vehicle is known
    # (tests/test_flight_safety.py has other systems arriving from the vehicle's own address).
    assert result.link["other_system"] + result.link["other_address"] > 100
    assert abs(result.metrics["steady_state_error_m"]) < 0.05


def test_a_mode_change_by_someone_else_stops_the_setpoints():
    """A pilot (here a second ground station) switches the vehicle to LAND mid-flight."""
    config = load_config("outdoor-altitude")
    with SitlServer(UdpTransport(("127.0.0.1", 0)), lockstep=True, seed=7) as server:
        link = MavlinkLink(server.connection_string)
        port = int(server.connection_string.rsplit(":", 1)[1])

        def pilot():
            _wait_sim(server, 6.0)
            mav = mavlink.MAVLink(None, srcSystem=200, srcComponent=1)
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.sendto(mav.command_long_encode(1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0,
                                             mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 9, 0, 0, 0, 0, 0).pack(mav),
                     ("127.0.0.1", port))
            s.close()

        threading.Thread(target=pilot, daemon=True).start()
        try:
            flight = Flight(config, "nlsoc", MavlinkSession(config, link), console=lambda s: None)
            flight.preflight()
            result = flight.fly()
        finally:
            link.close()
        snap_after = server.snapshot()
    assert result.exit_reason == "vehicle_took_over" and result.exit_code == 9
    assert any("left guided control" in e["text"] and "LAND" in e["text"] for e in result.events)
    assert 3.0 < result.duration_s < 6.0  # the mission starts after about 1.5 s of preflight
    assert snap_after["on_ground"] and not snap_after["armed"]


@pytest.mark.parametrize("output", ["rates", "actuator"])
def test_other_outputs_fly(tmp_path, output):
    cfg = write_config(tmp_path, "outdoor-altitude", ALTITUDE_MISSION, "alt", 15.0)
    p, doc = gcs_fly("--controller", "loc", "--config", str(cfg), "--sitl", "lockstep", "--output", output)
    assert p.returncode == 0, p.stderr[-2000:]
    assert abs(doc["metrics"]["steady_state_error_m"]) < 0.05
    assert_landed(doc)


def test_signed_flight():
    key = bytes(range(32))
    config = load_config("outdoor-altitude")
    takeoff, hold = config.mission
    cfg = dataclasses.replace(config, mission=(dataclasses.replace(takeoff, duration_s=2.0, z_m=1.0),
                                               dataclasses.replace(hold, duration_s=2.0)))
    with SitlServer(UdpTransport(("127.0.0.1", 0)), lockstep=True, seed=8, signing_key=key) as server:
        link = MavlinkLink(server.connection_string, signing_key=key)
        try:
            flight = Flight(cfg, "pd", MavlinkSession(cfg, link), console=lambda s: None)
            flight.preflight()
            result = flight.fly()
        finally:
            link.close()
        counters = server.snapshot()["counters"]
    assert result.exit_reason == "completed"
    assert link.mav.signing.sign_outgoing
    assert result.link["received"] > 500
    assert counters.get("unsigned", 0) <= 2, counters


def test_interrupt_before_arming_does_not_arm(tmp_path):
    summary = tmp_path / "s.json"
    proc = subprocess.Popen([sys.executable, "-m", "gcs.cli", "fly", "--sitl", "lockstep", "--summary", str(summary)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        for line in proc.stdout:  # type: ignore[union-attr]
            if line.startswith("[link] connected"):
                break
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    doc = json.loads(summary.read_text())
    assert proc.returncode == 7 and doc["exit_reason"] == "preflight_refused"
    assert "interrupted before arming" in err
    assert not any(e["kind"] == "arming" and e["text"] == "armed" for e in doc["events"])
