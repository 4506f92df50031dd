"""Vehicle files, ArduPilot parameters, battery, sensors, wind."""

from __future__ import annotations

import math
import statistics
import textwrap
from itertools import pairwise

import numpy as np
import pytest

from quadrotor.errors import ConfigError
from quadrotor.frames import Kinematics
from sitl.copter import battery as batt
from sitl.copter.params import ParamStore, ardupilot_params
from sitl.copter.sensors import NedSensors
from sitl.copter.vehicle import BatteryParams
from sitl.copter.vehicle_file import bundled_vehicles, load_vehicle, parse_vehicle

MINIMAL = {"vehicle": {"mass_kg": 1.0, "inertia_kg_m2": [0.01, 0.01, 0.02]},
           "rotors": {"arm_length_m": 0.2, "max_thrust_n": 6.0}}


def with_(section, key, value):
    d = {k: dict(v) for k, v in MINIMAL.items()}
    d.setdefault(section, {})[key] = value
    return d


def test_bundled_vehicles_load():
    assert {"quad-1kg", "talon-550"} <= set(bundled_vehicles())
    v = load_vehicle()
    assert v.name == "quad-1kg" and v.mass_kg == 1.0 and v.max_total_thrust_n == pytest.approx(24.5)
    assert v.hover_thrust_fraction == pytest.approx(9.81 / 24.5)
    L, T, k = v.rotors.arm_length_m, v.rotors.max_thrust_n, v.rotors.yaw_moment_m
    assert v.max_torque_nm == pytest.approx((math.sqrt(2) * L * T, math.sqrt(2) * L * T, 2 * k * T))
    t = load_vehicle("talon-550")
    assert t.rotors.arm_length_m == pytest.approx(0.275) and t.battery.cells == 4
    assert load_vehicle("talon-550.toml") == t


def test_load_by_path(tmp_path):
    p = tmp_path / "v.toml"
    p.write_text(textwrap.dedent("""
        [vehicle]
        mass_kg = 1.2
        inertia_kg_m2 = [[0.01, 0.001, 0.0], [0.001, 0.01, 0.0], [0.0, 0.0, 0.02]]
        [rotors]
        arm_length_m = 0.2
        max_thrust_n = 7.0
    """))
    v = load_vehicle(p)
    assert v.mass_kg == 1.2 and v.inertia_kg_m2[0][1] == 0.001 and v.source == str(p)


@pytest.mark.parametrize("data, key, words", [
    (with_("vehicle", "colour", "red"), "vehicle.colour", "unknown key"),
    ({**MINIMAL, "motors": {}}, "motors", "unknown section"),
    (with_("rotors", "max_thrust_n", -1.0), "rotors.max_thrust_n", "> 0"),
    (with_("rotors", "max_thrust_n", "6"), "rotors.max_thrust_n", "number"),
    (with_("rotors", "max_thrust_n", True), "rotors.max_thrust_n", "number"),
    (with_("battery", "cells", 2.5), "battery.cells", "integer"),
    (with_("battery", "initial_charge", 1.5), "battery.initial_charge", "[0, 1]"),
    (with_("sensors", "rangefinder", 1), "sensors.rangefinder", "true or false"),
    (with_("control", "rate_p_1_s", [1, 2]), "control.rate_p_1_s", "3 numbers"),
    (with_("vehicle", "model", "quadratic"), "vehicle.model", "rigid_body"),
    (with_("vehicle", "inertia_kg_m2", [[0.01, 0.002, 0], [0.001, 0.01, 0], [0, 0, 0.02]]),
     "vehicle.inertia_kg_m2", "not symmetric"),
    (with_("vehicle", "inertia_kg_m2", [0.01, -0.01, 0.02]), "vehicle.inertia_kg_m2", "positive definite"),
    (with_("vehicle", "mass_kg", 10.0), "rotors.max_thrust_n", "cannot lift"),
    ({"vehicle": {"mass_kg": 1.0}, "rotors": MINIMAL["rotors"]}, "vehicle.inertia_kg_m2", "missing"),
    (with_("home", "lat_deg", 100.0), "home.lat_deg", "[-90, 90]"),
])
def test_invalid_vehicles_name_the_key(data, key, words):
    with pytest.raises(ConfigError) as e:
        parse_vehicle(data, "x.toml")
    assert e.value.key == key and words in str(e.value) and str(e.value).startswith(f"x.toml: {key}: ")


def test_unknown_vehicle_and_bad_toml(tmp_path):
    with pytest.raises(ConfigError, match=r"bundled: .*quad-1kg"):
        load_vehicle("no-such-vehicle")
    p = tmp_path / "bad.toml"
    p.write_text("[vehicle\n")
    with pytest.raises(ConfigError, match="invalid TOML"):
        load_vehicle(p)


def test_ardupilot_parameter_defaults_and_rules():
    v = load_vehicle()
    ps = ParamStore(ardupilot_params(v))
    assert ps["GUID_OPTIONS"] == 0 and ps["GUID_TIMEOUT"] == 3.0 and ps["DISARM_DELAY"] == 10
    assert ps["MOT_THST_HOVER"] == pytest.approx(v.hover_thrust_fraction, abs=1e-4)
    assert ps["WP_SPD_UP"] == 2.5 and ps["WP_SPD_DN"] == 1.5 and ps["SYSID_THISMAV"] == 1
    seen = []
    ps.add_listener(lambda n, val: seen.append((n, val)))
    assert ps.set("GUID_OPTIONS", 8.4) == (True, "")
    assert ps["GUID_OPTIONS"] == 8.0 and seen == [("GUID_OPTIONS", 8.0)]   # integer type rounds
    ok, reason = ps.set("GUID_TIMEOUT", 50.0)
    assert not ok and "outside" in reason and ps["GUID_TIMEOUT"] == 3.0
    assert ps.set("FRAME_CLASS", 2) == (False, "read-only")
    assert ps.set("NOPE", 1)[0] is False
    assert ps.set("GUID_TIMEOUT", float("nan"))[0] is False
    names = list(ps)
    assert len(names) == len(set(names)) == len(ps) and all(len(n) <= 16 for n in names)
    with pytest.raises(ValueError, match="unknown"):
        ParamStore(ardupilot_params(v), {"NOPE": 1})


def test_battery_model():
    v = load_vehicle()
    bp = v.battery
    ocv = [batt.open_circuit_voltage(c / 100, bp) for c in range(101)]
    assert all(b >= a for a, b in pairwise(ocv)) and ocv[-1] == pytest.approx(12.6) and ocv[0] > 9.0
    hover = v.mass_kg * v.gravity_m_s2 / 4
    power = batt.rotor_power_w([hover] * 4, v.rotors)
    assert 60.0 < power < 150.0           # about 100 W/kg for a 1 kg quad
    s = batt.initial_battery(bp)
    for _ in range(600):
        s = batt.step(s, power, 0.1, bp)   # one minute of hover
    current = power / s.voltage_v + bp.avionics_current_a
    assert s.current_a == pytest.approx(current, rel=0.01)
    assert s.consumed_mah == pytest.approx(s.current_a * 60 / 3.6, rel=0.02)
    assert s.voltage_v < batt.open_circuit_voltage(s.charge, bp)          # sag under load
    assert s.charge == pytest.approx(1 - s.consumed_mah / bp.capacity_mah)
    assert s.consumed_wh == pytest.approx(s.voltage_v * s.current_a / 60, rel=0.02)
    empty = batt.step(batt.BatteryState(0.0, 9.0), 1e6, 0.1, BatteryParams())
    assert math.isfinite(empty.voltage_v) and empty.charge == 0.0


def test_sensors_noise_and_baro_resolution():
    v = load_vehicle()
    k = Kinematics(1.0, 2.0, -3.04, 0.5, 0.0, -0.2, 1.0, 0.0, 0.0, 0.0, 0.1, 0.0, 0.0)
    s = NedSensors(v.sensors, np.random.default_rng([7, 2]))
    navs = [s.nav(k) for _ in range(2000)]
    imus = [s.imu(k) for _ in range(2000)]
    assert all(abs(n.baro_alt_m / 0.1 - round(n.baro_alt_m / 0.1)) < 1e-9 for n in navs)
    assert statistics.mean(n.baro_alt_m for n in navs) == pytest.approx(3.04, abs=0.01)
    assert statistics.stdev(n.n for n in navs) == pytest.approx(v.sensors.position_noise_std_m, rel=0.1)
    assert statistics.stdev(i.p for i in imus) == pytest.approx(v.sensors.rate_noise_std_rad_s, rel=0.1)
    assert statistics.stdev(i.roll for i in imus) == pytest.approx(v.sensors.attitude_noise_std_rad, rel=0.1)
    a = NedSensors(v.sensors, np.random.default_rng([7, 2]))
    assert [a.nav(k) for _ in range(5)] == navs[:5]   # same seed, same readings


def test_rangefinder_when_fitted():
    v = load_vehicle()
    sp = v.sensors.__class__(rangefinder=True, rangefinder_noise_std_m=0.0, rangefinder_max_m=4.0)
    s = NedSensors(sp, np.random.default_rng(1))
    k = Kinematics(0, 0, -1.0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0)
    assert s.nav(k).range_m == pytest.approx(1.0)
    assert s.nav(k._replace(d=-10.0)).range_m == -1.0
    assert NedSensors(v.sensors, np.random.default_rng(1)).nav(k).range_m == -1.0
