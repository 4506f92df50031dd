"""Closed-loop flights of the built-in SITL's own autopilot with vehicle faults (sitl.copter.faults): the
autopilot, tuned for the nominal vehicle, holds the faulty one; its motor outputs show the fault."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M
from sitl_testkit import Gcs

from gcs.vehicles.embedded import EmbeddedSitl
from sitl.copter import dispatch_nav as DN
from sitl.copter.faults import FaultParams, hover_trim_n
from sitl.copter.modes import Mode
from sitl.copter.simulation import Simulation
from sitl.copter.telemetry import TelemetryCounters, build
from sitl.copter.vehicle_file import load_vehicle, with_faults

V = load_vehicle()
ALT_M = 5.0


def run(sim: Simulation, seconds: float) -> None:
    for _ in range(int(round(seconds * 400))):
        sim.tick()


def hold(faults: FaultParams, seconds: float = 5.0) -> tuple[Simulation, dict]:
    """GUIDED take-off to 5 m, 8 s to settle, then ``seconds`` of hover: the worst errors and mean commands."""
    sim = Simulation(with_faults(V, faults), seed=3)
    run(sim, 0.5)
    sim.home.is_set = True  # as HomeTracker does once the estimator is ready
    ap = sim.autopilot
    assert ap.set_mode(Mode.GUIDED, sim.time_ns)[0] and ap.arm(sim.time_ns)[0]
    assert DN.nav_command(sim, M.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, ALT_M), None, sim.time_ns)[0] == 0
    run(sim, 8.0)
    alt_err = horiz = tilt = 0.0
    cmds = []
    for _ in range(int(seconds * 10)):
        run(sim, 0.1)
        k = sim.world.kinematics
        alt_err = max(alt_err, abs(-k.d - ALT_M))
        horiz = max(horiz, math.hypot(k.n, k.e))
        tilt = max(tilt, math.degrees(math.acos(math.cos(sim.imu.roll) * math.cos(sim.imu.pitch))))
        cmds.append(ap.rotor_cmd_n)
    mean = tuple(sum(c[i] for c in cmds) / len(cmds) for i in range(4))
    assert ap.armed and ap.mode == Mode.GUIDED
    return sim, {"alt_err": alt_err, "horiz": horiz, "tilt": tilt, "cmd": mean}


@pytest.fixture(scope="module")
def nominal():
    return hold(FaultParams())[1]


def test_a_weak_motor_still_hovers_and_its_output_rises(nominal):
    sim, r = hold(FaultParams(motor_scale=(0.85, 1.0, 1.0, 1.0)))
    assert r["alt_err"] < 0.1 and r["horiz"] < 0.3 and r["tilt"] < 2.0          # the integrators compensate
    c1, c2, c3, c4 = r["cmd"]
    assert c1 == pytest.approx(hover_trim_n(sim.vehicle)[0] / 0.85, rel=0.03)     # 1/0.85 of its share
    assert c1 > 1.12 * max(c2, c3, c4)
    assert (c2, c3, c4) == pytest.approx(nominal["cmd"][1:], rel=0.03)           # the others as nominal
    servo = build(M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, sim, TelemetryCounters(0))   # PWM 1000 + 1000 T / T_max
    assert servo.servo1_raw > max(servo.servo2_raw, servo.servo3_raw, servo.servo4_raw) + 30


def test_a_heavier_vehicle_holds_altitude(nominal):
    sim, r = hold(FaultParams(mass_scale=1.2))
    assert r["alt_err"] < 0.1 and r["horiz"] < 0.3 and r["tilt"] < 2.0
    assert sum(r["cmd"]) == pytest.approx(1.2 * sum(nominal["cmd"]), rel=0.02)    # 20 % more thrust
    assert sim.params["MOT_THST_HOVER"] == pytest.approx(V.hover_thrust_fraction, abs=1e-4)  # still the nominal value


def test_an_offset_centre_of_mass_is_trimmed_out():
    sim, r = hold(FaultParams(com_offset_m=(0.03, -0.02, 0.0), inertia_scale=1.5))
    assert r["alt_err"] < 0.1 and r["horiz"] < 0.3 and r["tilt"] < 2.0
    assert r["cmd"] == pytest.approx(hover_trim_n(sim.vehicle), rel=0.03)


def test_the_sitl_arg_path_flies_a_weak_motor_on_a_slow_clock():
    """As ``gcs fly --sitl-arg=--motor-scale=0.85,1,1,1 --sitl-arg=--clock-rate=0.988`` starts it: lockstep,
    GUIDED_NOGPS climb and hold, over UDP."""
    gcs = Gcs("udpin:127.0.0.1:0", hello=False)
    port = gcs.conn.port.getsockname()[1]
    child = EmbeddedSitl(port, lockstep=True, seed=5,
                         extra_args=["--motor-scale=0.85,1,1,1", "--clock-rate=0.988"]).start()
    try:
        assert gcs.wait_heartbeat(timeout=20) is not None, child.exit_reason()
        gcs.start_lockstep_streams()
        assert gcs.request(M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, 100).result == M.MAV_RESULT_ACCEPTED
        assert gcs.set_mode(20).result == 0 and gcs.arm().result == 0
        for _ in range(200):                       # 2 s climbing at 0.5 m/s
            gcs.step(0.6)
        for _ in range(300):                       # 3 s holding
            pos = gcs.step(0.5)
        gcs.drain()
        assert -pos.z > 0.7 and abs(pos.vz) < 0.1
        att = gcs.log["ATTITUDE"][-1]
        assert abs(att.roll) < math.radians(2) and abs(att.pitch) < math.radians(2)
        # 5 s of lockstep (plus the commands' zero-time) on a clock at 0.988: time_boot_ms about 4940
        stamps = [m.time_boot_ms for m in gcs.log["ATTITUDE"]]
        span_ms = stamps[-1] - stamps[0]
        assert span_ms == pytest.approx(0.988 * 10 * (len(stamps) - 1), abs=2)
        servo = gcs.log["SERVO_OUTPUT_RAW"][-1]
        assert servo.servo1_raw > max(servo.servo2_raw, servo.servo3_raw, servo.servo4_raw) + 30
        assert servo.time_usec == pytest.approx(att.time_boot_ms * 1000, abs=10_000)
    finally:
        child.stop()
        gcs.close()
