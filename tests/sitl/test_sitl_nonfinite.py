"""NaN and inf in setpoints, commands and parameters: refused, counted, never integrated into the physics."""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sitl.copter.server import SitlServer
from sitl.net.udp import UdpTransport

M = mavlink
ENC = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
PEER = (0, "fuzzer")
NAN, INF = math.nan, math.inf

nasty = st.one_of(st.sampled_from([NAN, INF, -INF, 3.4e38, -3.4e38, 1e20, 0.0, 0.4, 1.0, -1.0]),
                  st.floats(width=32, allow_nan=True, allow_infinity=True))
MASKS = st.sampled_from([0, 0b111, 64, 128, 128 | 0b111, 0b011])
COMMANDS = st.sampled_from([M.MAV_CMD_DO_SET_MODE, M.MAV_CMD_COMPONENT_ARM_DISARM, M.MAV_CMD_SET_MESSAGE_INTERVAL,
                            M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_NAV_LAND])
PARAMS = st.sampled_from([b"GUID_TIMEOUT", b"MOT_THST_HOVER", b"ATC_ANG_RLL_P", b"ATC_RATE_R_MAX", b"WP_SPD_UP",
                          b"ATC_ANGLE_MAX", b"SR0_EXTRA1", b"DISARM_DELAY"])
FIRST_PARAMS = {M.MAV_CMD_DO_SET_MODE: 2, M.MAV_CMD_COMPONENT_ARM_DISARM: 2, M.MAV_CMD_SET_MESSAGE_INTERVAL: 2,
                M.MAV_CMD_GET_MESSAGE_INTERVAL: 1, M.MAV_CMD_REQUEST_MESSAGE: 1}

messages = st.one_of(
    st.builds(M.MAVLink_set_attitude_target_message, st.just(0), st.just(1), st.just(1), MASKS,
              st.lists(nasty, min_size=4, max_size=4), nasty, nasty, nasty, nasty),
    st.builds(M.MAVLink_set_actuator_control_target_message, st.just(0), st.just(0), st.just(1), st.just(1),
              st.lists(nasty, min_size=8, max_size=8)),
    st.builds(M.MAVLink_command_long_message, st.just(1), st.just(1), COMMANDS, st.just(0), *[nasty] * 7),
    st.builds(M.MAVLink_param_set_message, st.just(1), st.just(1), PARAMS, nasty, st.just(9)),
)


def wire(msg):
    """The frame and the message as the vehicle decodes it (float32 on the wire: 1e39 arrives as inf)."""
    frame = msg.pack(ENC)
    ENC.seq = (ENC.seq + 1) & 0xFF
    rx = mavlink.MAVLink(None)
    return frame, rx.parse_buffer(frame)[0]


def uses_non_finite(m) -> bool:
    """Whether the message has a NaN/inf in a field the autopilot would use (what must be refused)."""
    bad = lambda *vs: not all(math.isfinite(v) for v in vs)  # noqa: E731
    kind = m.get_type()
    if kind == "SET_ATTITUDE_TARGET":
        used = [] if m.type_mask & 64 else [m.thrust]
        used += [] if m.type_mask & 128 else list(m.q)
        used += [r for bit, r in zip((1, 2, 4), (m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate))
                 if not m.type_mask & bit]
        return bad(*used)
    if kind == "SET_ACTUATOR_CONTROL_TARGET":
        return bad(*m.controls[:4])
    if kind == "COMMAND_LONG":
        p = (m.param1, m.param2, m.param3, m.param4, m.param5, m.param6, m.param7)
        return bad(*p[:FIRST_PARAMS.get(m.command, 0)])
    return bad(m.param_value)


@pytest.fixture(scope="module")
def flying():
    """A lockstep vehicle driven in the test's thread, GUID_OPTIONS=8 (thrust is throttle)."""
    srv = SitlServer(UdpTransport(("127.0.0.1", 0)), lockstep=True, seed=11, params={"GUID_OPTIONS": 8})
    yield srv
    srv.close()


def send(srv: SitlServer, msg) -> None:
    srv.handle_input([(PEER, wire(msg)[0], True)])


def fly(srv: SitlServer, steps: int, thrust: float = 0.45) -> None:
    for _ in range(steps):
        send(srv, M.MAVLink_set_attitude_target_message(0, 1, 1, 0b111, [1, 0, 0, 0], 0, 0, 0, thrust))


def assert_finite(srv: SitlServer) -> None:
    sim, ap = srv.sim, srv.sim.autopilot
    values = [*sim.world.kinematics, *sim.imu, *sim.nav, ap.throttle, *ap.rate_target, *ap.att_target_q,
              *ap.rate_ctl.integ, ap.climb_ctl.integ, ap.climb_ctl.shaped]
    if ap.target is not None:
        t = ap.target
        values += [*t.q, *t.rates, t.value, *t.torques]
    bad = [v for v in values if not (isinstance(v, (int, float)) and math.isfinite(v))]
    assert not bad, bad
    assert all(math.isfinite(sim.params[n]) for n in sim.params)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(messages)
def test_non_finite_inputs_are_refused_counted_and_never_reach_the_physics(flying, msg):
    srv, ap = flying, flying.sim.autopilot
    if not ap.armed or ap.mode != 20:
        send(srv, M.MAVLink_command_long_message(1, 1, M.MAV_CMD_DO_SET_MODE, 0, 1, 20, 0, 0, 0, 0, 0))
        send(srv, M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 21196, 0, 0, 0, 0, 0))
        fly(srv, 20, 0.6)
    assert ap.armed
    frame, received = wire(msg)
    target_before = ap.target
    params_before = {n: srv.sim.params[n] for n in srv.sim.params}
    c0 = dict(srv.counters.as_dict())
    srv.handle_input([(PEER, frame, True)])
    c = srv.counters.as_dict()
    assert c["handler_errors"] == c0["handler_errors"]
    refused = uses_non_finite(received)
    assert c["non_finite"] - c0["non_finite"] == int(refused)
    if refused:
        if received.get_type() in ("SET_ATTITUDE_TARGET", "SET_ACTUATOR_CONTROL_TARGET"):
            assert ap.target is target_before                    # the previous target stays
        if received.get_type() == "PARAM_SET":
            assert {n: srv.sim.params[n] for n in srv.sim.params} == params_before
    for _ in range(5):                                           # let what was accepted act for 50 ms
        srv.step()
    assert_finite(srv)
    fly(srv, 3)
    assert_finite(srv)
    srv.links.discard()


def test_a_non_finite_command_is_denied(flying):
    """Run standalone too: the module's vehicle may hold any parameter values the fuzz set."""
    d = flying.dispatcher
    count = flying.counters.non_finite
    replies, _ = d.handle(wire(M.MAVLink_command_long_message(1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                                              M.MAVLINK_MSG_ID_ATTITUDE, NAN, 0, 0, 0, 0, 0))[1])
    assert [(r.get_type(), r.result) for r in replies] == [("COMMAND_ACK", M.MAV_RESULT_DENIED)]
    assert flying.counters.non_finite == count + 1
    timeout_s = flying.sim.params["GUID_TIMEOUT"]
    replies, _ = d.handle(wire(M.MAVLink_param_set_message(1, 1, b"GUID_TIMEOUT", INF, 9))[1])
    # as ArduPilot 4.8: PARAM_ERROR VALUE_OUT_OF_RANGE, the value unchanged
    assert [(r.get_type(), r.error) for r in replies] == [("PARAM_ERROR", M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE)]
    assert flying.sim.params["GUID_TIMEOUT"] == timeout_s and flying.counters.non_finite == count + 2
    flying.sim.autopilot.events.clear()
