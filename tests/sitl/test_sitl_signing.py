"""MAVLink 2 signing: no lock-out by a forged frame, no replay across a restart, wrong keys counted."""

from __future__ import annotations

import json
import socket
import time

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from quadrotor.mavlink.signing import (NEW_STREAM_WINDOW, SignatureCheck, SigningStateFile, default_state_path,
                                       setup_signing, wall_clock_timestamp)
from sitl.copter.server import SitlServer
from sitl.net.endpoint import MavlinkEndpoint
from sitl.net.udp import UdpTransport

M = mavlink
KEY = bytes(range(32))
ARM = M.MAV_CMD_COMPONENT_ARM_DISARM


def signer(key: bytes = KEY, timestamp: int | None = None, link_id: int = 1, system_id: int = 255) -> mavlink.MAVLink:
    enc = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=190)
    enc.signing.secret_key = key
    enc.signing.sign_outgoing = True
    enc.signing.link_id = link_id
    enc.signing.timestamp = wall_clock_timestamp() if timestamp is None else timestamp
    return enc


def pack(enc: mavlink.MAVLink, msg) -> bytes:
    buf = msg.pack(enc)
    enc.seq = (enc.seq + 1) & 0xFF
    return buf


def arm_frame(enc: mavlink.MAVLink, arm: bool = True) -> bytes:
    return pack(enc, M.MAVLink_command_long_message(1, 1, ARM, 0, 1.0 if arm else 0.0, 0, 0, 0, 0, 0, 0))


def forged(timestamp: int, link_id: int = 1, system_id: int = 255) -> bytes:
    """A 34-byte signed frame: valid framing and CRC, a huge timestamp, a garbage signature."""
    buf = bytearray(pack(signer(bytes(32), timestamp, link_id, system_id), M.MAVLink_heartbeat_message(6, 8, 0, 0,
                                                                                                      0, 3)))
    buf[-6:] = b"\x00\x11\x22\x33\x44\x55"
    return bytes(buf)


class Client:
    """A raw UDP ground station: sends bytes, reads what the vehicle answers (verified with ``KEY``)."""

    def __init__(self, srv: SitlServer) -> None:
        self.addr = ("127.0.0.1", int(srv.connection_string.rsplit(":", 1)[1]))
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.settimeout(0.2)
        self.parser = mavlink.MAVLink(None)
        self.parser.robust_parsing = True
        setup_signing(self.parser, KEY, sign_outgoing=False)

    def send(self, data: bytes) -> None:
        self.sock.sendto(data, self.addr)

    def ack(self, command: int, timeout: float = 3.0):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                data = self.sock.recv(65535)
            except TimeoutError:
                continue
            for m in self.parser.parse_buffer(data) or []:
                if m.get_type() == "COMMAND_ACK" and m.command == command:
                    return m
        return None

    def close(self) -> None:
        self.sock.close()


def test_the_stock_check_is_locked_out_by_one_forged_frame():
    """What the fix is for: pymavlink stores the timestamp before it checks the signature."""
    rx = mavlink.MAVLink(None)
    rx.robust_parsing = True
    rx.signing.secret_key = KEY
    ts = wall_clock_timestamp()
    rx.parse_buffer(forged(ts + 10**9))
    got = rx.parse_buffer(arm_frame(signer(timestamp=ts))) or []
    assert [m.get_type() for m in got] == ["BAD_DATA"]


def test_a_forged_frame_does_not_lock_out_the_real_key():
    rx = mavlink.MAVLink(None)
    rx.robust_parsing = True
    check = setup_signing(rx, KEY, sign_outgoing=False)
    ts = wall_clock_timestamp()
    assert [m.get_type() for m in rx.parse_buffer(forged(ts + 10**9)) or []] == ["BAD_DATA"]
    assert check.bad_signature == 1 and rx.signing.timestamp < ts + 10**9   # nothing stored
    assert [m.get_type() for m in rx.parse_buffer(arm_frame(signer(timestamp=ts))) or []] == ["COMMAND_LONG"]
    assert check.accepted == 1


def test_timestamp_rules_after_the_signature():
    rx = mavlink.MAVLink(None)
    rx.robust_parsing = True
    check = setup_signing(rx, KEY, sign_outgoing=False)
    now = rx.signing.timestamp
    assert abs(now - wall_clock_timestamp()) < 5 * 100_000            # starts at the wall clock, not 0
    old = signer(timestamp=now - NEW_STREAM_WINDOW - 100)
    assert rx.parse_buffer(arm_frame(old))[0].get_type() == "BAD_DATA"  # new stream > 1 min behind
    assert check.stale_timestamp == 1
    enc = signer(timestamp=now - NEW_STREAM_WINDOW + 100)              # within the minute: accepted
    frame = arm_frame(enc)
    assert rx.parse_buffer(frame)[0].get_type() == "COMMAND_LONG"
    assert rx.parse_buffer(frame)[0].get_type() == "BAD_DATA"          # the same frame again
    assert check.replayed == 1 and check.last_rejection == "replayed"
    assert rx.parse_buffer(arm_frame(enc))[0].get_type() == "COMMAND_LONG"  # the next one: fine


def test_each_refused_frame_of_one_datagram_is_counted_for_its_own_reason():
    """A datagram is parsed whole before its frames are classified: every refusal keeps its reason."""
    ep = MavlinkEndpoint(1, 1, KEY)
    now = wall_clock_timestamp()
    enc = signer(timestamp=now)
    frame = arm_frame(enc)
    stale = arm_frame(signer(timestamp=now - NEW_STREAM_WINDOW - 100, link_id=2))
    radio_status = bytearray(pack(signer(bytes(32), now, link_id=3), M.MAVLink_radio_status_message(0, 0, 0, 0, 0,
                                                                                                     0, 0)))
    assert [m.get_type() for m in ep.decode("gcs", frame, datagram=True)] == ["COMMAND_LONG"]
    got = ep.decode("gcs", frame + stale + forged(now + 10**9) + bytes(radio_status) + frame, datagram=True)
    assert [m.get_type() for m in got] == ["RADIO_STATUS"]   # a SiK radio's frame passes unsigned (as ArduPilot)
    c = ep.counters
    assert (c.replayed, c.stale_timestamp, c.bad_signature, c.unsigned) == (2, 1, 1, 0)
    assert c.frames_in == 2 and c.malformed == 0


def test_forged_frame_then_valid_arm_over_udp(make_server):
    srv = make_server(signing_key=KEY)
    c = Client(srv)
    try:
        enc = signer()
        c.send(forged(enc.signing.timestamp + 10**10, link_id=enc.signing.link_id))
        c.send(arm_frame(enc))
        ack = c.ack(ARM)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        assert srv.snapshot()["armed"]
        counters = srv.snapshot()["counters"]
        assert counters["bad_signature"] == 1 and counters["replayed"] == 0
    finally:
        c.close()


def test_wrong_key_is_bad_signature(make_server):
    srv = make_server(signing_key=KEY)
    c = Client(srv)
    try:
        wrong = signer(key=bytes(32))
        for _ in range(3):
            c.send(arm_frame(wrong))
        c.send(pack(signer(), M.MAVLink_command_long_message(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, 1, 0, 0, 0, 0, 0, 0)))
        assert c.ack(M.MAV_CMD_REQUEST_MESSAGE) is not None
        counters = srv.snapshot()["counters"]
        assert counters["bad_signature"] == 3
        assert counters["replayed"] == counters["stale_timestamp"] == counters["unsigned"] == 0
        assert not srv.snapshot()["armed"]
    finally:
        c.close()


def _serve(state_path, fn):
    srv = SitlServer(UdpTransport(("127.0.0.1", 0)), lockstep=True, signing_key=KEY,
                     signing_state=state_path).start()
    c = Client(srv)
    try:
        return fn(srv, c)
    finally:
        c.close()
        srv.stop()


def test_a_captured_arm_is_refused_after_a_restart(tmp_path):
    state = tmp_path / "signing.json"
    enc = signer()
    captured = arm_frame(enc)

    def first(srv, c):
        c.send(captured)
        assert c.ack(ARM).result == M.MAV_RESULT_ACCEPTED
        c.send(arm_frame(enc, arm=False))
        assert c.ack(ARM).result == M.MAV_RESULT_ACCEPTED
        assert not srv.snapshot()["armed"]
        return srv.endpoint.signing_timestamp

    local = _serve(state, first)
    doc = json.loads(state.read_text())
    assert doc["timestamp"] >= local - 1 and [1, 255, 190, enc.signing.timestamp - 1] in doc["streams"]

    def replay(srv, c):
        assert srv.endpoint.signing_timestamp >= local     # the local timestamp did not go back
        c.send(captured)
        assert c.ack(ARM, timeout=1.0) is None
        snap = srv.snapshot()
        assert not snap["armed"]
        assert snap["counters"]["replayed"] == 1 and snap["counters"]["bad_signature"] == 0
        c.send(arm_frame(enc))                             # the real sender goes on
        assert c.ack(ARM).result == M.MAV_RESULT_ACCEPTED

    _serve(state, replay)

    def without_state(srv, c):                             # control: what the state file prevents
        c.send(captured)
        return c.ack(ARM, timeout=1.0)

    assert _serve(tmp_path / "fresh.json", without_state) is not None


def test_state_file_is_written_atomically_and_at_most_once_a_second(tmp_path):
    t = [0.0]
    f = SigningStateFile(tmp_path / "d" / "s.json", clock_s=lambda: t[0])
    ep = MavlinkEndpoint(1, 1, KEY)
    sig = ep.mav.signing
    assert f.maybe_save(sig) and f.saves == 1
    sig.timestamp += 5
    assert not f.maybe_save(sig)                          # changed, but too soon
    t[0] = 1.1
    assert f.maybe_save(sig) and f.saves == 2
    t[0] = 5.0
    assert not f.maybe_save(sig)                          # unchanged
    assert [p.name for p in (tmp_path / "d").iterdir()] == ["s.json"]   # no temporary file left
    other = mavlink.MAVLink(None)
    assert f.load(other.signing) and other.signing.timestamp == sig.timestamp


def test_corrupt_state_is_ignored_and_reported(tmp_path):
    p = tmp_path / "s.json"
    p.write_text('{"format": "quadrotor-sitl-signing-state", "version": 1, "timestamp": -5, "streams": []}')
    f = SigningStateFile(p)
    sig = mavlink.MAVLink(None).signing
    assert not f.load(sig) and "bad timestamp" in f.load_error and sig.stream_timestamps == {}


def test_default_state_path_depends_on_key_and_system_id(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    a = default_state_path(KEY, 1)
    assert a.parent == tmp_path / "quadrotor-sitl" and a.suffix == ".json"
    assert KEY.hex() not in str(a)
    assert len({a, default_state_path(KEY, 2), default_state_path(bytes(32), 1)}) == 3
    assert default_state_path(KEY, 1) == a


def test_outgoing_frames_carry_the_wall_clock():
    ep = MavlinkEndpoint(1, 1, KEY)
    buf = ep.encode(M.MAVLink_heartbeat_message(2, 3, 0, 0, 0, 3))
    low, high = int.from_bytes(buf[-12:-8], "little"), int.from_bytes(buf[-8:-6], "little")
    assert abs((low | high << 32) - wall_clock_timestamp()) < 5 * 100_000


@pytest.mark.parametrize("bad", [b"", bytes(31)])
def test_setup_signing_refuses_bad_keys(bad):
    with pytest.raises(ValueError):
        setup_signing(mavlink.MAVLink(None), bad)


def test_one_check_shared_by_parsers():
    a, b = mavlink.MAVLink(None), mavlink.MAVLink(None)
    check = setup_signing(a, KEY, sign_outgoing=False)
    from quadrotor.mavlink.signing import install_signature_check
    assert install_signature_check(b, check) is check and b.signing is a.signing
    enc = signer()
    frame = arm_frame(enc)
    assert a.parse_buffer(frame)[0].get_type() == "COMMAND_LONG"
    b.robust_parsing = True
    assert b.parse_buffer(frame)[0].get_type() == "BAD_DATA"       # replayed on another peer's parser
    assert isinstance(check, SignatureCheck) and check.replayed == 1
