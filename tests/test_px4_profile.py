"""PX4 pieces without the firmware: modes, bytewise parameters, EVENT decoding, the profile's choices."""

from __future__ import annotations

import struct
from collections import deque
from types import SimpleNamespace

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs.errors import PreflightRefused
from gcs.link.guard import GuardLimits, OutputGuard
from gcs.link.param_encoding import ParamEncodingError, decode_param, encode_param
from gcs.vehicles.ardupilot import ArduPilotProfile
from gcs.vehicles.autopilots import profile_for
from gcs.vehicles.firmware import Firmware
from gcs.vehicles.px4 import OBL_LAND, OFFBOARD_LOSS_S, Px4Profile
from gcs.vehicles.profile import velocity_var_m2_s2
from gcs.vehicles.px4_events import EventMetadata, parse_event
from gcs.vehicles.px4_modes import HOLD, LAND, OFFBOARD, px4_mode_name
from quadrotor.mavlink.framing import restore_unknown_header


def test_px4_custom_modes_and_names():
    assert OFFBOARD == 6 << 16 == 393216
    assert HOLD == 50593792  # the raw number PX4 reports while in Hold
    assert LAND == (4 << 16) | (6 << 24)
    assert [px4_mode_name(m) for m in (OFFBOARD, HOLD, LAND)] == ["Offboard", "Hold", "Land"]
    assert px4_mode_name(-1) == "unknown"
    assert px4_mode_name(4 << 16 | 77 << 24) == "AUTO.77"


@pytest.mark.parametrize("value", [0, 1, 4, 10, 255, -1, -3, 2**31 - 1, -2**31])
def test_int32_parameters_round_trip_bytewise(value):
    wire = encode_param(value, mavlink.MAV_PARAM_TYPE_INT32, True)
    assert struct.pack("<f", wire) == struct.pack("<i", value)
    assert decode_param(wire, mavlink.MAV_PARAM_TYPE_INT32, True) == value


def test_c_cast_and_real32_parameters_are_the_float_itself():
    assert encode_param(4, mavlink.MAV_PARAM_TYPE_INT32, False) == 4.0
    assert decode_param(0.5, mavlink.MAV_PARAM_TYPE_REAL32, True) == 0.5
    # what PX4 sent for COM_DL_LOSS_T = 10 in its PARAM_VALUE
    assert decode_param(1.401298464324817e-44, mavlink.MAV_PARAM_TYPE_INT32, True) == 10.0


def test_integer_parameters_refuse_values_their_type_cannot_hold():
    with pytest.raises(ParamEncodingError):
        encode_param(2.5, mavlink.MAV_PARAM_TYPE_INT32, True)
    with pytest.raises(ParamEncodingError):
        encode_param(300, mavlink.MAV_PARAM_TYPE_UINT8, True)


def test_the_guard_passes_a_negative_bytewise_integer_but_not_a_nan_float():
    guard = OutputGuard(GuardLimits(max_body_rate_rad_s=35.0))
    mav = mavlink.MAVLink(None)
    nan_int = encode_param(-1, mavlink.MAV_PARAM_TYPE_INT32, True)
    assert guard.check(mav.param_set_encode(1, 1, b"X", nan_int, mavlink.MAV_PARAM_TYPE_INT32)) is None
    assert guard.check(mav.param_set_encode(1, 1, b"X", float("nan"), mavlink.MAV_PARAM_TYPE_REAL32)) is not None


def _event_frame(event_id: int, args: bytes = b"") -> object:
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    payload = struct.pack("<IIHBBB", event_id, 1234, 7, 0, 0, 6) + args
    payload = payload.rstrip(b"\0") or b"\0"
    header = struct.pack("<BBBBBBBHB", 0xFD, len(payload), 0, 0, 0, 1, 1, 410 & 0xFFFF, 0)
    frame = header + payload + b"\0\0"
    msg = mavlink.MAVLink_unknown(410, bytearray(frame))
    del mav
    return msg


def test_event_frames_get_their_header_and_decode_with_metadata():
    msg = _event_frame((1 << 24) | 3087815, bytes([3, 2]))
    restore_unknown_header(msg)
    assert (msg.get_srcSystem(), msg.get_srcComponent()) == (1, 1)
    ev = parse_event(msg)
    assert ev is not None and ev.component == 1 and ev.sub_id == 3087815 and ev.sequence == 7
    meta = EventMetadata({"components": {"1": {"event_groups": {"arming_check": {"events": {
        "3087815": {"message": "No offboard signal <param>COM_OF_LOSS_T</param> {2}",
                    "arguments": [{"name": "modes", "type": "uint8_t"}, {"name": "i", "type": "uint8_t"}]}}}}}}})
    assert meta.describe(ev) == "No offboard signal COM_OF_LOSS_T 2"
    assert "not in" in meta.describe(parse_event(_event_frame(99)))


def test_enum_and_bitfield_arguments_are_put_in_words():
    enums = {"arm_disarm_reason_t": {"type": "uint8_t", "entries": {"6": {"description": "landing"}}},
             "group_t": {"type": "uint32_t", "is_bitfield": True,
                         "entries": {"1": {"description": "Manual"}, "4": {"description": "Offboard"}}}}
    meta = EventMetadata({"components": {"0": {"enums": enums}, "1": {"event_groups": {"c": {"events": {
        "9": {"message": "Disarmed by {1} ({2})",
              "arguments": [{"name": "r", "type": "arm_disarm_reason_t"}, {"name": "g", "type": "group_t"}]},
        "10": {"message": "Disarmed by {1}", "arguments": [{"name": "r", "type": "arm_disarm_reason_t"}]}}}}}}})
    ev = parse_event(_event_frame((1 << 24) | 9, bytes([6]) + struct.pack("<I", 5)))
    assert meta.describe(ev) == "Disarmed by landing (Manual, Offboard)"
    assert meta.describe(parse_event(_event_frame((1 << 24) | 10, bytes([77])))) == "Disarmed by 77"  # not listed


def _status(**kw):
    base = dict(armed=True, custom_mode=OFFBOARD, statustext=deque(), events=deque())
    base.update(kw)
    return SimpleNamespace(**base)


def test_arming_refusal_says_the_event_or_that_it_came_as_one():
    ev = parse_event(_event_frame((1 << 24) | 5))
    st = _status(statustext=deque(["Arming denied: Resolve system health failures first"]), events=deque([ev]))
    assert "came as PX4 event" in Px4Profile().arming_refusal(st, 1)
    meta = EventMetadata({"components": {"1": {"event_groups": {"d": {"events": {"5": {"message": "No GPS"}}}}}}})
    assert Px4Profile(meta).arming_refusal(st, 1) == "No GPS"
    assert Px4Profile().arming_refusal(_status(statustext=deque(["Arming denied: x"])), 1) == "Arming denied: x"


def test_control_lost_and_families():
    p = Px4Profile()
    assert p.control_lost(_status()) is None
    assert p.control_lost(_status(custom_mode=HOLD)) == "mode Hold"
    assert p.control_lost(_status(armed=False)) == "disarmed"
    assert HOLD in p.hover_modes and p.stream_before_mode
    assert isinstance(profile_for(3), ArduPilotProfile) and isinstance(profile_for(12), Px4Profile)
    with pytest.raises(PreflightRefused, match="neither ArduPilot"):
        profile_for(8)
    assert Firmware(12).params_bytewise() and not Firmware(3).params_bytewise()
    assert Firmware(3, None, 16).params_bytewise()


class _Params:
    """VehicleParams' interface over a dict (what a PX4 holds)."""

    def __init__(self, values):
        self.values = dict(values)
        self.changed = {}
        self.said_lines = []
        self.link = SimpleNamespace(param_get=self._get)
        self.on_message = None

    def _get(self, name, **kw):
        from gcs.link.mavlink import LinkError
        if name not in self.values:
            raise LinkError(name)
        return self.values[name]

    def check_interrupt(self):
        pass

    def get(self, name, default):
        if name not in self.values:
            if default is None:
                raise PreflightRefused(name)
            return default
        return self.values[name]

    def set(self, name, value, old):
        self.changed.setdefault(name, old)
        self.values[name] = value
        return value

    def said(self, text):
        self.said_lines.append(text)

    def event(self, kind, text):
        pass


def test_configure_sets_the_offboard_loss_failsafe_and_reads_the_adapters_values():
    params = _Params({"COM_OBL_RC_ACT": 0, "COM_OF_LOSS_T": 1.0, "COM_DISARM_LAND": 2.0, "MPC_THR_HOVER": 0.5,
                      "MC_ROLL_P": 4.0, "MC_PITCH_P": 4.0, "MC_YAW_P": 2.8, "MC_ROLLRATE_MAX": 220.0,
                      "MC_PITCHRATE_MAX": 220.0, "MC_YAWRATE_MAX": 200.0})
    out = Px4Profile().configure(params, Firmware(12, (1, 16, 0), 0xE8FF), "attitude")
    assert params.values["COM_OBL_RC_ACT"] == OBL_LAND and params.values["COM_OF_LOSS_T"] == OFFBOARD_LOSS_S
    assert params.changed == {"COM_OBL_RC_ACT": 0, "COM_OF_LOSS_T": 1.0}
    assert out.hover_throttle == 0.5 and out.angle_gain_1_s == (4.0, 4.0, 2.8)
    assert out.angle_accel_limit_rad_s2 == (0.0, 0.0, 0.0) and out.output == "attitude"
    with pytest.raises(PreflightRefused, match="SET_ACTUATOR_CONTROL_TARGET"):
        Px4Profile().configure(params, Firmware(12, (1, 16, 0), 0xE8FF), "actuator")
    with pytest.raises(PreflightRefused, match="MPC_THR_HOVER"):
        Px4Profile().configure(_Params(dict(params.values, MPC_THR_HOVER=0.0)), None, "attitude")


def test_the_setpoint_loss_in_effect_is_the_lower_com_of_loss_t():
    base = {"COM_OBL_RC_ACT": 4, "COM_DISARM_LAND": 2.0, "MPC_THR_HOVER": 0.5}
    p = Px4Profile()
    assert p.setpoint_loss_s is None  # not configured yet: no rule
    p.configure(_Params(dict(base, COM_OF_LOSS_T=1.0)), None)
    assert p.setpoint_loss_s == OFFBOARD_LOSS_S
    p.configure(_Params(dict(base, COM_OF_LOSS_T=0.2)), None)  # a lower one is left alone and is what counts
    assert p.setpoint_loss_s == pytest.approx(0.2)
    assert ArduPilotProfile.setpoint_loss_s is None  # GUIDED keeps its mode through a gap


def test_a_gap_in_our_setpoints_beyond_px4s_loss_time_is_control_lost():
    """A stalled ground station (SIGSTOP 2 s, measured on PX4 SITL) can miss the HEARTBEATs of PX4's
    Land (an overflowing socket) and PX4 hands offboard back to the next setpoint: the gap itself
    ends the flight as the vehicle's."""
    from gcs.vehicles.mavlink import MavlinkSession

    profile = Px4Profile()
    profile.setpoint_loss_s = 0.5
    status = SimpleNamespace(time_boot_ms=0)  # the vehicle's clock, from its telemetry
    s = SimpleNamespace(profile=profile, _last_setpoint_ms=None, telemetry=SimpleNamespace(status=status))
    gap = MavlinkSession._setpoint_gap
    assert gap(s) is None  # no setpoint sent yet
    s._last_setpoint_ms = 1_000
    status.time_boot_ms = 2_090  # past COM_OF_LOSS_T but within the vehicle's reaction: the HEARTBEATs decide
    assert gap(s) is None
    status.time_boot_ms = 3_050
    said = gap(s)
    assert said is not None and "2.05 s" in said and "COM_OF_LOSS_T = 0.5 s" in said and "PX4" in said
    s.profile = ArduPilotProfile()
    assert gap(s) is None


def test_the_drag_of_a_vehicle_px4_simulates_itself_comes_from_sih():
    base = {"COM_OBL_RC_ACT": 4, "COM_OF_LOSS_T": 0.5, "COM_DISARM_LAND": 2.0, "MPC_THR_HOVER": 0.5}
    assert Px4Profile().configure(_Params(base), None).drag_1_s is None  # a real vehicle: the config's
    sitl = dict(base, SENS_EN_GPSSIM=1, SYS_HITL=0)  # PX4 SITL's sihsim airframes
    sih = _Params(dict(sitl, SIH_KDV=1.0, SIH_MASS=2.0))
    assert Px4Profile().configure(sih, None).drag_1_s == pytest.approx(0.5)
    assert any("SIH_KDV" in t for t in sih.said_lines)
    assert Px4Profile().configure(_Params(dict(sitl, SIH_KDV=1.0, SIH_MASS=0.0)), None).drag_1_s is None


@pytest.mark.parametrize(("extra", "simulated"), [
    ({"SENS_EN_GPSSIM": 1, "SYS_HITL": 0}, True),   # SITL with SIH
    ({"SENS_EN_GPSSIM": 0, "SYS_HITL": 2}, True),   # SIH on a flight controller
    ({"SYS_HITL": 2}, True),                        # ... whose firmware has no simulated-GPS parameter
    ({"SENS_EN_GPSSIM": 0, "SYS_HITL": 0}, False),  # a real Pixhawk with the SIH module built in
    ({"SYS_HITL": 1}, False),                       # HITL with an external simulator: SIH does not run
])
def test_only_a_running_sih_counts_as_px4_simulating_its_vehicle(extra, simulated):
    base = {"COM_OBL_RC_ACT": 4, "COM_OF_LOSS_T": 0.5, "COM_DISARM_LAND": 2.0, "MPC_THR_HOVER": 0.5,
            "SIH_KDV": 1.0, "SIH_MASS": 1.0}
    params = _Params(dict(base, **extra))
    assert Px4Profile.simulates_itself(params) is simulated
    out = Px4Profile().configure(params, None)
    assert (out.drag_1_s is not None) is simulated
    assert (out.horizontal_velocity_std_m_s is not None) is simulated


def test_where_sih_simulates_the_vehicle_its_horizontal_velocity_is_taken_from_the_positions():
    base = {"COM_OBL_RC_ACT": 4, "COM_OF_LOSS_T": 0.5, "COM_DISARM_LAND": 2.0, "MPC_THR_HOVER": 0.5}
    config_var = (0.0025, 0.0025, 0.0025)
    real = Px4Profile().configure(_Params(base), None)
    assert real.horizontal_velocity_std_m_s is None
    assert velocity_var_m2_s2(config_var, real) == config_var  # a real vehicle: fused as the config says
    sih = _Params(dict(base, SIH_KDV=1.0, SIH_MASS=1.0, SENS_EN_GPSSIM=1))
    out = Px4Profile().configure(sih, None)
    assert out.horizontal_velocity_std_m_s == Px4Profile.SIH_HORIZONTAL_VELOCITY_STD_M_S
    north, east, down = velocity_var_m2_s2(config_var, out)
    assert north == east == Px4Profile.SIH_HORIZONTAL_VELOCITY_STD_M_S ** 2 >= 1e4 * config_var[0]
    assert down == config_var[2]  # the vertical velocity is still fused
    assert any("velocity from the positions" in t for t in sih.said_lines)
    # kept through the output's own configuration
    assert Px4Profile().configure_output(sih, "attitude", None, out).horizontal_velocity_std_m_s == \
        out.horizontal_velocity_std_m_s


def test_mode_commands_use_px4s_main_and_sub_modes_and_nav_land():
    p = Px4Profile()
    assert p._mode_command(OFFBOARD) == (mavlink.MAV_CMD_DO_SET_MODE, [1.0, 6.0, 0.0])
    cmd, params = p._mode_command(LAND)
    assert cmd == mavlink.MAV_CMD_NAV_LAND and all(v == 0.0 for v in params)
