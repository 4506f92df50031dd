"""ArduPilot SITL's ground contact and sensor smoothing in the emulation (ardupilot_emulation.ground)."""

from __future__ import annotations

import pytest

from quadrotor.frames import Kinematics
from sitl.copter import rigid_body
from sitl.copter.ardupilot_emulation.ground import (RELEASE_SPEED_M_S, SMOOTHING_TAU_S, SmoothedSensors,
                                                    sticky_ground_step)
from sitl.copter.ardupilot_emulation.vehicle import arducopter_sitl_vehicle
from sitl.copter.rigid_body import RigidBodyModel, RigidBodyState

DT = 1.0 / 1200.0


def _model():
    v = arducopter_sitl_vehicle()
    return v, RigidBodyModel(v)


def _motors_at(state, total_n):
    return state._replace(t1=total_n / 4, t2=total_n / 4, t3=total_n / 4, t4=total_n / 4)


def test_thrust_above_weight_builds_a_hidden_climb_rate_until_it_reaches_the_release_speed():
    v, m = _model()
    weight = v.mass_kg * v.gravity_m_s2
    thrust = 1.2 * weight  # about 2 m/s^2 upward
    s = _motors_at(RigidBodyState(), thrust)
    steps, pinned = 0, []
    while s.on_ground and steps < 5000:
        s = sticky_ground_step(s, (thrust / 4,) * 4, DT, m)
        steps += 1
        if s.on_ground:
            pinned.append(s)
    accel = thrust / v.mass_kg - v.gravity_m_s2
    # On the ground the whole time: height 0, no horizontal motion, no rates ...
    assert all(p.d == 0.0 and p.vn == p.ve == 0.0 and p.p == p.q == p.r == 0.0 for p in pinned)
    # ... while the upward velocity grows at the net acceleration (less the drag, small at these speeds)
    assert -pinned[len(pinned) // 2].vd == pytest.approx(accel * len(pinned) / 2 * DT, rel=0.15)
    # released once it reaches 1.2 m/s (1 mm per step of ArduPilot's 1200 Hz physics), not before
    assert pytest.approx(1.2) == RELEASE_SPEED_M_S
    assert -pinned[-1].vd < RELEASE_SPEED_M_S <= -s.vd
    assert steps * DT == pytest.approx(RELEASE_SPEED_M_S / accel, rel=0.15)
    assert s.d < 0.0  # and it climbs


def test_the_plain_plant_lets_go_at_once():
    v, m = _model()
    thrust = 1.2 * v.mass_kg * v.gravity_m_s2
    s = rigid_body.step(_motors_at(RigidBodyState(), thrust), (thrust / 4,) * 4, DT, m)
    assert not s.on_ground


def test_thrust_below_weight_keeps_it_resting_with_no_velocity():
    v, m = _model()
    thrust = 0.8 * v.mass_kg * v.gravity_m_s2
    s = _motors_at(RigidBodyState(), thrust)
    for _ in range(1200):
        s = sticky_ground_step(s, (thrust / 4,) * 4, DT, m)
    assert s.on_ground and s.d == 0.0 and s.vd == 0.0


def test_in_the_air_it_is_the_plain_step():
    v, m = _model()
    s = _motors_at(RigidBodyState(d=-1.0, vd=-0.3, on_ground=False), 30.0)
    cmd = (7.0, 7.5, 8.0, 7.2)
    assert sticky_ground_step(s, cmd, DT, m) == rigid_body.step(s, cmd, DT, m)


def _k(d, vd):
    return Kinematics(0.0, 0.0, d, 0.0, 0.0, vd, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def test_smoothing_follows_free_motion_once_settled():
    smooth = SmoothedSensors(_k(0.0, -0.5))
    dt, d = 0.0025, 0.0
    out = None
    for _ in range(400):  # 1 s of a steady 0.5 m/s climb from a matched start
        d -= 0.5 * dt
        out = smooth.apply(_k(d, -0.5), dt)
    # the velocity exactly; the position within one step's motion (the reading is taken after the truth moved)
    assert out.vd == pytest.approx(-0.5, abs=1e-4) and out.d == pytest.approx(d, abs=0.5 * dt * 1.01)


def test_a_pinned_vehicle_with_a_hidden_climb_rate_reads_a_steady_climb_of_a_tau():
    smooth = SmoothedSensors(_k(0.0, 0.0))
    dt, accel, out = 0.0025, 1.76, None
    for i in range(1, 241):  # 0.6 s pinned at height 0, hidden upward speed a t (the firmware's log)
        out = smooth.apply(_k(0.0, -accel * i * dt), dt)
    assert -out.vd == pytest.approx(accel * SMOOTHING_TAU_S, rel=0.05)  # 0.176 m/s, as in the log
    assert -out.d > 0.05  # the sensed height is already above the liftoff mark


def test_bad_time_constant_refused():
    with pytest.raises(ValueError, match="tau_s"):
        SmoothedSensors(_k(0.0, 0.0), tau_s=0.0)


def test_only_the_emulated_simulation_has_the_firmware_simulators_ground_and_sensors():
    from sitl.copter.simulation import Simulation

    emulated = Simulation(arducopter_sitl_vehicle(), emulate="arducopter", ekf_ready_s=0.0)
    plain = Simulation(arducopter_sitl_vehicle())
    assert emulated.world.plant.step_fn is sticky_ground_step
    assert plain.world.plant.step_fn is rigid_body.step
    # armed on the ground with thrust above weight: the emulated vehicle stays put while its sensors climb
    v = emulated.vehicle
    thrust = 1.18 * v.mass_kg * v.gravity_m_s2
    smooth = SmoothedSensors(emulated.world.kinematics)
    emulated.world.plant.state = _motors_at(emulated.world.plant.state, thrust)
    sensed = None
    for _ in range(160):  # 0.4 s
        emulated.world.step((thrust / 4,) * 4, emulated.dt_s)
        sensed = smooth.apply(emulated.world.kinematics, emulated.dt_s)
    assert emulated.world.on_ground and emulated.world.kinematics.d == 0.0
    assert sensed.vd < -0.1
