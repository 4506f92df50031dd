"""MAVLink 2 signing under attack: forged frames (wrong key) with huge timestamps, replays.

* A signed flight (``gcs fly --signing-key FILE``, ``sitl --signing-key HEX``) through the proxy,
  which cannot sign: its hostile frames go unsigned or forged (signed with a wrong key), some
  claiming the real sender's stream with a signing timestamp of 2**48 - 1.  Nothing forged may be
  taken, and nothing forged may lock the real peer out: the flight completes.
* Directly against ``sitl --udp-listen --signing-key``:
  - a signed ARM of now arms it (the test's sanity);
  - a signed ARM captured in an earlier session (its signing timestamp a day old: MAVLink's
    replay window for a new stream is one minute) replayed at a freshly (re)started sitl must
    not arm it;
  - the ARM of this session replayed after the session moved on must not arm it;
  - a forged frame (wrong key) with a huge timestamp in the ground station's stream must not make
    the sitl refuse the ground station's next, correctly signed, command.
* Directly against ``gcs.link.mavlink.MavlinkLink``: the same forgery in the vehicle's stream must
  not make the link drop the vehicle's next correctly signed frame.
"""

from __future__ import annotations

import math
import os
import socket
import subprocess
import sys
import time

import pytest

from hostile_kit import Spec, free_udp_port, report, sitl_supports, udp_port_bound
from mitm import ForgedSigned, GarbageDatagrams, HostileFields, OtherSystem, decode_frames, mavlink, new_parser

KEY_HEX = "42" * 16 + "a5" * 16
KEY = bytes.fromhex(KEY_HEX)
#: pymavlink / MAVLink signing time: 10 us units since 2015-01-01.
EPOCH_2015 = 1420070400


def signing_now() -> int:
    return int((time.time() - EPOCH_2015) * 100_000)


# ----------------------------------------------------------------------------- the signed flight
def test_signed_flight_with_forged_frames(fly):
    faults = [ForgedSigned(p=0.03, huge=True), ForgedSigned(p=0.02, huge=False),
              HostileFields(p=0.03, values=(math.nan, math.inf, 1e38), name="unsigned_or_forged_fields"),
              OtherSystem(p=0.1), GarbageDatagrams(p=0.03, max_len=800)]
    o, verdict = fly(Spec(faults=faults, signing_key=KEY_HEX, proxy_seed=11, timeout_s=60.0), expect_complete=True)
    assert not verdict, report(o, verdict)
    assert o.monitor["up_signed"] > 100 and o.monitor["down_signed"] > 100, "the link was not signed"
    assert o.proxy["faults"]["forged_signed"]["events"] > 0


# ----------------------------------------------------------------------------- directly against sitl
class SignedClient:
    """A ground station's socket towards ``sitl --udp-listen``; frames signed with ``key`` (or not)."""

    def __init__(self, port: int, key: bytes | None = KEY, sysid: int = 255, compid: int = 190,
                 timestamp: int | None = None) -> None:
        self.addr = ("127.0.0.1", port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        if key is not None:
            self.mav.signing.secret_key = key
            self.mav.signing.sign_outgoing = True
            self.mav.signing.link_id = 0
            self.mav.signing.timestamp = signing_now() if timestamp is None else timestamp
        self.parser = new_parser()
        self.armed: bool | None = None
        self.heartbeats = 0
        self.acks: list[tuple[int, int]] = []

    def frame(self, msg) -> bytes:
        buf = bytes(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) & 0xFF
        return buf

    def send_raw(self, data: bytes) -> None:
        self.sock.sendto(data, self.addr)

    def send(self, msg) -> bytes:
        data = self.frame(msg)
        self.send_raw(data)
        return data

    def arm_frame(self, arm: bool = True) -> bytes:
        return self.frame(self.mav.command_long_encode(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                                       1.0 if arm else 0.0, 0, 0, 0, 0, 0, 0))

    def heartbeat(self) -> bytes:
        return self.send(self.mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0))

    def listen(self, seconds: float, until=None) -> None:
        """Read what the sitl sends for ``seconds`` (or until ``until()``)."""
        end = time.monotonic() + seconds
        while time.monotonic() < end and not (until is not None and until()):
            try:
                data = self.sock.recv(65535)
            except (TimeoutError, OSError):
                continue
            for m in decode_frames(self.parser, data):
                if m.get_srcSystem() != 1:
                    continue
                if m.get_type() == "HEARTBEAT":
                    self.armed = bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                    self.heartbeats += 1
                elif m.get_type() == "COMMAND_ACK":
                    self.acks.append((int(m.command), int(m.result)))

    def after(self, seconds: float = 2.5) -> None:
        """Listen until the next HEARTBEAT (the state after what was just sent) and an ACK, or ``seconds``."""
        hb, acks = self.heartbeats, len(self.acks)
        self.listen(seconds, until=lambda: self.heartbeats > hb and len(self.acks) > acks)

    def arm_acks(self) -> list[int]:
        return [r for c, r in self.acks if c == mavlink.MAV_CMD_COMPONENT_ARM_DISARM]

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def signed_sitl(tmp_path):
    """Factory: a started ``sitl --udp-listen 127.0.0.1:<port> --signing-key KEY`` (real time); its port.
    Calling it again stops the previous one first (a restart).  Where the SITL keeps its signing state
    across restarts (``--signing-state``), ``state`` names the file (the same name: the same vehicle
    restarted; default: a new file, a vehicle that never saw this key)."""
    procs: list[subprocess.Popen] = []
    count = [0]

    def start(state: str | None = None) -> int:
        for p in procs:
            _stop(p)
        port = free_udp_port()
        count[0] += 1
        extra = []
        if sitl_supports("--signing-state"):
            extra = ["--signing-state", str(tmp_path / (state or f"fresh{count[0]}.json"))]
        p = subprocess.Popen([sys.executable, "-m", "sitl.cli", "--udp-listen", f"127.0.0.1:{port}",
                              "--signing-key", KEY_HEX, "--seed", "0", *extra], stdin=subprocess.DEVNULL,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        procs.append(p)
        end = time.monotonic() + 15
        while time.monotonic() < end and p.poll() is None and not udp_port_bound(port):
            time.sleep(0.02)
        assert p.poll() is None, f"sitl exited: {p.stderr.read().decode(errors='replace')[-500:]}"
        return port

    yield start
    for p in procs:
        _stop(p)
        err = p.stderr.read().decode(errors="replace")
        assert "Traceback" not in err, err[-1500:]


def _stop(p: subprocess.Popen) -> None:
    if p.poll() is None:
        p.send_signal(2)
        try:
            p.wait(5)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(5)


def _hello(c: SignedClient) -> None:
    """Say hello (the sitl answers senders) and read its greeting."""
    c.heartbeat()
    c.listen(2.0, until=lambda: c.heartbeats > 0)


def test_signed_arm_of_now_arms(signed_sitl):
    c = SignedClient(signed_sitl())
    try:
        _hello(c)
        c.send_raw(c.arm_frame())
        c.listen(2.5, until=lambda: c.armed)
        assert mavlink.MAV_RESULT_ACCEPTED in c.arm_acks() and c.armed, \
            f"a correctly signed ARM was not taken: acks {c.arm_acks()}, armed {c.armed}"
    finally:
        c.close()


def test_replayed_signed_arm_from_an_earlier_session_does_not_arm_a_restarted_sitl(signed_sitl):
    day_old = signing_now() - 24 * 3600 * 100_000
    # The ARM a ground station sent yesterday (correct key, its stream, its timestamp then), as captured.
    yesterday = SignedClient(1, timestamp=day_old)
    captured = yesterday.arm_frame()
    yesterday.close()
    port = signed_sitl()  # (re)started now
    attacker = SignedClient(port, key=None, sysid=77, compid=77)
    try:
        _hello(attacker)  # unsigned: rejected, but the sitl now answers this address
        attacker.send_raw(captured)
        attacker.after()
        assert attacker.armed is not None, "no HEARTBEAT from the sitl"
        assert not attacker.armed and mavlink.MAV_RESULT_ACCEPTED not in attacker.arm_acks(), (
            f"a day-old signed ARM replayed at a restarted sitl armed it (acks {attacker.arm_acks()}, "
            f"armed {attacker.armed}): the sitl's signing timestamp starts at 0, so any old timestamp "
            "opens a new stream")
    finally:
        attacker.close()


def test_replayed_arm_of_the_previous_session_does_not_arm_the_restarted_sitl(signed_sitl):
    """The ARM of the session just before the restart (seconds old, inside the one-minute window of a
    new stream): refused only if the vehicle remembers its streams across the restart, as ArduPilot keeps
    its signing timestamp in storage."""
    gcs = SignedClient(signed_sitl(state="vehicle.json"))
    try:
        _hello(gcs)
        captured = gcs.arm_frame()
        gcs.send_raw(captured)
        gcs.listen(2.5, until=lambda: gcs.armed)
        assert gcs.armed, f"the legitimate ARM failed: {gcs.arm_acks()}"
        gcs.send_raw(gcs.arm_frame(False))
        gcs.heartbeat()
        gcs.listen(2.5, until=lambda: gcs.armed is False)
        assert gcs.armed is False, "the legitimate DISARM failed"
    finally:
        gcs.close()
    attacker = SignedClient(signed_sitl(state="vehicle.json"), key=None, sysid=77, compid=77)  # restarted
    try:
        _hello(attacker)
        attacker.send_raw(captured)
        attacker.after()
        assert attacker.armed is not None, "no HEARTBEAT from the restarted sitl"
        assert not attacker.armed and mavlink.MAV_RESULT_ACCEPTED not in attacker.arm_acks(), (
            f"the ARM captured before the restart, replayed at once, armed the restarted sitl "
            f"(acks {attacker.arm_acks()}, armed {attacker.armed})")
    finally:
        attacker.close()


def test_replay_within_the_session_is_rejected(signed_sitl):
    port = signed_sitl()
    gcs = SignedClient(port)
    attacker = SignedClient(port, key=None, sysid=77, compid=77)
    try:
        _hello(gcs)
        captured = gcs.arm_frame()
        gcs.send_raw(captured)
        gcs.listen(2.5, until=lambda: gcs.armed)
        assert gcs.armed, f"the legitimate ARM failed: {gcs.arm_acks()}"
        gcs.send_raw(gcs.arm_frame(False))
        gcs.heartbeat()
        gcs.listen(2.5, until=lambda: gcs.armed is False)
        assert gcs.armed is False, "the legitimate DISARM failed"
        _hello(attacker)
        attacker.send_raw(captured)
        attacker.after()
        assert attacker.armed is False, "the replayed ARM of this session armed the vehicle"
    finally:
        gcs.close()
        attacker.close()


def test_forged_huge_timestamp_does_not_lock_out_the_ground_station(signed_sitl):
    port = signed_sitl()
    gcs = SignedClient(port)
    attacker = SignedClient(port, key=os.urandom(32), timestamp=2 ** 48 - 2)  # the gcs's stream, wrong key
    try:
        _hello(gcs)
        attacker.send(attacker.mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0))
        time.sleep(0.1)
        gcs.send_raw(gcs.arm_frame())
        gcs.listen(2.5, until=lambda: gcs.armed)
        assert mavlink.MAV_RESULT_ACCEPTED in gcs.arm_acks() and gcs.armed, (
            f"after one forged frame (wrong key, timestamp 2**48-2) in the ground station's stream, its correctly "
            f"signed ARM was refused (acks {gcs.arm_acks()}, armed {gcs.armed}): the stream's timestamp was taken "
            "from a frame whose signature was never checked")
    finally:
        gcs.close()
        attacker.close()


# ----------------------------------------------------------------------------- directly against MavlinkLink
def test_forged_huge_timestamp_does_not_blind_the_link():
    from gcs.link.mavlink import LinkError, MavlinkLink

    link = MavlinkLink("udpin:127.0.0.1:0", signing_key=KEY)
    addr = link.conn.port.getsockname()
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    real = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    real.signing.secret_key, real.signing.sign_outgoing, real.signing.link_id = KEY, True, 0
    real.signing.timestamp = signing_now()
    forger = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    forger.signing.secret_key, forger.signing.sign_outgoing, forger.signing.link_id = os.urandom(32), True, 0
    forger.signing.timestamp = 2 ** 48 - 2

    def hb(mav) -> bytes:
        return bytes(mav.heartbeat_encode(2, 3, 0, 0, 0).pack(mav))

    def received(wait_s: float = 0.5) -> list:
        out, end = [], time.monotonic() + wait_s
        while time.monotonic() < end:
            try:
                out += [m for m in link.drain() if m.get_type() == "HEARTBEAT"]
            except LinkError:
                pass
            link.wait_readable(0.02)
        return out

    try:
        vehicle.sendto(hb(real), addr)
        assert received(), "a correctly signed HEARTBEAT was not received"
        vehicle.sendto(hb(forger), addr)
        assert not received(0.3), "a forged HEARTBEAT (wrong key) was accepted"
        vehicle.sendto(hb(real), addr)
        got = received()
        assert got, ("after one forged frame (wrong key, timestamp 2**48-2) in the vehicle's stream the link "
                     "dropped the vehicle's next correctly signed frame")
    finally:
        vehicle.close()
        link.close()
