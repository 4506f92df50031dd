"""ArduPilotProfile.configure: the parameters a flight sets (and VehicleParams restores), what it reads, refusals."""

from __future__ import annotations

import math

import pytest

from gcs.errors import PreflightRefused
from gcs.link.mavlink import LinkError
from gcs.vehicles.ardupilot import FS_GCS_LAND, FS_GCS_TIMEOUT_S, GUID_TIMEOUT_S, ArduPilotProfile
from gcs.vehicles.profile import OutputParams
from gcs.vehicles.firmware import BUILTIN_SITL_MARK, CAP_SET_ACTUATOR_TARGET, CAP_SET_ATTITUDE_TARGET, Firmware
from gcs.vehicles.params import VehicleParams

#: ArduCopter 4.8's defaults (copter.parm) for what the profile reads and sets.
ARDUCOPTER = {"GUID_OPTIONS": 0, "ATC_ANGLE_BOOST": 1, "GUID_TIMEOUT": 3.0, "FS_GCS_ENABLE": 0, "FS_GCS_TIMEOUT": 5.0,
              "MAV_GCS_SYSID": 255, "MOT_THST_HOVER": 0.39, "ATC_ANG_RLL_P": 4.5, "ATC_ANG_PIT_P": 4.5,
              "ATC_ANG_YAW_P": 4.5, "ATC_ACC_R_MAX": 1100.0, "ATC_ACC_P_MAX": 1100.0, "ATC_ACC_Y_MAX": 270.0,
              "ATC_RATE_R_MAX": 0.0, "ATC_RATE_P_MAX": 0.0, "ATC_RATE_Y_MAX": 0.0, "ATC_RATE_FF_ENAB": 1}
ARDUCOPTER_FW = Firmware(3, (4, 8, 0), 0xFBEF & ~CAP_SET_ACTUATOR_TARGET)


class FakeLink:
    """A vehicle's parameters: missing names do not answer; ``refuse`` names keep their value on PARAM_SET."""

    source_system = 255

    def __init__(self, values):
        self.values = {k: float(v) for k, v in values.items()}
        self.refuse: set[str] = set()
        self.sets: list[tuple[str, float]] = []

    def param_get(self, name, timeout_s=3.0, retries=2, on_message=None):
        if name not in self.values:
            raise LinkError(f"no PARAM_VALUE for {name}")
        return self.values[name]

    def param_set(self, name, value, timeout_s=3.0, retries=2, on_message=None):
        self.sets.append((name, value))
        if name not in self.refuse:
            self.values[name] = float(value)
        return self.values[name]


def params_for(values):
    events = []
    link = FakeLink(values)
    return VehicleParams(link, lambda m: None, lambda k, t: events.append((k, t)), lambda: None), link, events


def test_attitude_flight_parameters_are_set_read_and_restored():
    params, link, events = params_for(ARDUCOPTER)
    out = ArduPilotProfile().configure(params, ARDUCOPTER_FW, output="attitude")
    v = link.values
    assert v["GUID_OPTIONS"] == 8 and v["ATC_ANGLE_BOOST"] == 0 and v["ATC_RATE_FF_ENAB"] == 0
    assert v["GUID_TIMEOUT"] == GUID_TIMEOUT_S and v["FS_GCS_ENABLE"] == FS_GCS_LAND
    assert v["FS_GCS_TIMEOUT"] == FS_GCS_TIMEOUT_S and FS_GCS_TIMEOUT_S >= 2.0
    assert out.output == "attitude" and out.hover_throttle == 0.39 and out.angle_gain_1_s == (4.5, 4.5, 4.5)
    assert out.angle_accel_limit_rad_s2 == pytest.approx((math.radians(550), math.radians(550), math.radians(120)))
    assert out.rate_limit_rad_s == (0.0, 0.0, 0.0)
    params.restore(lambda: False)
    assert {k: link.values[k] for k in ARDUCOPTER} == pytest.approx({k: float(x) for k, x in ARDUCOPTER.items()})


def test_rates_needs_the_rate_feed_forward_on():
    params, link, _ = params_for(dict(ARDUCOPTER, ATC_RATE_FF_ENAB=0))
    out = ArduPilotProfile().configure(params, ARDUCOPTER_FW, output="rates")
    assert link.values["ATC_RATE_FF_ENAB"] == 1 and out.output == "rates"
    params, link, _ = params_for(ARDUCOPTER)
    ArduPilotProfile().configure(params, ARDUCOPTER_FW, output="rates")
    assert ("ATC_RATE_FF_ENAB", 1.0) not in link.sets and ("ATC_RATE_FF_ENAB", 0.0) not in link.sets


def test_the_output_can_be_configured_after_the_common_part():
    """configure() without the output (the preflight that does not know it yet), then configure_output()."""
    params, link, _ = params_for(ARDUCOPTER)
    p = ArduPilotProfile()
    out = p.configure(params, ARDUCOPTER_FW)
    assert out.output is None and link.values["ATC_RATE_FF_ENAB"] == 1
    out = p.configure_output(params, "attitude", ARDUCOPTER_FW, out)
    assert out.output == "attitude" and link.values["ATC_RATE_FF_ENAB"] == 0


def test_actuator_is_refused_where_the_firmware_does_not_take_it():
    params, link, _ = params_for(ARDUCOPTER)
    with pytest.raises(PreflightRefused, match="does not take SET_ACTUATOR_CONTROL_TARGET"):
        ArduPilotProfile().configure(params, ARDUCOPTER_FW, output="actuator")
    assert link.sets == []   # refused before anything was set
    params, link, _ = params_for(ARDUCOPTER)
    out = ArduPilotProfile().configure(params, ARDUCOPTER_FW)   # told the output later
    with pytest.raises(PreflightRefused, match="does not take SET_ACTUATOR_CONTROL_TARGET"):
        ArduPilotProfile().configure_output(params, "actuator", ARDUCOPTER_FW, out)
    ours = Firmware(3, (4, 8, 0), CAP_SET_ATTITUDE_TARGET | CAP_SET_ACTUATOR_TARGET, builtin_sitl=True)
    for fw in (ours, Firmware(3), None):   # takes it, or unknown: flown
        params, link, _ = params_for(ARDUCOPTER)
        assert ArduPilotProfile().configure(params, fw, output="actuator").output == "actuator"
        assert link.values["ATC_RATE_FF_ENAB"] == 1


def test_the_builtin_sitl_mark_is_eight_bytes():
    assert len(BUILTIN_SITL_MARK) == 8


def test_a_refused_parameter_refuses_the_flight():
    for name, output in (("ATC_RATE_FF_ENAB", "attitude"), ("GUID_TIMEOUT", "rates"), ("FS_GCS_ENABLE", "rates")):
        params, link, _ = params_for(ARDUCOPTER)
        link.refuse.add(name)
        with pytest.raises(PreflightRefused, match=name):
            ArduPilotProfile().configure(params, ARDUCOPTER_FW, output=output)


def test_missing_failsafe_parameters_are_warned_not_refused():
    values = {k: v for k, v in ARDUCOPTER.items() if k not in ("FS_GCS_ENABLE", "FS_GCS_TIMEOUT", "MAV_GCS_SYSID",
                                                                "GUID_TIMEOUT")}
    params, link, events = params_for(values)
    ArduPilotProfile().configure(params, ARDUCOPTER_FW, output="attitude")
    warnings = " ".join(t for k, t in events if k == "warning")
    assert "FS_GCS_ENABLE" in warnings and "GUID_TIMEOUT" in warnings


def test_a_ground_station_id_that_is_not_ours_leaves_the_failsafe_alone():
    params, link, events = params_for(dict(ARDUCOPTER, MAV_GCS_SYSID=254))
    ArduPilotProfile().configure(params, ARDUCOPTER_FW, output="attitude")
    assert any("MAV_GCS_SYSID is 254" in t for k, t in events if k == "warning")
    assert link.values["FS_GCS_ENABLE"] == 0   # it would land on another station's silence, not ours
    params, link, events = params_for({**{k: v for k, v in ARDUCOPTER.items() if k != "MAV_GCS_SYSID"},
                                       "SYSID_MYGCS": 255})   # before ArduPilot 4.7
    ArduPilotProfile().configure(params, ARDUCOPTER_FW, output="attitude")
    assert not any("MAV_GCS_SYSID" in t for k, t in events if k == "warning")


def test_shorter_timeouts_are_kept():
    params, link, _ = params_for(dict(ARDUCOPTER, GUID_TIMEOUT=0.2, FS_GCS_TIMEOUT=2.0, FS_GCS_ENABLE=5))
    ArduPilotProfile().configure(params, ARDUCOPTER_FW, output="attitude")
    assert link.values["GUID_TIMEOUT"] == 0.2 and link.values["FS_GCS_TIMEOUT"] == 2.0
    assert not [s for s in link.sets if s[0] in ("GUID_TIMEOUT", "FS_GCS_TIMEOUT", "FS_GCS_ENABLE")]


def test_implausible_limits_are_refused():
    params, _, _ = params_for(dict(ARDUCOPTER, ATC_ACC_R_MAX=-5.0))
    with pytest.raises(PreflightRefused, match="ATC_ACC"):
        ArduPilotProfile().configure(params, ARDUCOPTER_FW, output="attitude")


def test_output_params_defaults_are_linear_and_unlimited():
    out = OutputParams(0.4, (4.5, 4.5, 4.5))
    assert out.angle_accel_limit_rad_s2 == (0.0, 0.0, 0.0) and out.rate_limit_rad_s == (0.0, 0.0, 0.0)
    assert out.output is None
