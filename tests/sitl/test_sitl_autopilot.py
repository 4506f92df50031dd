"""Emulated ArduCopter behaviour, driven directly (no link)."""

from __future__ import annotations

import math

import pytest

from quadrotor.frames import euler_to_quaternion
from quadrotor.wind import WindParams
from sitl.copter.modes import Mode
from sitl.copter.simulation import InitialConditions, Simulation
from sitl.copter.vehicle_file import load_vehicle

V = load_vehicle()
LEVEL = (1.0, 0.0, 0.0, 0.0)


def make(**kw) -> Simulation:
    return Simulation(V, seed=kw.pop("seed", 1), **kw)


def run(sim: Simulation, seconds: float, thrust: float | None = 0.5, q=LEVEL, mask: int = 0b111, rates=(0, 0, 0)):
    """Send a target every 10 ms (None: send nothing) and tick."""
    for _ in range(int(round(seconds / 0.01))):
        if thrust is not None:
            sim.autopilot.set_attitude_target(mask, q, rates, thrust, sim.time_ns)
        for _ in range(4):
            sim.tick()


def alt(sim: Simulation) -> float:
    return -sim.world.kinematics.d


def armed_guided(**kw) -> Simulation:
    sim = make(**kw)
    assert sim.autopilot.set_mode(Mode.GUIDED_NOGPS, 0) == (True, "")
    assert sim.autopilot.arm(sim.time_ns) == (True, "")
    return sim


def test_arming_refused_when_leaning():
    sim = make(initial=InitialConditions(roll_deg=40.0))
    ok, reason = sim.autopilot.arm(0)
    assert not ok and reason.startswith("Leaning")
    assert sim.autopilot.events[-1][1].startswith("Arm: Leaning")
    sim = make(initial=InitialConditions(roll_deg=15.0))
    assert sim.autopilot.arm(0)[0]            # within ATC_ANGLE_MAX (30 deg)


def test_arming_refused_when_not_landed():
    sim = make(initial=InitialConditions(altitude_m=10.0))
    ok, reason = sim.autopilot.arm(0)
    assert not ok and reason.startswith("Not landed")


def test_arming_refused_when_battery_low():
    sim = make(params={"BATT_LOW_VOLT": 12.9})
    ok, reason = sim.autopilot.arm(0)
    assert not ok and "low voltage" in reason
    sim = make(params={"BATT_ARM_VOLT": 13.0})
    assert "arming volt" in sim.autopilot.arm(0)[1]
    v = V.__class__(**{**V.__dict__, "battery": V.battery.__class__(initial_charge=0.02)})
    assert "Battery" in Simulation(v).autopilot.arm(0)[1]


def test_arming_checks_can_be_skipped_or_forced_but_not_in_land():
    sim = make(params={"BATT_LOW_VOLT": 12.9, "ARMING_CHECK": 0})
    assert sim.autopilot.arm(0)[0]
    sim = make(initial=InitialConditions(roll_deg=40.0))
    assert sim.autopilot.arm(0, force=True)[0]
    sim = make()
    sim.autopilot.set_mode(Mode.LAND, 0)
    assert sim.autopilot.arm(0) == (False, "Mode not armable")


def test_prearm_delay():
    sim = make(prearm_delay_s=1.0)
    assert "not ready" in sim.autopilot.arm(0)[1]
    run(sim, 1.0, thrust=None)
    assert sim.autopilot.arm(sim.time_ns)[0]


def test_set_attitude_target_acceptance_rules():
    sim = make()
    ap = sim.autopilot
    assert ap.set_attitude_target(7, LEVEL, (0, 0, 0), 0.5, 0) == (False, "not in a guided mode")
    ap.set_mode(Mode.GUIDED, 0)
    assert ap.set_attitude_target(7 | 64, LEVEL, (0, 0, 0), 0.5, 0)[1] == "THROTTLE_IGNORE"
    assert "unit" in ap.set_attitude_target(7, (1.0, 0.1, 0.0, 0.0), (0, 0, 0), 0.5, 0)[1]
    assert "partly" in ap.set_attitude_target(1, LEVEL, (0, 0, 0), 0.5, 0)[1]
    assert not ap.set_attitude_target(7, (math.nan, 0, 0, 0), (0, 0, 0), 0.5, 0)[0]
    assert not ap.set_attitude_target(0, LEVEL, (math.inf, 0, 0), 0.5, 0)[0]
    assert ap.targets_rejected == 6
    assert ap.set_attitude_target(7, (0.99995, 0.01, 0.0, 0.0), (0, 0, 0), 0.5, 0)[0]  # |q|^2 within 1e-3
    assert ap.set_attitude_target(128, (0, 0, 0, 0), (0.1, 0.2, 0.3), 0.5, 0)[0]      # rates only
    assert ap.target.kind == "rates" and ap.target.rates == (0.1, 0.2, 0.3)
    assert ap.set_attitude_target(128 | 7, (0, 0, 0, 0), (9, 9, 9), 0.5, 0)[0]        # zero rates
    assert ap.target.rates == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("thrust, climb", [(0.5, 0.0), (0.6, 0.5), (1.0, 2.5), (1.7, 2.5), (0.0, -1.5),
                                           (0.25, -0.75), (-3.0, -1.5)])
def test_thrust_is_a_climb_rate_by_default(thrust, climb):
    sim = make()
    sim.autopilot.set_mode(Mode.GUIDED_NOGPS, 0)
    sim.autopilot.set_attitude_target(7, LEVEL, (0, 0, 0), thrust, 0)
    t = sim.autopilot.target
    assert not t.use_thrust and t.value == pytest.approx(climb)


def test_guid_options_8_makes_thrust_throttle():
    sim = make(params={"GUID_OPTIONS": 8})
    sim.autopilot.set_mode(Mode.GUIDED_NOGPS, 0)
    sim.autopilot.set_attitude_target(7, LEVEL, (0, 0, 0), 0.42, 0)
    assert sim.autopilot.target.use_thrust and sim.autopilot.target.value == pytest.approx(0.42)


def test_climb_rate_demand_is_tracked():
    sim = armed_guided()
    run(sim, 4.0, 0.6)                               # +0.5 m/s
    assert -sim.world.kinematics.vd == pytest.approx(0.5, abs=0.05)
    run(sim, 3.0, 0.5)                               # hold
    h = alt(sim)
    run(sim, 2.0, 0.5)
    assert alt(sim) == pytest.approx(h, abs=0.15)
    run(sim, 3.0, 0.25)                              # -0.75 m/s
    assert -sim.world.kinematics.vd == pytest.approx(-0.75, abs=0.05)


def test_thrust_mode_hover_and_climb():
    sim = armed_guided(params={"GUID_OPTIONS": 8})
    hover = sim.params["MOT_THST_HOVER"]
    run(sim, 1.0, hover + 0.1)
    assert not sim.autopilot.land_complete and alt(sim) > 0.3
    run(sim, 20.0, hover)                    # hover thrust: only drag acts, the climb dies out
    assert abs(sim.world.kinematics.vd) < 0.05
    run(sim, 2.0, 0.5)
    assert -sim.world.kinematics.vd > 3.0   # 0.5 climbs fast (ArduCopter SITL: about 5 m/s)


def test_attitude_and_rate_targets_are_tracked():
    sim = armed_guided()
    run(sim, 2.0, 0.6)
    q = euler_to_quaternion(math.radians(15), math.radians(-10), math.radians(30))
    run(sim, 1.5, 0.5, q=q)
    assert math.degrees(sim.imu.roll) == pytest.approx(15, abs=1.0)
    assert math.degrees(sim.imu.pitch) == pytest.approx(-10, abs=1.0)
    assert math.degrees(sim.imu.yaw) == pytest.approx(30, abs=1.5)
    run(sim, 1.0, 0.5)
    run(sim, 1.0, 0.5, mask=128, rates=(0.0, 0.0, 0.5))   # yaw at 0.5 rad/s
    assert sim.world.kinematics.r == pytest.approx(0.5, abs=0.05)


def test_actuator_controls_map_to_torque_and_thrust():
    sim = make(initial=InitialConditions(altitude_m=50.0))
    ap = sim.autopilot
    ap.set_mode(Mode.GUIDED_NOGPS, 0)
    ap.arm(0, force=True)
    hover = V.hover_thrust_fraction
    for _ in range(100):                 # spin up and settle at hover thrust, no torque
        ap.set_actuator_controls([0, 0, 0, hover, 0, 0, 0, 0], sim.time_ns)
        for _ in range(4):
            sim.tick()
    p0 = sim.world.kinematics.p
    for _ in range(10):                  # 0.1 s of roll torque 0.05 x max
        ap.set_actuator_controls([0.05, 0, 0, hover, 0, 0, 0, 0], sim.time_ns)
        for _ in range(4):
            sim.tick()
    tau = 0.05 * V.max_torque_nm[0]
    lag = V.rotors.time_constant_s
    expected = tau / V.inertia_kg_m2[0][0] * (0.1 - lag * (1 - math.exp(-0.1 / lag)))
    assert sim.world.kinematics.p - p0 == pytest.approx(expected, rel=0.05)
    assert ap.throttle == pytest.approx(hover)


def test_disarm_delay_disarms_a_vehicle_that_never_takes_off():
    sim = armed_guided()
    run(sim, 9.5, 0.5)
    assert sim.autopilot.armed
    run(sim, 0.6, 0.5)
    assert not sim.autopilot.armed and "landed for 10 s" in sim.autopilot.events[-1][1]
    sim = armed_guided(params={"DISARM_DELAY": 0})
    run(sim, 12.0, 0.5)
    assert sim.autopilot.armed


def test_disarm_refused_in_flight_unless_forced():
    sim = armed_guided()
    run(sim, 2.0, 0.8)
    assert sim.autopilot.disarm(sim.time_ns)[0] is False
    assert sim.autopilot.disarm(sim.time_ns, force=True)[0] is True


def test_guided_timeout_levels_and_lands():
    sim = armed_guided()
    run(sim, 3.0, 0.8)
    run(sim, 2.9, None)                       # commands stop
    assert sim.autopilot.mode == Mode.GUIDED_NOGPS
    run(sim, 0.2, None)
    assert sim.autopilot.mode == Mode.LAND and sim.autopilot.failsafe == "guided timeout"
    assert any("Guided timeout" in t for _, t in sim.autopilot.events)
    run(sim, 25.0, None)
    assert not sim.autopilot.armed and alt(sim) == pytest.approx(0.0, abs=0.05)


def test_land_mode_lands_and_disarms():
    sim = armed_guided()
    run(sim, 4.0, 1.0)                        # climb to ~8 m
    h = alt(sim)
    assert h > 6.0
    sim.autopilot.set_mode(Mode.LAND, sim.time_ns)
    run(sim, 4.0, None)
    assert -sim.world.kinematics.vd == pytest.approx(-0.5, abs=0.1)   # LAND_SPD_MS below 10 m
    run(sim, 20.0, None)
    assert not sim.autopilot.armed and sim.world.on_ground and sim.autopilot.land_complete
    assert any("landed" in t for _, t in sim.autopilot.events)


def test_land_descends_fast_above_land_alt_low():
    sim = armed_guided(params={"LAND_ALT_LOW_M": 2.0})
    run(sim, 4.0, 1.0)
    sim.autopilot.set_mode(Mode.LAND, sim.time_ns)
    run(sim, 5.0, None)                       # the climb-rate target ramps at WP_ACC_Z = 1 m/s/s
    assert -sim.world.kinematics.vd == pytest.approx(-1.5, abs=0.15)   # WP_SPD_DN


def test_stabilize_without_rc_idles_on_the_ground():
    sim = make()
    assert sim.autopilot.arm(0)[0]
    run(sim, 2.0, None)
    assert sim.world.on_ground and sim.autopilot.armed and sim.autopilot.throttle == 0.0


def test_battery_failsafe_announces_and_lands():
    sim = armed_guided(params={"BATT_FS_LOW_ACT": 1})
    run(sim, 2.0, 0.8)
    sim.params.set("BATT_LOW_VOLT", 12.7)
    run(sim, 10.5, 0.5)
    assert sim.autopilot.mode == Mode.LAND and sim.autopilot.failsafe == "battery"
    assert any("Battery 1 is low" in t for _, t in sim.autopilot.events)


def test_reduced_model_flies_the_same_mission():
    sim = Simulation(V.with_model("reduced"), seed=1)
    sim.autopilot.set_mode(Mode.GUIDED_NOGPS, 0)
    assert sim.autopilot.arm(0)[0]
    run(sim, 4.0, 0.75)
    assert alt(sim) > 2.5
    sim.autopilot.set_mode(Mode.LAND, sim.time_ns)
    run(sim, 20.0, None)
    assert not sim.autopilot.armed and alt(sim) == pytest.approx(0.0, abs=0.01)


def test_wind_is_seeded_and_pushes_the_vehicle():
    def flight(seed):
        sim = armed_guided(seed=seed, wind=WindParams(3.0, 90.0, 0.5))
        run(sim, 6.0, 0.75)
        return sim.world.kinematics
    a, b, c = flight(1), flight(1), flight(2)
    assert a == b and a != c
    assert a.e > 1.0 and a.ve > 0.5         # blown east
