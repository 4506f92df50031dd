"""The SITL through real pymavlink clients: UDP, TCP, serial (pty); lockstep and real time."""

from __future__ import annotations

import socket
import time

import pytest
from pymavlink import mavutil
from sitl_testkit import Gcs

from quadrotor.wind import WindParams
from sitl.copter.simulation import InitialConditions
from sitl.net.pty import PtyTransport
from sitl.net.tcp import TcpTransport
from sitl.net.udp import UdpTransport

M = mavutil.mavlink
GUIDED_NOGPS, LAND = 20, 9
ARMED = M.MAV_MODE_FLAG_SAFETY_ARMED


def test_heartbeat_and_requested_stream_rates_in_real_time(make_server, make_gcs):
    srv = make_server(lockstep=False)
    gcs = make_gcs(srv)
    hb = gcs.last_heartbeat()
    assert hb.type == M.MAV_TYPE_QUADROTOR and hb.autopilot == M.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert hb.custom_mode == 0 and not hb.base_mode & ARMED
    # nothing but heartbeats until a stream is requested (like ArduCopter)
    gcs.recv(timeout=0.4, cond=lambda m: False)
    assert set(gcs.log) <= {"HEARTBEAT", "HOME_POSITION"}    # HOME_POSITION: home set (as ArduCopter)
    assert gcs.request(M.MAVLINK_MSG_ID_ATTITUDE, 50).result == M.MAV_RESULT_ACCEPTED
    gcs.conn.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_POSITION, 10, 1)
    assert gcs.recv("LOCAL_POSITION_NED", 2.0) is not None
    gcs.log.clear()
    t0 = time.monotonic()
    while time.monotonic() - t0 < 3.0:
        gcs.recv(timeout=0.1, cond=lambda m: False)
    span = time.monotonic() - t0
    att = len(gcs.log.get("ATTITUDE", []))
    pos = len(gcs.log.get("LOCAL_POSITION_NED", []))
    glob = len(gcs.log.get("GLOBAL_POSITION_INT", []))
    assert att == pytest.approx(50 * span, rel=0.10)
    assert pos == pytest.approx(10 * span, rel=0.10) and glob == pytest.approx(10 * span, rel=0.10)
    assert len(gcs.log.get("HEARTBEAT", [])) == pytest.approx(span, abs=1.01)
    assert gcs.param_get("SR0_POSITION").param_value == 10


def test_lockstep_takeoff_hold_and_land(make_server, make_gcs):
    srv = make_server(seed=4)
    gcs = make_gcs(srv)
    gcs.start_lockstep_streams()
    gcs.request(M.MAVLINK_MSG_ID_ALTITUDE, 10)
    # unsafe: battery below BATT_LOW_VOLT -> refused with a STATUSTEXT
    assert gcs.param_set("BATT_LOW_VOLT", 12.9).param_value == pytest.approx(12.9)
    assert gcs.set_mode(GUIDED_NOGPS).result == M.MAV_RESULT_ACCEPTED
    assert gcs.arm().result == M.MAV_RESULT_FAILED
    assert gcs.recv("STATUSTEXT", cond=lambda m: m.text.startswith("Arm: Battery")) is not None
    assert gcs.param_set("BATT_LOW_VOLT", 10.5).param_value == pytest.approx(10.5)
    assert gcs.arm().result == M.MAV_RESULT_ACCEPTED
    t0 = srv.time_s
    # climb at 1.25 m/s (thrust 0.75) for 3 s, then hold
    for _ in range(300):
        pos = gcs.step(0.75)
    assert srv.time_s - t0 == pytest.approx(3.0)
    assert -pos.z > 2.5 and -pos.vz == pytest.approx(1.25, abs=0.15)
    for _ in range(300):
        pos = gcs.step(0.5)
    h = -pos.z
    assert 3.0 < h < 5.0 and abs(pos.vz) < 0.15
    alt = gcs.log["ALTITUDE"][-1]
    assert alt.altitude_relative == pytest.approx(h, abs=0.3)
    assert abs(alt.altitude_relative * 10 - round(alt.altitude_relative * 10)) < 1e-3  # 10 cm baro resolution
    assert gcs.set_mode(LAND).result == M.MAV_RESULT_ACCEPTED
    for _ in range(2000):
        pos = gcs.step(0.5)                       # keeps the lockstep clock running; ignored in LAND
        hb = gcs.last_heartbeat()
        if not srv.snapshot()["armed"]:
            break
    else:
        pytest.fail("LAND did not disarm")
    gcs.drain()
    assert abs(pos.z) < 0.2
    assert any("Disarming" in t for t in gcs.texts)
    for _ in range(110):                          # heartbeats report disarmed, LAND
        gcs.step(0.5)
    hb = gcs.last_heartbeat()
    assert hb.custom_mode == LAND and not hb.base_mode & ARMED
    snap = srv.snapshot()
    assert snap["on_ground"] and snap["battery"].consumed_mah > 10


def test_arming_refused_while_leaning_or_not_landed(make_server, make_gcs):
    for initial, words in ((InitialConditions(roll_deg=40.0), "Arm: Leaning"),
                           (InitialConditions(altitude_m=10.0), "Arm: Not landed")):
        srv = make_server(initial=initial)
        gcs = make_gcs(srv)
        gcs.set_mode(GUIDED_NOGPS)
        assert gcs.arm().result == M.MAV_RESULT_FAILED
        assert gcs.recv("STATUSTEXT", cond=lambda m, words=words: m.text.startswith(words)) is not None
        assert gcs.arm(force=True).result == M.MAV_RESULT_ACCEPTED   # 21196 forces


def test_onboard_failsafe_fires_when_commands_stop_lockstep(make_server, make_gcs):
    srv = make_server()
    gcs = make_gcs(srv)
    gcs.start_lockstep_streams()
    gcs.set_mode(GUIDED_NOGPS)
    assert gcs.arm().result == M.MAV_RESULT_ACCEPTED
    for _ in range(200):
        gcs.step(0.8)
    t_last = srv.time_s
    # no new target: THROTTLE_IGNORE targets are rejected but still tick the lockstep clock
    fired_at = None
    for _ in range(600):
        gcs.step(0.5, type_mask=0b111 | 64)
        if fired_at is None and srv.snapshot()["mode"] == "LAND":
            fired_at = srv.time_s
    assert fired_at == pytest.approx(t_last + 3.0, abs=0.02)          # GUID_TIMEOUT
    gcs.drain()
    assert any(t.startswith("Guided timeout") for t in gcs.texts)
    assert gcs.last_heartbeat().custom_mode == LAND
    assert srv.snapshot()["targets_rejected"] >= 600


def test_onboard_failsafe_fires_when_commands_stop_real_time(make_server, make_gcs):
    srv = make_server(lockstep=False, params={"GUID_TIMEOUT": 0.5})
    gcs = make_gcs(srv)
    gcs.set_mode(GUIDED_NOGPS)
    assert gcs.arm().result == M.MAV_RESULT_ACCEPTED
    t_end = time.monotonic() + 0.4
    while time.monotonic() < t_end:
        gcs.conn.mav.set_attitude_target_send(0, 1, 1, 7, [1, 0, 0, 0], 0, 0, 0, 0.5)
        time.sleep(0.02)
    t_stop = time.monotonic()
    msg = gcs.recv("STATUSTEXT", timeout=5.0, cond=lambda m: m.text.startswith("Guided timeout"))
    assert msg is not None and 0.4 < time.monotonic() - t_stop < 3.0
    hb = gcs.recv("HEARTBEAT", timeout=3.0, cond=lambda m: m.custom_mode == LAND)
    assert hb is not None
    # on the ground LAND completes at once: disarmed
    hb = gcs.recv("HEARTBEAT", timeout=3.0, cond=lambda m: not m.base_mode & ARMED)
    assert hb is not None


def fly_recorded(make_server, make_gcs, seed: int) -> list[tuple]:
    srv = make_server(seed=seed, wind=WindParams(2.0, None, 0.7))
    gcs = make_gcs(srv)
    gcs.start_lockstep_streams()
    gcs.set_mode(GUIDED_NOGPS)
    gcs.arm()
    out = []
    for k in range(300):
        m = gcs.step(0.8 if k < 150 else 0.5)
        att = gcs.log["ATTITUDE"][-1]
        out.append((m.time_boot_ms, m.x, m.y, m.z, m.vx, m.vy, m.vz, att.roll, att.pitch, att.yawspeed))
    return out


def test_lockstep_is_deterministic_for_a_seed(make_server, make_gcs):
    a = fly_recorded(make_server, make_gcs, 11)
    b = fly_recorded(make_server, make_gcs, 11)
    c = fly_recorded(make_server, make_gcs, 12)
    assert a == b
    assert a != c
    assert [r[0] for r in a] == list(range(10, 3010, 10))   # one step = 10 ms, one message per step


def test_parameter_protocol(make_server, make_gcs):
    srv = make_server()
    gcs = make_gcs(srv)
    gcs.conn.mav.param_request_list_send(1, 1)
    first = gcs.recv("PARAM_VALUE")
    values = [first] + [gcs.recv("PARAM_VALUE", 2.0) for _ in range(first.param_count - 1)]
    names = {v.param_id: v for v in values}
    assert len(names) == first.param_count and {v.param_index for v in values} == set(range(first.param_count))
    for name, value in (("GUID_OPTIONS", 0), ("GUID_TIMEOUT", 3.0), ("DISARM_DELAY", 10), ("WP_SPD_UP", 2.5)):
        assert names[name].param_value == pytest.approx(value)
    assert names["MOT_THST_HOVER"].param_value == pytest.approx(0.4004, abs=1e-4)
    assert names["GUID_OPTIONS"].param_type == M.MAV_PARAM_TYPE_INT32
    gcs.conn.mav.param_request_read_send(1, 1, b"", names["DISARM_DELAY"].param_index)
    assert gcs.recv("PARAM_VALUE").param_id == "DISARM_DELAY"
    assert gcs.param_set("GUID_OPTIONS", 8).param_value == 8
    assert gcs.param_get("GUID_OPTIONS").param_value == 8
    assert srv.sim.params["GUID_OPTIONS"] == 8
    # As ArduPilot: a value outside the documented range is set; the echo carries param_index -1 (65535)
    echo = gcs.param_set("GUID_TIMEOUT", 99.0)
    assert echo.param_value == 99.0 and echo.param_index == 65535 and srv.sim.params["GUID_TIMEOUT"] == 99.0
    # an unknown name: PARAM_ERROR only, no STATUSTEXT, no PARAM_VALUE
    gcs.conn.mav.param_set_send(1, 1, b"NO_SUCH_PARAM", 1.0, M.MAV_PARAM_TYPE_REAL32)
    err = gcs.recv("PARAM_ERROR")
    assert err.param_id == "NO_SUCH_PARAM" and err.error == M.MAV_PARAM_ERROR_DOES_NOT_EXIST
    # a read-only one: denied, said, and the unchanged value echoed
    ro = gcs.param_set("FRAME_CLASS", 2)
    assert ro.param_value == 1 and srv.sim.params["FRAME_CLASS"] == 1
    assert gcs.recv("STATUSTEXT", cond=lambda m: "Param write denied (FRAME_CLASS)" in m.text) is not None
    assert not any("NO_SUCH_PARAM" in t for t in gcs.texts)


def test_commands_modes_timesync_and_messages(make_server, make_gcs):
    srv = make_server()
    gcs = make_gcs(srv)
    assert gcs.command(M.MAV_CMD_DO_SET_MODE, 1, 7).result == M.MAV_RESULT_FAILED        # CIRCLE: not emulated
    assert gcs.command(12345).result == M.MAV_RESULT_UNSUPPORTED
    gcs.conn.mav.set_mode_send(1, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)
    ack = gcs.recv("COMMAND_ACK", cond=lambda m: m.command == M.MAVLINK_MSG_ID_SET_MODE)
    assert ack.result == M.MAV_RESULT_ACCEPTED and srv.snapshot()["mode"] == "GUIDED"
    assert gcs.command(M.MAV_CMD_NAV_LAND).result == M.MAV_RESULT_ACCEPTED and srv.snapshot()["mode"] == "LAND"
    gcs.request(M.MAVLINK_MSG_ID_VFR_HUD, 20)
    assert gcs.command(M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_VFR_HUD).result == M.MAV_RESULT_ACCEPTED
    assert gcs.log["MESSAGE_INTERVAL"][-1].interval_us == 50000     # sent before the ACK, as ArduPilot does
    assert gcs.request(M.MAVLINK_MSG_ID_VFR_HUD, 0).result == M.MAV_RESULT_ACCEPTED            # -1: stop
    assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION).result == 0
    ver = gcs.recv("AUTOPILOT_VERSION")
    assert ver.capabilities & M.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_BATTERY_STATUS).result == 0
    bs = gcs.recv("BATTERY_STATUS")
    assert bs.voltages[0] == pytest.approx(4200, abs=5) and bs.voltages[3] == 65535
    assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, 9999).result == M.MAV_RESULT_FAILED
    gcs.conn.mav.timesync_send(0, 123456789)
    ts = gcs.recv("TIMESYNC")
    assert ts.ts1 == 123456789 and ts.tc1 == srv.sim.time_ns


def test_messages_for_other_systems_are_ignored_and_counted(make_server, make_gcs):
    srv = make_server()
    gcs = make_gcs(srv)
    assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, target_system=7, timeout=0.5) is None
    gcs.conn.mav.set_attitude_target_send(0, 7, 1, 7, [1, 0, 0, 0], 0, 0, 0, 0.5)
    gcs.conn.mav.param_set_send(1, 42, b"GUID_OPTIONS", 8, M.MAV_PARAM_TYPE_REAL32)   # another component
    gcs.command(M.MAV_CMD_REQUEST_MESSAGE, 1)   # round trip: everything before it was processed
    snap = srv.snapshot()
    assert snap["counters"]["wrong_target"] == 3 and snap["steps"] == 0 and not snap["armed"]
    assert srv.sim.params["GUID_OPTIONS"] == 0


def test_actuator_control_target_through_mavlink(make_server, make_gcs):
    srv = make_server(params={"DISARM_DELAY": 0})
    gcs = make_gcs(srv)
    gcs.start_lockstep_streams()
    gcs.set_mode(GUIDED_NOGPS)
    gcs.arm()
    hover = srv.vehicle.hover_thrust_fraction
    for k in range(150):
        thrust = hover + 0.15 if k < 100 else hover
        gcs.conn.mav.set_actuator_control_target_send(0, 0, 1, 1, [0, 0, 0, thrust, 0, 0, 0, 0])
        pos = gcs.recv("LOCAL_POSITION_NED")
    assert -pos.z > 1.0
    for _ in range(20):                                     # yaw torque: positive yaw rate
        gcs.conn.mav.set_actuator_control_target_send(0, 0, 1, 1, [0, 0, 0.3, hover, 0, 0, 0, 0])
        gcs.recv("LOCAL_POSITION_NED")
    assert gcs.log["ATTITUDE"][-1].yawspeed > 0.1
    assert srv.snapshot()["steps"] == 170


def test_signing_rejects_unsigned_and_wrong_keys(make_server):
    key = bytes(range(32))
    srv = make_server(signing_key=key)
    good = mavutil.mavlink_connection(srv.connection_string, source_system=255)
    good.setup_signing(key, sign_outgoing=True)
    good.mav.heartbeat_send(6, 8, 0, 0, 0)
    hb = good.recv_match(type="HEARTBEAT", blocking=True, timeout=5)
    assert hb is not None and hb._signed                      # telemetry is signed
    good.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    ack = good.recv_match(type="COMMAND_ACK", blocking=True, timeout=5)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    bad = mavutil.mavlink_connection(srv.connection_string, source_system=254)
    bad.setup_signing(bytes(32), sign_outgoing=True)            # wrong key
    plain = mavutil.mavlink_connection(srv.connection_string, source_system=253)
    try:
        for conn in (bad, plain):
            conn.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 21196, 0, 0, 0, 0, 0)
        time.sleep(0.3)
        good.mav.command_long_send(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, 1, 0, 0, 0, 0, 0, 0)
        assert good.recv_match(type="COMMAND_ACK", blocking=True, timeout=5) is not None
        c = srv.snapshot()["counters"]
        assert c["bad_signature"] >= 1 and c["unsigned"] >= 1
        assert srv.snapshot()["armed"]                          # the forged disarms were rejected
    finally:
        for conn in (good, bad, plain):
            conn.close()


def test_udp_client_mode_sends_to_a_listening_gcs(make_server, make_gcs):
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    gcs_conn = f"udpin:127.0.0.1:{port}"
    gcs = Gcs(gcs_conn, hello=False)             # listening before the vehicle starts
    try:
        srv = make_server(transport=UdpTransport(("127.0.0.1", 0), ("127.0.0.1", port)), lockstep=False)
        assert srv.connection_string == gcs_conn
        assert gcs.wait_heartbeat() is not None  # heartbeats arrive without sending anything
        assert gcs.command(M.MAV_CMD_DO_SET_MODE, 1, GUIDED_NOGPS).result == M.MAV_RESULT_ACCEPTED
    finally:
        gcs.close()


def test_tcp_endpoint(make_server, make_gcs):
    srv = make_server(transport=TcpTransport(("127.0.0.1", 0)))
    assert srv.connection_string.startswith("tcp:127.0.0.1:")
    gcs = make_gcs(srv, hello=False)
    gcs.start_lockstep_streams()
    gcs.set_mode(GUIDED_NOGPS)
    assert gcs.arm().result == M.MAV_RESULT_ACCEPTED
    for _ in range(50):
        gcs.step(0.9)
    second = make_gcs(srv, hello=False)                # a second connection is a link of its own:
    assert second.request(M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 100).result == M.MAV_RESULT_ACCEPTED
    first = gcs.step(0.9)                              # the first one's streams are unchanged
    got = second.recv("LOCAL_POSITION_NED", 2.0)       # and the second gets what it asked for
    assert got is not None and got.time_boot_ms == first.time_boot_ms
    assert "ATTITUDE" not in second.log                # and nothing it did not ask for


def test_serial_pty_endpoint_with_baud_limit(make_server, make_gcs):
    from quadrotor.clock import MonotonicClock
    from sitl.net.radio import RadioParams
    clock = MonotonicClock()
    srv = make_server(transport=PtyTransport(clock.now_ns), radio=RadioParams(baud=57600), clock=clock)
    assert srv.connection_string.startswith("/dev/")
    gcs = make_gcs(srv.connection_string, baud=57600)
    gcs.conn.mav.param_request_list_send(1, 1)
    t0 = time.monotonic()
    first = gcs.recv("PARAM_VALUE")
    for _ in range(first.param_count - 1):
        assert gcs.recv("PARAM_VALUE", 3.0) is not None
    elapsed = time.monotonic() - t0
    wire_s = first.param_count * len(first.get_msgbuf()) * 10 / 57600
    assert elapsed >= 0.9 * (wire_s - len(first.get_msgbuf()) * 10 / 57600)
