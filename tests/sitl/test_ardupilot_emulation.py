"""``sitl --emulate arducopter``: the emulated pieces of ArduCopter, flown in-process (no link)."""

from __future__ import annotations

import math

import pytest

from quadrotor.frames import euler_to_quaternion
from sitl.copter.ardupilot_emulation.filters import LowPass2p, RatePid
from sitl.copter.ardupilot_emulation.motors import ARMING_DELAY_S, SpoolState, actuator_to_thrust, thrust_to_actuator
from sitl.copter.ardupilot_emulation.shaping import attitude_command_model, sqrt_controller
from sitl.copter.ardupilot_emulation.vehicle import arducopter_sitl_vehicle
from sitl.copter.simulation import Simulation

GUIDED_NOGPS = 20
FLIGHT = {"GUID_OPTIONS": 8, "ATC_ANGLE_BOOST": 0, "ATC_RATE_FF_ENAB": 0}


def make_sim(ekf_ready_s: float = 1.0, **params: float) -> Simulation:
    return Simulation(arducopter_sitl_vehicle(), emulate="arducopter", ekf_ready_s=ekf_ready_s,
                      params={**FLIGHT, **params})


def run_until(sim: Simulation, t_s: float, q=None, thrust: float | None = None) -> None:
    while sim.time_s < t_s:
        if q is not None:
            sim.autopilot.set_attitude_target(7, q, (0.0, 0.0, 0.0), thrust, sim.time_ns)
        sim.tick()


def armed_on_ground(ekf_ready_s: float = 1.0) -> Simulation:
    """A simulation armed in GUIDED_NOGPS on the ground, 1.1 s after boot."""
    sim = make_sim(ekf_ready_s)
    run_until(sim, 1.1)
    sim.autopilot.set_mode(GUIDED_NOGPS, sim.time_ns)
    sim.autopilot.arm(sim.time_ns)
    return sim


def airborne(sim: Simulation, alt_m: float = 1.5) -> tuple[float, float, float, float]:
    """Armed in GUIDED_NOGPS and climbed to about ``alt_m``; returns the level quaternion flown."""
    ap = sim.autopilot
    run_until(sim, ap.readiness.ready_s + 0.1)
    assert ap.set_mode(GUIDED_NOGPS, sim.time_ns)[0]
    assert ap.arm(sim.time_ns)[0]
    q = euler_to_quaternion(0.0, 0.0, sim.imu.yaw)
    hover = sim.params["MOT_THST_HOVER"]
    t0 = sim.time_s
    while -sim.world.kinematics.d < alt_m and sim.time_s < t0 + 20:
        run_until(sim, sim.time_s + 0.01, q, 1.1 * hover)
    return q


def test_sqrt_controller_linear_then_square_root_and_never_overshooting():
    assert sqrt_controller(0.1, 4.5, 9.6, 0.0025) == pytest.approx(0.45)
    far = sqrt_controller(1.0, 4.5, 9.6, 0.0025)
    assert far == pytest.approx(math.sqrt(2 * 9.6 * (1.0 - 9.6 / 4.5 ** 2 / 2)))
    assert sqrt_controller(1e-4, 4.5, 9.6, 0.0025) <= 1e-4 / 0.0025


def test_command_model_approaches_a_rate_demand_within_the_acceleration_limit():
    w = a = 0.0
    accel_max = math.radians(1100)
    for _ in range(400):
        w_new, a = attitude_command_model(0.0, 1.0, w, a, 0.0, accel_max, 0.15, 0.0025)
        assert abs(w_new - w) <= accel_max * 0.0025 + 1e-9
        w = w_new
    assert w == pytest.approx(1.0, abs=0.01)


def test_gyro_filter_passes_dc_and_attenuates_above_cutoff():
    f = LowPass2p(400.0, 20.0)
    assert all(f.apply(2.0) == pytest.approx(2.0) for _ in range(10))
    g = LowPass2p(400.0, 20.0)
    out = [g.apply(math.sin(2 * math.pi * 100 * k / 400)) for k in range(400)]
    assert max(abs(v) for v in out[200:]) < 0.1


def test_rate_pid_integrator_is_frozen_while_the_motors_saturate():
    pid = RatePid(0.135, 0.135, 0.0036, 0.5, 20.0, 0.0, 20.0)
    pid.update(1.0, 0.0, 0.0025, limit=False)
    i0 = pid.integrator
    pid.update(1.0, 0.0, 0.0025, limit=True)
    assert pid.integrator == i0 > 0.0


def test_thrust_curve_round_trip_is_linear():
    for t in (0.0, 0.2, 0.366, 0.8, 1.0):
        assert actuator_to_thrust(thrust_to_actuator(t, 0.65, 0.15, 0.95), 0.65, 0.15, 0.95) == pytest.approx(t)
    assert thrust_to_actuator(0.0, 0.65, 0.15, 0.95) == pytest.approx(0.15)


def test_arming_refused_with_prearm_text_until_the_ekf_is_ready():
    sim = make_sim(ekf_ready_s=2.0)
    ap = sim.autopilot
    ap.set_mode(GUIDED_NOGPS, sim.time_ns)
    ok, reason = ap.arm(sim.time_ns)
    assert not ok and ap.events[-1][1] == f"PreArm: {reason}"
    assert not ap.position_ready(sim.time_ns)
    run_until(sim, 2.05)
    assert ap.position_ready(sim.time_ns)
    assert ap.arm(sim.time_ns)[0]


def test_no_thrust_during_the_arming_delay_then_spool_up_and_liftoff():
    sim = armed_on_ground()
    ap = sim.autopilot
    t_arm = sim.time_s
    q = euler_to_quaternion(0.0, 0.0, sim.imu.yaw)
    run_until(sim, t_arm + ARMING_DELAY_S - 0.05, q, 0.5)
    assert sum(ap.rotor_cmd_n) == 0.0 and ap.motors.spool == SpoolState.SHUT_DOWN
    run_until(sim, t_arm + ARMING_DELAY_S + 0.45, q, 0.5)
    assert ap.land_complete and ap.motors.spool == SpoolState.GROUND_IDLE
    run_until(sim, t_arm + ARMING_DELAY_S + 1.5, q, 0.5)
    assert not ap.land_complete and -sim.world.kinematics.d > 0.05


def test_heartbeat_status_boot_standby_active_standby():
    sim = make_sim(ekf_ready_s=4.0)
    ap = sim.autopilot
    seen = [ap.system_status]
    assert ap.base_mode == 81
    run_until(sim, 3.1)
    seen.append(ap.system_status)
    q = airborne(sim, 1.0)
    seen.append(ap.system_status)
    assert ap.base_mode == 209
    ap.set_mode(9, sim.time_ns)  # LAND
    while ap.armed and sim.time_s < 60:
        run_until(sim, sim.time_s + 0.05)
        if ap.land_complete and ap.armed:
            seen.append(ap.system_status)
    del q
    assert seen[:3] == [1, 3, 4] and not ap.armed and ap.base_mode == 81


def hold(sim: Simulation, seconds: float, roll_deg: float, alt_m: float) -> None:
    """Targets at ``roll_deg`` with a thrust that holds ``alt_m`` (a PD on the true altitude)."""
    yaw = sim.imu.yaw
    q = euler_to_quaternion(math.radians(roll_deg), 0.0, yaw)
    end = sim.time_s + seconds
    while sim.time_s < end:
        k = sim.world.kinematics
        thrust = 0.366 * (1.0 + 0.3 * (alt_m + k.d) + 0.5 * k.vd) / math.cos(math.radians(roll_deg))
        run_until(sim, sim.time_s + 0.01, q, thrust)


def test_guid_timeout_levels_and_holds_altitude_without_landing():
    sim = make_sim(GUID_TIMEOUT=0.5)
    ap = sim.autopilot
    airborne(sim, 1.5)
    hold(sim, 3.0, 0.0, 2.0)
    hold(sim, 0.5, 8.0, 2.0)
    assert math.degrees(sim.imu.roll) > 5.0
    alt0 = -sim.world.kinematics.d
    run_until(sim, sim.time_s + 3.0)  # no targets
    assert abs(math.degrees(sim.imu.roll)) < 1.0 and abs(math.degrees(sim.imu.pitch)) < 1.0
    assert abs(-sim.world.kinematics.d - alt0) < 0.5 and abs(sim.world.kinematics.vd) < 0.2
    assert ap.mode_name == "GUIDED_NOGPS" and ap.armed


def test_actuator_targets_are_ignored_as_on_arducopter():
    sim = make_sim()
    ap = sim.autopilot
    ap.set_mode(GUIDED_NOGPS, sim.time_ns)
    assert not ap.set_actuator_controls([0.0, 0.0, 0.0, 0.5], sim.time_ns)[0]


def test_on_the_ground_the_target_is_level_in_the_estimate_frame_and_the_integrators_relax():
    """make_safe_ground_handling: a level target (not the estimated attitude), integrators towards 0."""
    from quadrotor.frames import quaternion_to_euler

    sim = armed_on_ground()
    ap = sim.autopilot
    for pid in ap.att.pids:
        pid.integrator = 0.01
    run_until(sim, sim.time_s + 1.0, euler_to_quaternion(0.0, 0.0, sim.imu.yaw), 0.0)  # landed, zero thrust
    roll_t, pitch_t, yaw_t = quaternion_to_euler(ap.att.attitude_target)
    assert abs(roll_t) < 1e-9 and abs(pitch_t) < 1e-9
    assert yaw_t == pytest.approx(sim.imu.yaw, abs=1e-6)  # the heading target follows the body at idle
    assert sim.imu.roll > math.radians(0.05)  # while the estimate reads the firmware's tilt error
    # relaxed with 0.5 s: e^-2 of 0.01 after 1 s
    assert all(abs(pid.integrator) < 0.01 * math.exp(-1.9) for pid in ap.att.pids)


def test_spooling_up_on_the_ground_flies_a_level_target_then_the_pinned_vehicle_winds_the_rate_loop():
    """zero_throttle_and_relax_ac: with positive thrust the target stays level until the motors run
    unlimited; then, still held by the ground, a level command against the tilted estimate winds the
    roll integrator (on the firmware the vehicle rolls when the ground lets go)."""
    from quadrotor.frames import quaternion_to_euler

    sim = armed_on_ground()
    ap = sim.autopilot
    q = euler_to_quaternion(0.0, 0.0, sim.imu.yaw)
    run_until(sim, sim.time_s + ARMING_DELAY_S + 0.1, q, 0.5)
    assert ap.land_complete and ap.motors.spool in (SpoolState.GROUND_IDLE, SpoolState.SPOOLING_UP)
    roll_t, pitch_t, _ = quaternion_to_euler(ap.att.attitude_target)
    assert abs(roll_t) < 1e-9 and abs(pitch_t) < 1e-9
    assert ap.att.rate_demand[0] < 0.0  # levelling the estimated roll (+0.1 deg)
    t_end = sim.time_s + 2.0
    while ap.land_complete and sim.time_s < t_end:
        run_until(sim, sim.time_s + 0.0025, q, 0.5)
    assert not ap.land_complete and sim.world.kinematics.d == 0.0  # unlimited, still pinned
    run_until(sim, sim.time_s + 0.1, q, 0.5)
    assert sim.world.kinematics.d == 0.0
    assert ap.att.pids[0].integrator < 0.0
