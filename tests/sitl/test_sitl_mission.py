"""The mission protocol of the built-in SITL (missions, fences, rally points) against a pymavlink client.

What ArduPilot's MissionItemProtocol does is the reference: uploads item by item with MISSION_ACK at the
end, downloads with item 0 = home, the errors of invalid items, re-requests and the upload timeout.
"""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sitl.copter.mission import REREQUEST_NS, UPLOAD_TIMEOUT_NS, MissionProtocol
from sitl.copter.simulation import Simulation
from sitl.copter.vehicle_file import load_vehicle

M = mavlink
LAT, LON = -35.3632621, 149.1652374  # ArduPilot's CMAC, the default [home]


def _wp(seq: int, command: int = M.MAV_CMD_NAV_WAYPOINT, frame: int = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        dn_m: float = 0.0, z: float = 10.0, mission_type: int = 0, params=(0.0, 0.0, 0.0, 0.0)):
    lat = LAT + dn_m / 111_000.0
    return M.MAVLink_mission_item_int_message(1, 1, seq, frame, command, 0, 1, *params, round(lat * 1e7),
                                              round(LON * 1e7), z, mission_type)


def _upload(gcs, items, mission_type: int = 0, timeout: float = 5.0):
    """MISSION_COUNT, then each requested item; returns (requests seen, final MISSION_ACK)."""
    gcs.conn.mav.mission_count_send(1, 1, len(items), mission_type)
    requests = []
    while True:
        m = gcs.recv({"MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"}, timeout)
        assert m is not None, "no request / ACK"
        if m.get_type() == "MISSION_ACK":
            return requests, m
        requests.append(m)
        gcs.conn.mav.send(items[m.seq])


def _download(gcs, mission_type: int = 0, legacy: bool = False):
    gcs.conn.mav.mission_request_list_send(1, 1, mission_type)
    count = gcs.recv("MISSION_COUNT")
    assert count is not None and count.mission_type == mission_type
    out = []
    for seq in range(count.count):
        if legacy:
            gcs.conn.mav.mission_request_send(1, 1, seq, mission_type)
            out.append(gcs.recv("MISSION_ITEM", cond=lambda m, s=seq: m.seq == s))
        else:
            gcs.conn.mav.mission_request_int_send(1, 1, seq, mission_type)
            out.append(gcs.recv("MISSION_ITEM_INT", cond=lambda m, s=seq: m.seq == s))
        assert out[-1] is not None
    return out


MISSION = [
    _wp(0),
    _wp(1, M.MAV_CMD_NAV_TAKEOFF, z=5.0),
    _wp(2, dn_m=20.0, z=8.0, params=(2.0, 0.0, 0.0, math.nan)),          # hold 2 s; yaw NaN (allowed)
    M.MAVLink_mission_item_int_message(1, 1, 3, M.MAV_FRAME_MISSION, M.MAV_CMD_DO_CHANGE_SPEED, 0, 1, 1.0, 3.0,
                                       -1.0, 0.0, 0, 0, 0.0, 0),
    _wp(4, M.MAV_CMD_NAV_SPLINE_WAYPOINT, frame=M.MAV_FRAME_GLOBAL_INT, dn_m=30.0, z=600.0),
    M.MAVLink_mission_item_int_message(1, 1, 5, M.MAV_FRAME_MISSION, M.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 1, 0, 0, 0,
                                       0, 0, 0, 0.0, 0),
]


def test_mission_upload_and_download_as_ardupilot(make_server, make_gcs):
    srv = make_server()
    gcs = make_gcs(srv)
    requests, ack = _upload(gcs, MISSION)
    assert [r.seq for r in requests] == list(range(len(MISSION)))
    assert all(r.get_type() == "MISSION_REQUEST_INT" and r.target_system == 255 for r in requests)
    assert ack.type == M.MAV_MISSION_ACCEPTED and ack.mission_type == 0
    assert gcs.recv("STATUSTEXT", cond=lambda m: m.text == "Flight plan received") is not None
    assert srv.sim.missions.count(0) == len(MISSION)

    got = _download(gcs)
    assert len(got) == len(MISSION)
    home = got[0]   # item 0 is home (absolute altitude), whatever the uploader sent
    assert home.command == M.MAV_CMD_NAV_WAYPOINT and home.frame == M.MAV_FRAME_GLOBAL
    assert home.x == round(srv.sim.home.lat_deg * 1e7) and home.z == pytest.approx(srv.sim.home.alt_m, abs=0.01)
    for sent, back in zip(MISSION[1:], got[1:], strict=True):
        assert (back.command, back.x, back.y) == (sent.command, sent.x, sent.y)
        assert back.z == pytest.approx(sent.z) and back.param1 == pytest.approx(sent.param1)
    # frames as ArduPilot stores them: relative -> GLOBAL_RELATIVE_ALT, absolute -> GLOBAL, no location -> 0
    assert [m.frame for m in got[1:]] == [3, 3, 0, 0, 0]
    assert got[1].current == 1   # the first item after home is current
    # a sequence beyond the list: MISSION_COUNT, then INVALID_SEQUENCE
    gcs.conn.mav.mission_request_int_send(1, 1, 99, 0)
    assert gcs.recv("MISSION_COUNT").count == len(MISSION)
    assert gcs.recv("MISSION_ACK").type == M.MAV_MISSION_INVALID_SEQUENCE


def test_legacy_mission_item_client_gets_mission_request_and_degrees(make_server, make_gcs):
    srv = make_server()
    gcs = make_gcs(srv)
    items = [M.MAVLink_mission_item_message(1, 1, i, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_CMD_NAV_WAYPOINT, 0, 1,
                                            0, 0, 0, 0, LAT + i * 1e-4, LON, 10.0 + i, 0) for i in range(3)]
    requests, ack = _upload(gcs, items)
    assert ack.type == M.MAV_MISSION_ACCEPTED
    # the first request is MISSION_REQUEST_INT; after a MISSION_ITEM the vehicle asks as the client speaks
    assert [r.get_type() for r in requests] == ["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_REQUEST"]
    gcs.recv(timeout=0.3, cond=lambda m: False)
    assert any("GCS should send MISSION_ITEM_INT" in t for t in gcs.texts)
    assert srv.sim.missions.get(0, 2).x == pytest.approx((LAT + 2e-4) * 1e7, abs=50)   # float32 degrees
    got = _download(gcs, legacy=True)
    assert got[2].x == pytest.approx(LAT + 2e-4, abs=5e-6) and got[2].y == pytest.approx(LON, abs=5e-6)
    assert got[2].z == pytest.approx(12.0)


def test_fence_and_rally_lists_and_clear_all(make_server, make_gcs):
    srv = make_server()
    gcs = make_gcs(srv)
    fence = [_wp(i, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, dn_m=50.0 * i, mission_type=1,
                 params=(4.0, 0.0, 0.0, 0.0)) for i in range(4)]
    fence.append(_wp(4, M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, mission_type=1, params=(15.0, 0.0, 0.0, 0.0)))
    assert _upload(gcs, fence, 1)[1].type == M.MAV_MISSION_ACCEPTED
    rally = [_wp(0, M.MAV_CMD_NAV_RALLY_POINT, dn_m=100.0, z=15.0, mission_type=2)]
    assert _upload(gcs, rally, 2)[1].type == M.MAV_MISSION_ACCEPTED
    f = _download(gcs, 1)
    assert [m.command for m in f] == [5001] * 4 + [5004] and f[4].param1 == 15.0 and f[1].x == fence[1].x
    r = _download(gcs, 2)
    assert len(r) == 1 and r[0].frame == M.MAV_FRAME_GLOBAL_RELATIVE_ALT and r[0].z == pytest.approx(15.0)
    # the mission is untouched: home only
    gcs.conn.mav.mission_request_list_send(1, 1, 0)
    assert gcs.recv("MISSION_COUNT").count == 1
    gcs.conn.mav.mission_clear_all_send(1, 1, 1)
    ack = gcs.recv("MISSION_ACK")
    assert ack.type == M.MAV_MISSION_ACCEPTED and ack.mission_type == 1
    assert srv.sim.missions.count(1) == 0 and srv.sim.missions.count(2) == 1
    gcs.conn.mav.mission_clear_all_send(1, 1, M.MAV_MISSION_TYPE_ALL)
    assert gcs.recv("MISSION_ACK").type == M.MAV_MISSION_ACCEPTED and srv.sim.missions.count(2) == 0


@pytest.mark.parametrize(("item", "mission_type", "error"), [
    (_wp(0, 12345), 0, M.MAV_MISSION_UNSUPPORTED),
    (_wp(0, params=(math.nan, 0.0, 0.0, 0.0)), 0, M.MAV_MISSION_INVALID_PARAM1),
    (_wp(0, params=(0.0, math.inf, 0.0, 0.0)), 0, M.MAV_MISSION_INVALID_PARAM2),
    (_wp(0, frame=M.MAV_FRAME_LOCAL_NED), 0, M.MAV_MISSION_UNSUPPORTED_FRAME),
    (_wp(0, z=math.nan), 0, M.MAV_MISSION_INVALID_PARAM7),
    (_wp(0, M.MAV_CMD_DO_JUMP, frame=M.MAV_FRAME_MISSION, params=(0.0, 1.0, 0.0, 0.0)), 0, M.MAV_MISSION_ERROR),
    (_wp(0, M.MAV_CMD_NAV_WAYPOINT, mission_type=1), 1, M.MAV_MISSION_UNSUPPORTED),
    (_wp(0, M.MAV_CMD_NAV_FENCE_RETURN_POINT, frame=M.MAV_FRAME_MISSION, mission_type=1), 1,
     M.MAV_MISSION_UNSUPPORTED_FRAME),
    (_wp(0, M.MAV_CMD_NAV_WAYPOINT, mission_type=2), 2, M.MAV_MISSION_UNSUPPORTED),
])
def test_invalid_items_end_the_upload_with_ardupilots_error(make_server, make_gcs, item, mission_type, error):
    srv = make_server()
    gcs = make_gcs(srv)
    gcs.conn.mav.mission_count_send(1, 1, 1, mission_type)
    assert gcs.recv("MISSION_REQUEST_INT").seq == 0
    gcs.conn.mav.send(item)
    ack = gcs.recv("MISSION_ACK")
    assert ack.type == error and ack.mission_type == mission_type
    assert not srv.dispatcher.mission.receiving(mission_type)
    assert srv.sim.missions.count(mission_type) == 0


def test_wrong_sequence_is_refused_and_the_transfer_goes_on(make_server, make_gcs):
    srv = make_server()
    gcs = make_gcs(srv)
    gcs.conn.mav.mission_count_send(1, 1, 2, 0)
    assert gcs.recv("MISSION_REQUEST_INT").seq == 0
    gcs.conn.mav.send(_wp(1))
    assert gcs.recv("MISSION_ACK").type == M.MAV_MISSION_INVALID_SEQUENCE
    gcs.conn.mav.send(_wp(0))
    assert gcs.recv("MISSION_REQUEST_INT").seq == 1
    # a download during an upload is DENIED
    gcs.conn.mav.mission_request_list_send(1, 1, 0)
    assert gcs.recv("MISSION_ACK").type == M.MAV_MISSION_DENIED
    gcs.conn.mav.send(_wp(1))
    assert gcs.recv("MISSION_ACK").type == M.MAV_MISSION_ACCEPTED
    # an item without an upload: ERROR
    gcs.conn.mav.send(_wp(1))
    assert gcs.recv("MISSION_ACK").type == M.MAV_MISSION_ERROR
    # an empty upload clears
    gcs.conn.mav.mission_count_send(1, 1, 0, 0)
    assert gcs.recv("MISSION_ACK").type == M.MAV_MISSION_ACCEPTED and srv.sim.missions.count(0) == 0


def test_pending_request_is_repeated_after_a_second(make_server, make_gcs):
    srv = make_server()
    gcs = make_gcs(srv)
    gcs.conn.mav.mission_count_send(1, 1, 3, 0)
    first = gcs.recv("MISSION_REQUEST_INT")
    again = gcs.recv("MISSION_REQUEST_INT", timeout=10.0)
    assert first.seq == again.seq == 0
    gcs.conn.mav.mission_clear_all_send(1, 1, 0)   # same client: cancels its own upload
    assert gcs.recv("MISSION_ACK").type == M.MAV_MISSION_ACCEPTED
    assert not srv.dispatcher.mission.receiving(0)


def test_set_current_mission_current_and_item_reached(make_server, make_gcs):
    srv = make_server()
    gcs = make_gcs(srv)
    assert _upload(gcs, MISSION)[1].type == M.MAV_MISSION_ACCEPTED
    gcs.conn.mav.mission_set_current_send(1, 1, 3)
    cur = gcs.recv("MISSION_CURRENT")
    assert cur.seq == 3 and cur.total == len(MISSION) - 1 and cur.mission_state == M.MISSION_STATE_NOT_STARTED
    assert srv.sim.missions.current_seq == 3
    assert gcs.command(M.MAV_CMD_DO_SET_MISSION_CURRENT, 2).result == M.MAV_RESULT_ACCEPTED
    assert gcs.recv("MISSION_CURRENT", cond=lambda m: m.seq == 2) is not None     # sent on change
    assert gcs.command(M.MAV_CMD_DO_SET_MISSION_CURRENT, 40).result == M.MAV_RESULT_FAILED
    # streamed with EXTENDED_STATUS
    gcs.conn.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_EXTENDED_STATUS, 50, 1)
    gcs.start_lockstep_streams()
    gcs.step(thrust=0.0)
    for _ in range(30):
        gcs.step(thrust=0.0)
    assert any(m.seq == 2 for m in gcs.log.get("MISSION_CURRENT", []))
    # AUTO reached items -> MISSION_ITEM_REACHED
    with srv.lock:
        srv.sim.missions.reached.extend([1, 2])
    for _ in range(3):
        gcs.step(thrust=0.0)
    assert [m.seq for m in gcs.log["MISSION_ITEM_REACHED"]] == [1, 2] and srv.sim.missions.reached == []


def test_partial_write_replaces_a_range(make_server, make_gcs):
    srv = make_server()
    gcs = make_gcs(srv)
    assert _upload(gcs, MISSION)[1].type == M.MAV_MISSION_ACCEPTED
    gcs.conn.mav.mission_write_partial_list_send(1, 1, 2, 2, 0)
    assert gcs.recv("MISSION_REQUEST_INT").seq == 2
    gcs.conn.mav.send(_wp(2, dn_m=99.0, z=33.0))
    assert gcs.recv("MISSION_ACK").type == M.MAV_MISSION_ACCEPTED
    assert srv.sim.missions.count(0) == len(MISSION) and srv.sim.missions.get(0, 2).z == 33.0
    assert srv.sim.missions.get(0, 4).command == M.MAV_CMD_NAV_SPLINE_WAYPOINT
    gcs.conn.mav.mission_write_partial_list_send(1, 1, 5, 2, 0)
    assert gcs.recv("MISSION_ACK").type == M.MAV_MISSION_ERROR


# ---------------------------------------------------------------------- the state machine, clocked by hand
def _from(msg, sysid: int = 255, compid: int = 190):
    """``msg`` as received from system ``sysid`` (packed and parsed, so that its header says so)."""
    mav = M.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    return mav.parse_char(msg.pack(mav))


@pytest.fixture
def proto():
    sim = Simulation(load_vehicle(None))
    return MissionProtocol(sim, lambda: 1)


def test_upload_timeout_cancels_and_keeps_what_arrived(proto):
    out: list = []
    proto.handle(_from(M.MAVLink_mission_count_message(1, 1, 3, 0)), "link-a", 0, out)
    proto.handle(_from(_wp(0)), "link-a", 10, out)
    proto.handle(_from(_wp(1, z=7.0)), "link-a", 20, out)
    assert [m.seq for m in out if m.get_type() == "MISSION_REQUEST_INT"] == [0, 1, 2]
    proto.poll(20 + REREQUEST_NS // 2)
    assert proto.outbox == []
    proto.poll(20 + REREQUEST_NS + 1)
    assert [(k, m.get_type(), m.seq) for k, m in proto.outbox] == [("link-a", "MISSION_REQUEST_INT", 2)]
    proto.outbox.clear()
    proto.poll(20 + UPLOAD_TIMEOUT_NS + 1)
    (key, ack), = proto.outbox
    assert key == "link-a" and ack.type == M.MAV_MISSION_OPERATION_CANCELLED and ack.target_system == 255
    assert not proto.receiving(0)
    assert any("Mission upload timeout" in t for _s, t in proto.sim.autopilot.events)
    # as ArduPilot (which writes items as they come): the mission holds the two that arrived
    assert proto.sim.missions.count(0) == 2 and proto.sim.missions.get(0, 1).z == 7.0


def test_another_client_is_denied_while_one_uploads(proto):
    out: list = []
    proto.handle(_from(M.MAVLink_mission_count_message(1, 1, 2, 1)), "a", 0, out)
    out.clear()
    proto.handle(_from(M.MAVLink_mission_count_message(1, 1, 5, 1), sysid=254), "b", 1, out)
    assert out[0].get_type() == "MISSION_ACK" and out[0].type == M.MAV_MISSION_DENIED and out[0].target_system == 254
    out.clear()
    proto.handle(_from(_wp(0, M.MAV_CMD_NAV_FENCE_RETURN_POINT, mission_type=1), sysid=254), "b", 2, out)
    assert out[0].type == M.MAV_MISSION_DENIED
    out.clear()
    proto.handle(_from(M.MAVLink_mission_count_message(1, 1, 9999, 0)), "a", 3, out)
    assert out[0].type == M.MAV_MISSION_NO_SPACE
    out.clear()
    proto.handle(_from(M.MAVLink_mission_request_list_message(1, 1, 7)), "a", 3, out)
    assert out[0].type == M.MAV_MISSION_UNSUPPORTED
    # the fence upload in progress is untouched: a fence is stored only when complete
    assert proto.receiving(1) and proto.sim.missions.count(1) == 0
