"""Vehicle faults of the built-in SITL (sitl.copter.faults): options, the [faults] section, the physics,
the vehicle clock and the cannot-hover refusal.  No flight here (tests/sitl/test_sitl_faults_flight.py)."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from quadrotor.errors import ConfigError
from sitl.cli import main
from sitl.copter import rigid_body
from sitl.copter.faults import FaultParams, hover_problem, hover_trim_n
from sitl.copter.rigid_body import RigidBodyModel, initial_state, rotor_wrench
from sitl.copter.server import SitlServer
from sitl.copter.simulation import Simulation
from sitl.copter.telemetry import TelemetryCounters, build
from sitl.copter.telemetry_status import STATUS_BUILDERS
from sitl.copter.vehicle import VehicleParams
from sitl.copter.vehicle_file import load_vehicle, parse_vehicle, with_faults
from sitl.copter.world import ReducedPlant
from sitl.net.udp import UdpTransport

V = load_vehicle("quad-1kg")
D = V.rotors.arm_length_m / math.sqrt(2.0)
K = V.rotors.yaw_moment_m
IXX, IYY, IZZ = V.inertia_diagonal
C = 2.0                                   # a thrust command [N], the same for every motor
DT = 1e-4                                  # one physics step [s]


def faulty(**kw) -> VehicleParams:
    return with_faults(V, FaultParams(**kw))


def cli_error(capsys, args: list[str]) -> str:
    try:
        code = main([*args, "--describe"])
    except SystemExit as e:                # argparse's own errors
        code = e.code
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith("sitl: error: ") and "Traceback" not in err
    return err


# ------------------------------------------------------------------ options
@pytest.mark.parametrize("args, words", [
    (["--motor-scale=0.2,1,1,1"], "--motor-scale: motor 1 must be in [0.3, 1.5], got 0.2"),
    (["--motor-scale=1,1,1,1.6"], "--motor-scale: motor 4 must be in [0.3, 1.5], got 1.6"),
    (["--motor-scale=1,1,1"], "--motor-scale: expected 4 numbers"),
    (["--motor-scale=1,1,1,1,1"], "--motor-scale: expected 4 numbers"),
    (["--motor-scale=a,1,1,1"], "--motor-scale: expected comma-separated numbers"),
    (["--motor-scale=nan,1,1,1"], "--motor-scale: must be finite"),
    (["--com-offset=0,0.2,0"], "--com-offset: y must be in [-0.1, 0.1] m, got 0.2"),
    (["--com-offset=0,0"], "--com-offset: expected 3 numbers"),
    (["--mass-scale=abc"], "--mass-scale: invalid float value"),
    (["--mass-scale=0.4"], "--mass-scale: must be in [0.5, 2]"),
    (["--mass-scale=inf"], "--mass-scale: must be a finite number"),
    (["--inertia-scale=2.5"], "--inertia-scale: must be in [0.5, 2]"),
    (["--clock-rate=1.2"], "--clock-rate: must be in [0.9, 1.1], got 1.2"),
    (["--clock-rate=0.8"], "--clock-rate: must be in [0.9, 1.1], got 0.8"),
    (["--rig", "4dof", "--mass-scale=1.1"], "--mass-scale: not available with --rig"),
])
def test_bad_fault_options_are_refused_naming_the_option(capsys, args, words):
    assert words in cli_error(capsys, args)


@pytest.mark.parametrize("args, words", [
    (["--motor-scale=0.3,1,1,1"], "--motor-scale: cannot hover: motor 1 (scale 0.3) would need 133.5%"),
    (["--mass-scale=2", "--motor-scale=0.8,1,1,1"], "--motor-scale/--mass-scale: cannot hover: motor 1"),
    (["--com-offset=0.1,0.1,0"], "--com-offset: cannot hover: motor 1 (scale 1) would need 90.4%"),
])
def test_a_vehicle_that_cannot_hover_is_refused(capsys, args, words):
    assert words in cli_error(capsys, args)


def test_options_override_the_file_and_describe_shows_them(tmp_path, capsys):
    text = load_text() + "\n[faults]\nmotor_scale = [0.9, 1.0, 1.0, 1.0]\nmass_scale = 1.1\n"
    p = tmp_path / "v.toml"
    p.write_text(text)
    assert main(["--vehicle", str(p), "--mass-scale=1.2", "--clock-rate=0.988", "--describe"]) == 0
    out = capsys.readouterr().out
    assert "faults           motor scale 0.9,1,1,1; CoM offset 0,0,0 m; mass x1.2; inertia x1; clock rate 0.988" in out
    assert "hover thrust     0.4004" in out                  # the autopilot's: nominal
    assert main(["--describe"]) == 0 and "faults" not in capsys.readouterr().out


def load_text() -> str:
    from importlib import resources
    return (resources.files("sitl.vehicles") / "quad-1kg.toml").read_text(encoding="utf-8")


def test_the_ground_station_passes_them_through_sitl_arg():
    """gcs fly --sitl-arg=--motor-scale=... reaches the child's command line as one ``--opt=value``."""
    from gcs.vehicles.embedded import EmbeddedSitl
    ok = EmbeddedSitl(9, lockstep=True, extra_args=["--motor-scale=0.85,1,1,1", "--com-offset=-0.01,0,0"])
    r = subprocess.run([*ok.args, "--describe"], capture_output=True, text=True, timeout=30)
    assert r.returncode == 0 and "motor scale 0.85,1,1,1; CoM offset -0.01,0,0 m" in r.stdout
    bad = EmbeddedSitl(9, lockstep=True, extra_args=["--mass-scale=3"])
    r = subprocess.run([*bad.args, "--describe"], capture_output=True, text=True, timeout=30)
    assert r.returncode == 2 and r.stderr == "sitl: error: --mass-scale: must be in [0.5, 2], got 3\n"
    assert bad.args[:3] == [sys.executable, "-m", "sitl.cli"]


# ------------------------------------------------------------------ [faults] in a vehicle file
def with_section(faults: dict) -> dict:
    import tomllib
    data = tomllib.loads(load_text())
    data["faults"] = faults
    return data


def test_faults_section_loads():
    v = parse_vehicle(with_section({"motor_scale": [0.85, 1, 1, 1], "com_offset_m": [0.01, -0.02, 0.03],
                                    "mass_scale": 1.2, "inertia_scale": 0.8, "clock_rate": 0.988}), "x.toml")
    assert v.faults == FaultParams((0.85, 1.0, 1.0, 1.0), (0.01, -0.02, 0.03), 1.2, 0.8, 0.988)
    assert v.mass_kg == 1.0 and v.hover_thrust_fraction == V.hover_thrust_fraction   # nominal stays
    assert parse_vehicle(with_section({}), "x.toml").faults.nominal
    assert V.faults.nominal


@pytest.mark.parametrize("faults, key, words", [
    ({"motor_scal": [1, 1, 1, 1]}, "faults.motor_scal", "unknown key (known: motor_scale, com_offset_m"),
    ({"motor_scale": [1, 1, 1]}, "faults.motor_scale", "must be a list of 4 numbers (motors 1..4)"),
    ({"motor_scale": [1, 1, 1, 0.1]}, "faults.motor_scale", "allowed [0.3, 1.5]"),
    ({"com_offset_m": [0, 0, 0.5]}, "faults.com_offset_m", "allowed [-0.1, 0.1] m"),
    ({"com_offset_m": 0.01}, "faults.com_offset_m", "must be a list of 3 numbers (x, y, z)"),
    ({"mass_scale": "big"}, "faults.mass_scale", "must be a number"),
    ({"inertia_scale": 3.0}, "faults.inertia_scale", "allowed [0.5, 2]"),
    ({"clock_rate": 1.5}, "faults.clock_rate", "allowed [0.9, 1.1]"),
    ({"motor_scale": [0.4, 1, 1, 1]}, "faults", "cannot hover: motor 1 (scale 0.4)"),
    ({"mass_scale": 2.0, "motor_scale": [1, 1, 0.8, 1]}, "faults", "cannot hover: motor 3"),
])
def test_bad_faults_section_names_the_key(faults, key, words):
    with pytest.raises(ConfigError) as e:
        parse_vehicle(with_section(faults), "x.toml")
    assert e.value.key == key and words in e.value.reason and str(e.value).startswith(f"x.toml: {key}: ")


def test_fault_params_validate_themselves():
    with pytest.raises(ValueError, match=r"faults.motor_scale: must be 4 numbers"):
        FaultParams(motor_scale=(1.0, 1.0))
    with pytest.raises(ValueError, match=r"faults.clock_rate: must be in \[0.9, 1.1\], got 2"):
        FaultParams(clock_rate=2.0)
    with pytest.raises(ValueError, match="finite"):
        FaultParams(mass_scale=math.nan)


# ------------------------------------------------------------------ physics
def airborne(model: RigidBodyModel, cmd: float = C):
    """At rest in the air with each motor already producing its scaled command (no motor transient)."""
    s = model.vehicle.faults.motor_scale
    return initial_state(50.0)._replace(on_ground=False, t1=s[0] * cmd, t2=s[1] * cmd, t3=s[2] * cmd,
                                        t4=s[3] * cmd)


def accelerations(vehicle: VehicleParams, cmd: float = C) -> tuple[float, float, float, float]:
    """(down acceleration [m/s^2], p', q', r' [rad/s^2]) from rest under equal commands ``cmd``."""
    model = RigidBodyModel(vehicle)
    s = rigid_body.step(airborne(model, cmd), (cmd,) * 4, DT, model)
    return s.vd / DT, s.p / DT, s.q / DT, s.r / DT


def test_a_weak_motor_gives_the_expected_asymmetric_wrench():
    v = faulty(motor_scale=(0.8, 1.0, 1.0, 1.0))
    model = RigidBodyModel(v)
    s = rigid_body.step(airborne(model), (C,) * 4, DT, model)
    assert (s.t1, s.t2, s.t3, s.t4) == pytest.approx((0.8 * C, C, C, C))        # produced, not commanded
    f, tx, ty, tz = rotor_wrench((s.t1, s.t2, s.t3, s.t4), v)
    assert (f, tx, ty, tz) == pytest.approx((3.8 * C, 0.2 * D * C, -0.2 * D * C, -0.2 * K * C))
    ad, pd, qd, rd = accelerations(v)
    assert ad == pytest.approx(V.gravity_m_s2 - 3.8 * C / V.mass_kg, rel=1e-9)
    assert (pd, qd, rd) == pytest.approx((0.2 * D * C / IXX, -0.2 * D * C / IYY, -0.2 * K * C / IZZ), rel=1e-9)
    # the nominal vehicle under the same commands: no torque
    assert accelerations(V)[1:] == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)


def test_a_strong_motor_exceeds_the_nominal_full_thrust():
    model = RigidBodyModel(faulty(motor_scale=(1.0, 1.0, 1.5, 1.0)))
    tmax = V.rotors.max_thrust_n
    s = airborne(model, 0.0)
    for _ in range(2000):                                 # 2 s at 1 ms: the motor lag has settled
        s = rigid_body.step(s._replace(p=0.0, q=0.0, r=0.0), (2 * tmax,) * 4, 1e-3, model)
    assert s.t3 == pytest.approx(1.5 * tmax) and s.t1 == pytest.approx(tmax)   # the command clips at T_max


def test_a_centre_of_mass_offset_gives_the_expected_torque():
    cx, cy, cz = 0.02, -0.01, 0.05
    v = faulty(com_offset_m=(cx, cy, cz))
    f = 4 * C
    assert rotor_wrench((C,) * 4, v) == pytest.approx((f, cy * f, -cx * f, 0.0))
    _, pd, qd, rd = accelerations(v)
    # forward CoM: nose down (q' < 0); CoM to the left (cy < 0): roll left (p' < 0); z: no moment
    assert (pd, qd, rd) == pytest.approx((cy * f / IXX, -cx * f / IYY, 0.0), rel=1e-9, abs=1e-12)
    assert accelerations(faulty(com_offset_m=(0.0, 0.0, cz)))[1:] == pytest.approx((0, 0, 0), abs=1e-12)


def test_hover_trim_balances_the_offset_centre_of_mass():
    v = faulty(com_offset_m=(0.03, 0.02, 0.0), motor_scale=(0.9, 1.0, 1.0, 1.1))
    trim = hover_trim_n(v)
    f, tx, ty, tz = rotor_wrench(trim, v)
    assert f == pytest.approx(v.mass_kg * v.gravity_m_s2) and (tx, ty, tz) == pytest.approx((0, 0, 0), abs=1e-12)
    model = RigidBodyModel(v)
    cmd = [t / s for t, s in zip(trim, v.faults.motor_scale, strict=True)]
    s = initial_state(50.0)._replace(on_ground=False, t1=trim[0], t2=trim[1], t3=trim[2], t4=trim[3])
    s = rigid_body.step(s, cmd, DT, model)
    assert (s.vd, s.p, s.q, s.r) == pytest.approx((0, 0, 0, 0), abs=1e-12)   # the trim commands hover


def test_mass_and_inertia_scale_change_the_dynamics():
    ad0, pd0, _, _ = accelerations(faulty(motor_scale=(0.8, 1, 1, 1)))
    ad1, pd1, _, _ = accelerations(faulty(motor_scale=(0.8, 1, 1, 1), mass_scale=1.25, inertia_scale=2.0))
    g = V.gravity_m_s2
    assert ad1 == pytest.approx(g - 3.8 * C / 1.25, rel=1e-9) and ad0 == pytest.approx(g - 3.8 * C, rel=1e-9)
    assert pd1 == pytest.approx(pd0 / 2.0, rel=1e-9)
    model = RigidBodyModel(faulty(mass_scale=1.25, inertia_scale=2.0))
    assert model.mass_kg == pytest.approx(1.25)
    # the nominal hover thrust no longer holds the heavier vehicle
    hover = V.mass_kg * g / 4
    assert accelerations(faulty(mass_scale=1.25), hover)[0] == pytest.approx(g * (1 - 1 / 1.25), rel=1e-9)
    assert accelerations(V, hover)[0] == pytest.approx(0.0, abs=1e-9)


def test_the_reduced_plant_flies_the_faults_too():
    def after(v: VehicleParams, cmd: float):
        plant = ReducedPlant(v, initial_state(50.0)._replace(on_ground=False, t1=cmd, t2=cmd, t3=cmd, t4=cmd))
        for _ in range(100):
            plant.step((cmd,) * 4, 1e-3)
        return plant.kinematics
    hover = V.mass_kg * V.gravity_m_s2 / 4
    assert after(V.with_model("reduced"), hover).vd == pytest.approx(0.0, abs=1e-6)
    heavy = after(faulty(mass_scale=1.25).with_model("reduced"), hover)
    assert heavy.vd == pytest.approx(0.1 * V.gravity_m_s2 * (1 - 1 / 1.25), rel=0.05)
    weak = after(faulty(motor_scale=(0.8, 1, 1, 1)).with_model("reduced"), hover)
    assert weak.vd > 0.0 and weak.p > 0.0 and weak.q < 0.0   # rolls right, pitches down (motor 1 front-right)


def test_hover_problem():
    assert hover_problem(V) is None and hover_problem(faulty(motor_scale=(0.5, 1, 1, 1))) is None
    with pytest.raises(ConfigError, match="cannot hover: the rotors give"):
        with_faults(V, FaultParams(motor_scale=(0.3, 0.3, 0.3, 0.3)))
    with pytest.raises(ConfigError, match="below its minimum thrust"):
        with_faults(load_vehicle("talon-550"), FaultParams(com_offset_m=(0.1, 0.1, 0.0), mass_scale=0.5))


# ------------------------------------------------------------------ the vehicle clock
def test_clock_rate_scales_the_telemetry_stamps_not_the_physics():
    nominal, slow = Simulation(V, seed=4), Simulation(faulty(clock_rate=0.988), seed=4)
    for sim in (nominal, slow):
        for _ in range(4000):                                        # 10 s
            sim.tick()
    assert slow.time_ns == nominal.time_ns == 10_000_000_000
    assert slow.world.kinematics == nominal.world.kinematics         # same physics
    c = TelemetryCounters(boot_unix_us=1_700_000_000_000_000)
    att = build(M.MAVLINK_MSG_ID_ATTITUDE, slow, c)
    assert att.time_boot_ms == 9880 and build(M.MAVLINK_MSG_ID_ATTITUDE, nominal, c).time_boot_ms == 10000
    assert build(M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, slow, c).time_usec == 9_880_000
    assert build(M.MAVLINK_MSG_ID_ALTITUDE, slow, c).time_usec == 9_880_000
    st = STATUS_BUILDERS[M.MAVLINK_MSG_ID_SYSTEM_TIME](slow, c)
    assert st.time_boot_ms == 9880 and st.time_unix_usec == 1_700_000_000_000_000 + 9_880_000


def test_timesync_answers_with_the_vehicle_clock():
    srv = SitlServer(UdpTransport(("127.0.0.1", 0)), lockstep=True, vehicle=faulty(clock_rate=1.05))
    try:
        for _ in range(400):
            srv.sim.tick()
        enc = M.MAVLink(None, srcSystem=255, srcComponent=190)
        msg = M.MAVLink(None).parse_buffer(M.MAVLink_timesync_message(0, 123).pack(enc))[0]
        replies, _ = srv.dispatcher.handle(msg)
        assert [(r.get_type(), r.tc1, r.ts1) for r in replies] == [("TIMESYNC", 1_050_000_000, 123)]
    finally:
        srv.close()
