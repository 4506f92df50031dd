"""Links: per-link stream rates, several endpoints at once, UDP datagrams parsed one by one, fresh SYS_STATUS."""

from __future__ import annotations

import socket
import subprocess
import sys
import time

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from sitl_testkit import Gcs

from sitl.copter.server import SitlServer
from sitl.net.radio import RadioParams
from sitl.net.tcp import TcpTransport
from sitl.net.udp import UdpTransport

M = mavutil.mavlink
STEPS = 400


def attitude_step(gcs: Gcs, expect_ms: int):
    """One lockstep step (a level target); the ATTITUDE stamped with the step's end."""
    gcs.conn.mav.set_attitude_target_send(0, 1, 1, 0b111, [1.0, 0.0, 0.0, 0.0], 0, 0, 0, 0.0)
    m = gcs.recv("ATTITUDE", 5.0)
    assert m is not None, "no ATTITUDE after a step"
    assert m.time_boot_ms == expect_ms, "not exactly one ATTITUDE per step"
    return m


def sync(gcs: Gcs) -> None:
    """Everything the vehicle sent this client before now has arrived (one socket, in order)."""
    assert gcs.param_get("SR0_EXTRA1") is not None


def test_a_second_ground_station_does_not_change_the_first_ones_rates(make_server, make_gcs):
    srv = make_server()
    b = make_gcs(srv)                                   # like MAVProxy: ALL at 4 Hz at connect, then again
    b.conn.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_ALL, 4, 1)
    assert b.param_get("SR0_EXTRA1").param_value == 4
    a = make_gcs(srv)
    assert a.request(M.MAVLINK_MSG_ID_ATTITUDE, 100).result == M.MAV_RESULT_ACCEPTED
    t0 = srv.snapshot()["time_s"]
    assert t0 == 0.0
    last_request = time.monotonic()
    for k in range(STEPS):
        if time.monotonic() - last_request >= 0.5 or k % 100 == 50:   # every 0.5 s, and surely some
            b.conn.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_ALL, 4, 1)
            last_request = time.monotonic()
        attitude_step(a, 10 * (k + 1))
    sync(a)
    sync(b)
    assert len(a.log["ATTITUDE"]) == STEPS               # 100 Hz: one per step, none more
    assert a.conn.mav_loss == 0                          # its own sequence numbers: no gaps
    n_b = len(b.log.get("ATTITUDE", []))
    assert 15 <= n_b <= 17, n_b                          # 4 Hz over 4 s of simulated time
    assert "LOCAL_POSITION_NED" not in a.log             # B's ALL request did not reach A
    assert len(b.log.get("GLOBAL_POSITION_INT", [])) in (15, 16, 17)
    # MESSAGE_INTERVAL answers the asking link about its own rates, and only it
    a.command(M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE)
    b.command(M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE)
    sync(a)
    sync(b)
    assert [m.interval_us for m in a.log["MESSAGE_INTERVAL"]] == [10_000]
    assert [m.interval_us for m in b.log["MESSAGE_INTERVAL"]] == [250_000]
    assert srv.snapshot()["links"] == 2


def test_udp_and_tcp_at_once_are_separate_links(make_server, make_gcs):
    srv = make_server(transport=[UdpTransport(("127.0.0.1", 0)), TcpTransport(("127.0.0.1", 0))])
    udp_cs, tcp_cs = srv.connection_strings
    assert udp_cs.startswith("udpout:") and tcp_cs.startswith("tcp:") and srv.connection_string == udp_cs
    u = make_gcs(udp_cs)
    t = make_gcs(tcp_cs, hello=False)                   # TCP: a heartbeat without saying anything
    assert u.request(M.MAVLINK_MSG_ID_ATTITUDE, 100).result == M.MAV_RESULT_ACCEPTED
    assert t.request(M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 100).result == M.MAV_RESULT_ACCEPTED
    for k in range(20):
        attitude_step(u, 10 * (k + 1))
        pos = t.recv("LOCAL_POSITION_NED", 5.0)
        assert pos is not None and pos.time_boot_ms == 10 * (k + 1)
    sync(u)
    sync(t)
    assert "LOCAL_POSITION_NED" not in u.log and "ATTITUDE" not in t.log
    assert u.conn.mav_loss == 0 and t.conn.mav_loss == 0


def test_command_line_serves_several_endpoints():
    proc = subprocess.Popen([sys.executable, "-m", "sitl.cli", "--udp-listen", "127.0.0.1:0", "--tcp", "127.0.0.1:0",
                             "--lockstep"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = [proc.stdout.readline().strip(), proc.stdout.readline().strip()]
        assert lines[0].startswith("udpout:127.0.0.1:") and lines[1].startswith("tcp:127.0.0.1:"), lines
        for cs in lines:
            g = Gcs(cs, hello=cs.startswith("udp"))
            try:
                assert g.wait_heartbeat() is not None
                assert g.param_get("GUID_TIMEOUT").param_value == 3.0
            finally:
                g.close()
        proc.terminate()
        _, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0 and "Traceback" not in err


def _pack(enc: mavlink.MAVLink, msg) -> bytes:
    buf = msg.pack(enc)
    enc.seq = (enc.seq + 1) & 0xFF
    return buf


def _stray_byte_then_heartbeats(srv: SitlServer) -> None:
    port = int(srv.connection_string.rsplit(":", 1)[1])
    enc = mavlink.MAVLink(None, srcSystem=200, srcComponent=1)
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.settimeout(5.0)
    try:
        c0 = srv.snapshot()["counters"]
        s.sendto(b"\xfd", ("127.0.0.1", port))
        for _ in range(20):
            s.sendto(_pack(enc, mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)), ("127.0.0.1", port))
        s.sendto(_pack(enc, mavlink.MAVLink_param_request_read_message(1, 1, b"GUID_TIMEOUT", -1)), ("127.0.0.1", port))
        parser = mavlink.MAVLink(None)
        parser.robust_parsing = True
        end = time.monotonic() + 5.0
        answered = False
        while not answered and time.monotonic() < end:
            answered = any(m.get_type() == "PARAM_VALUE" for m in parser.parse_buffer(s.recv(65535)) or [])
        assert answered
        c = srv.snapshot()["counters"]
        assert c["frames_in"] - c0["frames_in"] == 21     # all 20 HEARTBEATs and the request
        assert c["truncated"] - c0["truncated"] == 1      # the stray byte, alone
    finally:
        s.close()


def test_a_stray_byte_datagram_does_not_swallow_the_next_frame(make_server):
    _stray_byte_then_heartbeats(make_server())


def test_datagrams_stay_separate_through_link_emulation(make_server):
    _stray_byte_then_heartbeats(make_server(radio=RadioParams(latency_s=0.002)))


def test_requested_sys_status_carries_the_current_error_counters(make_server, make_gcs):
    srv = make_server()
    g = make_gcs(srv)
    port = int(srv.connection_string.rsplit(":", 1)[1])
    enc = mavlink.MAVLink(None, srcSystem=255, srcComponent=0)
    bad = bytearray(_pack(enc, mavlink.MAVLink_param_request_list_message(1, 1)))
    bad[-1] ^= 0xFF                                      # bad CRC
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for _ in range(5):
            s.sendto(bytes(bad), ("127.0.0.1", port))
    finally:
        s.close()
    deadline = time.monotonic() + 5.0
    while srv.snapshot()["counters"]["bad_crc"] < 5 and time.monotonic() < deadline:
        time.sleep(0.01)
    ack = g.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_SYS_STATUS)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    st = g.recv("SYS_STATUS", 5.0)
    assert st is not None
    assert st.errors_comm == srv.snapshot()["counters"]["bad_crc"] == 5
