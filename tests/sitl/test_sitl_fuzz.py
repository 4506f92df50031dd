"""Garbage, truncated, mutated and hostile frames never stop the vehicle."""

from __future__ import annotations

import math
import socket
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sitl.copter.server import SitlServer
from sitl.net.tcp import TcpTransport
from sitl.net.udp import UdpTransport

M = mavlink
ENC = mavlink.MAVLink(None, srcSystem=255, srcComponent=0)

any_float = st.floats(allow_nan=True, allow_infinity=True, width=32)
small_int = st.integers(0, 255)


def pack(msg) -> bytes:
    buf = msg.pack(ENC)
    ENC.seq = (ENC.seq + 1) % 256
    return buf


COMMANDS = st.sampled_from([
    M.MAV_CMD_DO_SET_MODE, M.MAV_CMD_COMPONENT_ARM_DISARM, M.MAV_CMD_SET_MESSAGE_INTERVAL,
    M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
    M.MAV_CMD_NAV_LAND, 0, 65535])
PARAM_NAMES = st.one_of(st.sampled_from([b"GUID_OPTIONS", b"GUID_TIMEOUT", b"SYSID_THISMAV", b"SR0_EXTRA1",
                                         b"DISARM_DELAY", b"ATC_RATE_R_MAX", b"MOT_THST_HOVER", b"FRAME_CLASS"]),
                        st.binary(max_size=16))
TARGET = st.sampled_from([0, 1, 1, 1, 7])

messages = st.one_of(
    st.builds(M.MAVLink_set_attitude_target_message, st.integers(0, 2 ** 32 - 1), TARGET, st.sampled_from([0, 1, 9]),
              small_int, st.lists(any_float, min_size=4, max_size=4), any_float, any_float, any_float, any_float),
    st.builds(M.MAVLink_set_actuator_control_target_message, st.integers(0, 2 ** 63), small_int, TARGET,
              st.sampled_from([0, 1]), st.lists(any_float, min_size=8, max_size=8)),
    st.builds(M.MAVLink_command_long_message, TARGET, st.sampled_from([0, 1]), COMMANDS, small_int,
              *[any_float] * 7),
    st.builds(M.MAVLink_command_int_message, TARGET, st.sampled_from([0, 1]), small_int, COMMANDS, small_int,
              small_int, any_float, any_float, any_float, any_float, st.integers(-2 ** 31, 2 ** 31 - 1),
              st.integers(-2 ** 31, 2 ** 31 - 1), any_float),
    st.builds(M.MAVLink_param_set_message, TARGET, st.sampled_from([0, 1]), PARAM_NAMES, any_float, small_int),
    st.builds(M.MAVLink_param_request_read_message, TARGET, st.sampled_from([0, 1]), PARAM_NAMES,
              st.integers(-2 ** 15, 2 ** 15 - 1)),
    st.builds(M.MAVLink_param_request_list_message, TARGET, st.sampled_from([0, 1])),
    st.builds(M.MAVLink_request_data_stream_message, TARGET, st.sampled_from([0, 1]), small_int,
              st.integers(0, 65535), small_int),
    st.builds(M.MAVLink_set_mode_message, TARGET, small_int, st.integers(0, 2 ** 32 - 1)),
    st.builds(M.MAVLink_timesync_message, st.integers(-2 ** 63, 2 ** 63 - 1), st.integers(-2 ** 63, 2 ** 63 - 1)),
    st.builds(M.MAVLink_heartbeat_message, small_int, small_int, small_int, st.integers(0, 2 ** 32 - 1), small_int,
              small_int),
)


def mutate(frame: bytes, data: st.DataObject) -> bytes:
    b = bytearray(frame)
    for _ in range(data.draw(st.integers(1, 4))):
        op = data.draw(st.sampled_from(["flip", "truncate", "insert", "delete", "length", "flags"]))
        if not b:
            break
        i = data.draw(st.integers(0, len(b) - 1))
        if op == "flip":
            b[i] ^= data.draw(st.integers(1, 255))
        elif op == "truncate":
            del b[i:]
        elif op == "insert":
            b[i:i] = data.draw(st.binary(min_size=1, max_size=8))
        elif op == "delete":
            del b[i]
        elif op == "length" and len(b) > 1:
            b[1] = data.draw(small_int)
        elif op == "flags" and len(b) > 2:
            b[2] = data.draw(small_int)
    return bytes(b)


@pytest.fixture(scope="module")
def harness():
    """A lockstep server driven in the test's thread (never started): ``_process`` is the whole input path."""
    srv = SitlServer(UdpTransport(("127.0.0.1", 0)), lockstep=True, seed=3)
    yield srv
    srv.close()


def alive(srv: SitlServer) -> None:
    """The vehicle still simulates and still answers."""
    t = srv.sim.time_ns
    srv.tick()
    assert srv.sim.time_ns > t
    k = srv.sim.world.kinematics
    assert all(math.isfinite(v) for v in k)
    before = srv.counters.frames_in
    srv.handle_input([((0, "probe"), pack(M.MAVLink_param_request_read_message(0, 0, b"GUID_TIMEOUT", -1)), True)])
    assert srv.counters.frames_in == before + 1
    srv.links.discard()


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=600), st.booleans())
def test_random_bytes_never_crash(harness, data, datagram):
    harness.handle_input([((0, "fuzz"), data, datagram)])
    alive(harness)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(messages, min_size=1, max_size=4), st.data(), st.booleans())
def test_mutated_frames_never_crash(harness, msgs, data, datagram):
    frames = [pack(m) for m in msgs]
    blob = b"".join(mutate(f, data) if data.draw(st.booleans()) else f for f in frames)
    harness.handle_input([((0, "mutant"), blob, datagram)])
    alive(harness)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(messages)
def test_hostile_field_values_never_crash(harness, msg):
    errors = harness.counters.handler_errors
    harness.handle_input([((0, "hostile"), pack(msg), True)])
    assert harness.counters.handler_errors == errors       # handled, not merely survived
    harness.sim.params.set("SYSID_THISMAV", 1)              # keep the harness addressable
    alive(harness)


def test_bad_input_is_counted(harness):
    c0 = dict(harness.counters.as_dict())
    good = pack(M.MAVLink_param_request_list_message(1, 1))
    bad_crc = bytearray(good)
    bad_crc[-1] ^= 0xFF
    unknown = bytearray(pack(M.MAVLink_heartbeat_message(1, 2, 3, 4, 5, 3)))
    unknown[7] = 0xEE    # msgid low byte -> an id the dialect does not know (CRC cannot match either)
    peer = (0, "c")
    harness.handle_input([(peer, b"\x00\x01garbage", True), (peer, bytes(bad_crc), True), (peer, good[:-3], True),
                      (peer, pack(M.MAVLink_command_long_message(9, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)), True)])
    c = harness.counters.as_dict()
    assert c["bad_prefix"] > c0["bad_prefix"] and c["garbage_bytes"] >= c0["garbage_bytes"] + 9
    assert c["bad_crc"] == c0["bad_crc"] + 1
    assert c["truncated"] == c0["truncated"] + 1
    assert c["wrong_target"] == c0["wrong_target"] + 1
    harness.links.discard()


@pytest.fixture(scope="module")
def live_server():
    srv = SitlServer(UdpTransport(("127.0.0.1", 0)), lockstep=True, seed=5).start()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.settimeout(5.0)
    yield srv, sock
    sock.close()
    srv.stop()


def round_trip(srv: SitlServer, sock: socket.socket) -> None:
    """A valid PARAM_REQUEST_READ is answered (the endpoint is alive)."""
    port = int(srv.connection_string.rsplit(":", 1)[1])
    sock.sendto(pack(M.MAVLink_param_request_read_message(1, 1, b"GUID_TIMEOUT", -1)), ("127.0.0.1", port))
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    end = time.monotonic() + 5.0
    while time.monotonic() < end:
        data = sock.recv(65535)
        for m in parser.parse_buffer(data) or []:
            if m.get_type() == "PARAM_VALUE" and m.param_id == "GUID_TIMEOUT":
                return
    pytest.fail("no PARAM_VALUE after fuzzing")


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.one_of(st.binary(max_size=300), messages.map(pack)), min_size=1, max_size=20), st.data())
def test_fuzzed_datagrams_over_udp_never_stop_the_server(live_server, chunks, data):
    srv, sock = live_server
    port = int(srv.connection_string.rsplit(":", 1)[1])
    for c in chunks:
        if c and data.draw(st.booleans()):
            c = mutate(c, data)
        sock.sendto(c, ("127.0.0.1", port))
    # A fuzzed PARAM_SET may change SYSID_THISMAV after we reset it (the server thread reads
    # the datagrams on its own time): reset and try again.
    for attempt in range(3):
        time.sleep(0.05)
        srv.sim.params.set("SYSID_THISMAV", 1)
        try:
            round_trip(srv, sock)
            break
        except pytest.fail.Exception:
            if attempt == 2:
                raise
    assert srv.running


def test_tcp_stream_resynchronises_after_garbage():
    srv = SitlServer(TcpTransport(("127.0.0.1", 0)), lockstep=True).start()
    try:
        host, port = srv.transport.address
        s = socket.create_connection((host, port), timeout=5.0)
        s.sendall(b"\xfd\xff\x00garbage" + bytes(range(256)) + b"\xfe\x05trunc")
        parser = mavlink.MAVLink(None)
        parser.robust_parsing = True
        req = pack(M.MAVLink_param_request_read_message(1, 1, b"DISARM_DELAY", -1))
        end = time.monotonic() + 10.0
        got = False
        while not got and time.monotonic() < end:
            s.sendall(req)
            s.settimeout(0.2)
            try:
                data = s.recv(65535)
            except TimeoutError:
                continue
            got = any(m.get_type() == "PARAM_VALUE" for m in parser.parse_buffer(data) or [])
        assert got
        assert srv.snapshot()["counters"]["bad_prefix"] + srv.snapshot()["counters"]["bad_crc"] > 0
        s.close()
    finally:
        srv.stop()

