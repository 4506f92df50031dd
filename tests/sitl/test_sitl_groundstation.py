"""What the common ground stations ask of the built-in SITL beyond flying: home, status, sensors, MAVFTP.

Reference: what ArduCopter 4.8 answers (its GCS_MAVLink sources): HOME_POSITION / GPS_GLOBAL_ORIGIN,
GPS_RAW_INT and EKF_STATUS_REPORT, SYS_STATUS health bits (no fence breach, PREARM_CHECK), SYSTEM_TIME
with UTC, the ``@PARAM/param.pck`` file over MAVFTP, AUTOPILOT_VERSION capabilities, the hooks of the
navigation commands.
"""

from __future__ import annotations

import struct
import time
import types

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sitl.copter import dispatch_commands
from sitl.copter.ftp import ERR, OP

M = mavlink
S = M  # MAV_SYS_STATUS_* bits
FENCE = S.MAV_SYS_STATUS_GEOFENCE
PREARM = S.MAV_SYS_STATUS_PREARM_CHECK


def _request(gcs, msg_id: int, kind: str):
    ack = gcs.command(M.MAV_CMD_REQUEST_MESSAGE, msg_id)
    assert ack is not None
    return ack.result, (gcs.recv(kind) if ack.result == M.MAV_RESULT_ACCEPTED else None)


def test_home_position_origin_and_set_home(make_server, make_gcs):
    srv = make_server()
    gcs = make_gcs(srv)
    ack = gcs.command(M.MAV_CMD_GET_HOME_POSITION)
    assert ack.result == M.MAV_RESULT_ACCEPTED
    home, origin = gcs.log["HOME_POSITION"][-1], gcs.log["GPS_GLOBAL_ORIGIN"][-1]   # sent before the ACK
    boot = srv.vehicle.home
    assert home.latitude == pytest.approx(boot.lat_deg * 1e7, abs=30) and origin.latitude == round(boot.lat_deg * 1e7)
    assert home.altitude == pytest.approx(boot.alt_m * 1000, abs=200) and origin.altitude == round(boot.alt_m * 1000)
    assert list(home.q) == [1.0, 0.0, 0.0, 0.0]
    result, hp = _request(gcs, M.MAVLINK_MSG_ID_HOME_POSITION, "HOME_POSITION")
    assert result == M.MAV_RESULT_ACCEPTED and hp.latitude == home.latitude
    # DO_SET_HOME to a location 100 m north, 20 m higher: HOME_POSITION to everyone, relative_alt follows
    lat = boot.lat_deg + 100 / 111_320
    assert gcs.command(M.MAV_CMD_DO_SET_HOME, 0, 0, 0, 0, lat, boot.lon_deg, boot.alt_m + 20).result == 0
    # COMMAND_LONG carries degrees as float32 (~1 m at this latitude, as on ArduPilot; COMMAND_INT is exact)
    moved = gcs.recv("HOME_POSITION", cond=lambda m: abs(m.latitude - lat * 1e7) < 20)
    assert moved is not None and moved.x == pytest.approx(100, abs=1.5) and moved.z == pytest.approx(-20, abs=0.01)
    result, gp = _request(gcs, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, "GLOBAL_POSITION_INT")
    assert gp.relative_alt == pytest.approx(-20_000, abs=300)     # 20 m below the new home
    # locked by DO_SET_HOME: arming no longer moves it
    assert gcs.arm().result == M.MAV_RESULT_ACCEPTED
    assert srv.sim.home.lat_deg == pytest.approx(lat)
    # a home beyond 50 km of the origin is refused; param1 other than 0/1 fails
    assert gcs.command(M.MAV_CMD_DO_SET_HOME, 0, 0, 0, 0, boot.lat_deg + 1.0, boot.lon_deg, 0).result == \
        M.MAV_RESULT_FAILED
    assert gcs.command(M.MAV_CMD_DO_SET_HOME, 2, 0, 0, 0, lat, boot.lon_deg, 0).result == M.MAV_RESULT_FAILED
    # COMMAND_INT with a relative altitude; then param1 = 1: the current position
    gcs.conn.mav.command_int_send(1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_DO_SET_HOME, 0, 0, 0, 0, 0, 0,
                                  round(boot.lat_deg * 1e7), round(boot.lon_deg * 1e7), 5.0)
    assert gcs.recv("COMMAND_ACK").result == M.MAV_RESULT_ACCEPTED
    assert srv.sim.home.alt_m == pytest.approx(boot.alt_m + 25)
    assert gcs.command(M.MAV_CMD_DO_SET_HOME, 1).result == M.MAV_RESULT_ACCEPTED
    assert srv.sim.home.alt_m == pytest.approx(boot.alt_m, abs=0.3)
    # SET_HOME_POSITION (a message, no ACK)
    gcs.conn.mav.set_home_position_send(1, round(lat * 1e7), round(boot.lon_deg * 1e7), round(boot.alt_m * 1000),
                                        0, 0, 0, [1, 0, 0, 0], 0, 0, 0)
    assert gcs.recv("HOME_POSITION", cond=lambda m: abs(m.latitude - lat * 1e7) < 2) is not None


def test_home_waits_for_the_emulated_ekf_and_is_reset_at_arming(make_server, make_gcs):
    srv = make_server(emulate="arducopter", ekf_ready_s=0.5)
    gcs = make_gcs(srv)
    assert gcs.command(M.MAV_CMD_GET_HOME_POSITION).result == M.MAV_RESULT_FAILED     # no home before the EKF
    assert _request(gcs, M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, "GPS_GLOBAL_ORIGIN")[0] == M.MAV_RESULT_FAILED
    result, ekf = _request(gcs, M.MAVLINK_MSG_ID_EKF_STATUS_REPORT, "EKF_STATUS_REPORT")
    assert result == 0 and not ekf.flags & M.EKF_POS_HORIZ_ABS and ekf.flags & M.EKF_ATTITUDE
    assert gcs.request(M.MAVLINK_MSG_ID_ATTITUDE, 100).result == M.MAV_RESULT_ACCEPTED
    for _ in range(100):   # 1 s of lockstep steps
        gcs.conn.mav.set_attitude_target_send(0, 1, 1, 0b111, [1, 0, 0, 0], 0, 0, 0, 0.0)
        assert gcs.recv("ATTITUDE") is not None
    assert gcs.recv("HOME_POSITION") is not None or "HOME_POSITION" in gcs.log     # announced when set
    result, ekf = _request(gcs, M.MAVLINK_MSG_ID_EKF_STATUS_REPORT, "EKF_STATUS_REPORT")
    assert ekf.flags & M.EKF_POS_HORIZ_ABS and ekf.flags & M.EKF_PRED_POS_HORIZ_ABS
    assert srv.sim.home.is_set and not srv.sim.home.locked
    with srv.lock:   # the vehicle drifted 3 m north since home was set: arming re-sets home where it is
        srv.sim.home.lat_deg -= 3 / 111_320
    gcs.command(M.MAV_CMD_DO_SET_MODE, 1, 4)
    assert gcs.arm().result == M.MAV_RESULT_ACCEPTED
    assert srv.sim.home.lat_deg == pytest.approx(srv.vehicle.home.lat_deg, abs=0.3 / 111_320)


def test_gps_ekf_system_time_and_sensor_messages(make_server, make_gcs):
    srv = make_server()
    gcs = make_gcs(srv)
    result, gps = _request(gcs, M.MAVLINK_MSG_ID_GPS_RAW_INT, "GPS_RAW_INT")
    assert result == 0 and gps.fix_type >= 3 and gps.satellites_visible >= 6 and gps.eph < 200
    assert gps.lat == pytest.approx(srv.vehicle.home.lat_deg * 1e7, abs=30)
    result, ekf = _request(gcs, M.MAVLINK_MSG_ID_EKF_STATUS_REPORT, "EKF_STATUS_REPORT")
    assert ekf.flags == 831     # what ArduCopter SITL reports on the ground, ready
    result, st = _request(gcs, M.MAVLINK_MSG_ID_SYSTEM_TIME, "SYSTEM_TIME")
    assert abs(st.time_unix_usec / 1e6 - time.time()) < 600
    for msg_id, kind in ((M.MAVLINK_MSG_ID_RAW_IMU, "RAW_IMU"), (M.MAVLINK_MSG_ID_SCALED_PRESSURE, "SCALED_PRESSURE"),
                         (M.MAVLINK_MSG_ID_VIBRATION, "VIBRATION"), (M.MAVLINK_MSG_ID_POWER_STATUS, "POWER_STATUS"),
                         (M.MAVLINK_MSG_ID_MEMINFO, "MEMINFO"), (M.MAVLINK_MSG_ID_AHRS2, "AHRS2"),
                         (M.MAVLINK_MSG_ID_RC_CHANNELS, "RC_CHANNELS"),
                         (M.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT, "NAV_CONTROLLER_OUTPUT")):
        assert _request(gcs, msg_id, kind)[0] == M.MAV_RESULT_ACCEPTED, kind
    imu = gcs.log["RAW_IMU"][-1]
    assert imu.zacc == pytest.approx(-1000, abs=30) and abs(imu.xacc) < 30     # 1 g at rest, z down
    assert gcs.log["SCALED_PRESSURE"][-1].press_abs == pytest.approx(1013.25 * (1 - 2.25577e-5 * 584) ** 5.25588,
                                                                     abs=1.0)
    assert gcs.log["RC_CHANNELS"][-1].chancount == 0     # no RC
    # the stream groups as ArduCopter's
    gcs.conn.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_EXTENDED_STATUS, 50, 1)
    gcs.conn.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_EXTRA3, 50, 1)
    gcs.start_lockstep_streams()
    for _ in range(10):
        gcs.step(thrust=0.0)
    for kind in ("SYS_STATUS", "GPS_RAW_INT", "MISSION_CURRENT", "MEMINFO", "POWER_STATUS", "NAV_CONTROLLER_OUTPUT",
                 "EKF_STATUS_REPORT", "VIBRATION", "SYSTEM_TIME", "AHRS", "BATTERY_STATUS"):
        assert kind in gcs.log, kind


def test_sys_status_health_has_no_fence_breach_and_says_when_arming_would_pass(make_server, make_gcs):
    srv = make_server(prearm_delay_s=0.2)
    gcs = make_gcs(srv)
    result, st = _request(gcs, M.MAVLINK_MSG_ID_SYS_STATUS, "SYS_STATUS")
    for bit in (S.MAV_SYS_STATUS_SENSOR_3D_GYRO, S.MAV_SYS_STATUS_SENSOR_3D_ACCEL, S.MAV_SYS_STATUS_SENSOR_3D_MAG,
                S.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE, S.MAV_SYS_STATUS_SENSOR_GPS, S.MAV_SYS_STATUS_AHRS,
                S.MAV_SYS_STATUS_SENSOR_BATTERY, S.MAV_SYS_STATUS_LOGGING):
        assert st.onboard_control_sensors_present & bit and st.onboard_control_sensors_enabled & bit
        assert st.onboard_control_sensors_health & bit, hex(bit)
    # fence: present and healthy (MAVProxy: no "fence breach"), not enabled (FENCE_ENABLE 0)
    assert st.onboard_control_sensors_present & FENCE and st.onboard_control_sensors_health & FENCE
    assert not st.onboard_control_sensors_enabled & FENCE
    # pre-arm: enabled; unhealthy while the estimator settles and arming is refused ...
    assert st.onboard_control_sensors_enabled & PREARM and not st.onboard_control_sensors_health & PREARM
    assert gcs.arm().result == M.MAV_RESULT_FAILED
    gcs.conn.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_EXTENDED_STATUS, 10, 1)
    gcs.start_lockstep_streams()
    for _ in range(30):
        gcs.step(thrust=0.0)
    # ... healthy once it would pass, and arming passes
    assert gcs.log["SYS_STATUS"][-1].onboard_control_sensors_health & PREARM
    assert gcs.arm().result == M.MAV_RESULT_ACCEPTED


def _ftp(gcs, seq: int, opcode: int, data: bytes = b"", offset: int = 0, size: int | None = None,
         session: int = 0) -> None:
    n = len(data) if size is None else size
    payload = struct.pack("<HBBBBBxI", seq, session, opcode, n, 0, 0, offset) + data
    gcs.conn.mav.file_transfer_protocol_send(0, 1, 1, list(payload.ljust(251, b"\0")))


def _ftp_reply(gcs, timeout: float = 5.0):
    m = gcs.recv("FILE_TRANSFER_PROTOCOL", timeout)
    assert m is not None, "no FTP reply"
    p = bytes(m.payload)
    seq, session, opcode, size, req, burst, offset = struct.unpack_from("<HBBBBBxI", p)
    return types.SimpleNamespace(seq=seq, opcode=opcode, size=size, req=req, burst=burst, offset=offset,
                                 data=p[12:12 + size])


def test_mavftp_serves_the_parameter_file(make_server, make_gcs):
    from MAVProxy.modules.lib.param_ftp import ftp_param_decode

    srv = make_server(params={"GUID_OPTIONS": 8})
    gcs = make_gcs(srv)
    name = b"@PARAM/param.pck?withdefaults=1"
    _ftp(gcs, 1, OP.OPEN_RO, name)
    r = _ftp_reply(gcs)
    assert (r.opcode, r.req, r.seq) == (OP.ACK, OP.OPEN_RO, 2) and r.size == 4
    _ftp(gcs, 2, OP.BURST, offset=0, size=239)
    data = bytearray()
    while True:
        r = _ftp_reply(gcs)
        if r.opcode == OP.NACK:
            assert r.data[0] == ERR.EOF and r.req == OP.BURST
            break
        assert r.offset == len(data)
        data += r.data
    _ftp(gcs, 3, OP.TERMINATE)
    assert _ftp_reply(gcs).opcode == OP.ACK
    pdata = ftp_param_decode(bytes(data))
    assert pdata is not None
    got = {n.decode(): v for n, v, _t in pdata.params}
    ps = srv.sim.params
    assert set(got) == set(ps) and all(got[n] == pytest.approx(ps[n], rel=1e-6) for n in ps)
    defaults = {n.decode(): v for n, v, _t in pdata.defaults}
    # MAVProxy's decoder gives every parameter a default (its value when the file carries none): only
    # GUID_OPTIONS, set to 8 at boot, differs from its default
    assert set(defaults) == set(got) and {n: d for n, d in defaults.items() if d != got[n]} == {"GUID_OPTIONS": 0}
    # ReadFile of a block, other files, write operations: NACK at once (so a client falls back)
    _ftp(gcs, 4, OP.OPEN_RO, b"@PARAM/param.pck")
    assert _ftp_reply(gcs).opcode == OP.ACK
    _ftp(gcs, 5, OP.READ, offset=0, size=100)
    r = _ftp_reply(gcs)
    assert r.opcode == OP.ACK and r.size == 100 and struct.unpack_from("<H", r.data)[0] == 0x671B
    _ftp(gcs, 6, OP.OPEN_RO, b"@PARAM/param.pck")
    assert _ftp_reply(gcs).data[0] == ERR.FAIL       # one file open per session
    _ftp(gcs, 7, OP.RESET)
    assert _ftp_reply(gcs).opcode == OP.ACK
    _ftp(gcs, 8, OP.OPEN_RO, b"@SYS/threads.txt")
    r = _ftp_reply(gcs)
    assert r.opcode == OP.NACK and r.data[0] == ERR.NOT_FOUND
    _ftp(gcs, 9, OP.CREATE, b"/APM/x.txt")
    assert _ftp_reply(gcs).opcode == OP.NACK
    _ftp(gcs, 10, OP.LIST, b"/")
    assert _ftp_reply(gcs).opcode == OP.NACK


def test_capabilities_match_what_is_implemented(make_server, make_gcs):
    srv = make_server()
    gcs = make_gcs(srv)
    gcs.command(M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1)
    caps = gcs.recv("AUTOPILOT_VERSION").capabilities
    for bit in (M.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT, M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT,
                M.MAV_PROTOCOL_CAPABILITY_MISSION_INT, M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
                M.MAV_PROTOCOL_CAPABILITY_FTP, M.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET,
                M.MAV_PROTOCOL_CAPABILITY_MAVLINK2, M.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE,
                M.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY):
        assert caps & bit, hex(bit)
    position = "SET_POSITION_TARGET_LOCAL_NED" in dispatch_commands.NAV_MESSAGES
    assert bool(caps & M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED) == position
    # PROTOCOL_VERSION: ArduPilot answers neither the command nor REQUEST_MESSAGE 300
    assert gcs.command(M.MAV_CMD_REQUEST_PROTOCOL_VERSION, 1).result == M.MAV_RESULT_UNSUPPORTED


def test_navigation_commands_and_messages_go_to_the_navigation_module(make_server, make_gcs, monkeypatch):
    calls = []

    def nav_command(sim, command, params, frame, now_ns):
        calls.append((command, params, frame, now_ns == sim.time_ns))
        return M.MAV_RESULT_IN_PROGRESS, "testing"

    fake = types.SimpleNamespace(nav_command=nav_command, nav_message=lambda sim, msg, now: calls.append(msg))
    monkeypatch.setattr(dispatch_commands, "NAV_COMMANDS", frozenset({M.MAV_CMD_NAV_TAKEOFF}))
    monkeypatch.setattr(dispatch_commands, "dispatch_nav", fake)
    srv = make_server()
    gcs = make_gcs(srv)
    assert gcs.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 7.5).result == M.MAV_RESULT_IN_PROGRESS
    gcs.conn.mav.command_int_send(1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_TAKEOFF, 0, 0,
                                  0, 0, 0, 0, -353632621, 1491652374, 5.0)
    assert gcs.recv("COMMAND_ACK").result == M.MAV_RESULT_IN_PROGRESS
    (c1, p1, f1, t1), (c2, p2, f2, t2) = calls
    assert c1 == c2 == M.MAV_CMD_NAV_TAKEOFF and f1 is None and f2 == M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    assert len(p1) == len(p2) == 7 and p1[6] == 7.5 and int(p2[4]) == -353632621 and int(p2[5]) == 1491652374
    assert t1 and t2
