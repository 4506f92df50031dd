"""The navigation modes of the built-in SITL (sitl.copter.navigation, sitl.copter.dispatch_nav), driven
directly: GUIDED take-off and position/velocity targets, LOITER, BRAKE, ALT_HOLD, RTL, AUTO."""

from __future__ import annotations

import math
import time

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from quadrotor.clock import ScaledClock
from quadrotor.geodesy import geodetic_from_local
from sitl.cli import main as sitl_main
from sitl.copter import dispatch_nav as DN
from sitl.copter.mission_store import MissionItem
from sitl.copter.modes import Mode
from sitl.copter.navigation import sqrt_controller
from sitl.copter.simulation import Simulation
from sitl.copter.vehicle_file import load_vehicle

V = load_vehicle()


def make(**kw) -> Simulation:
    sim = Simulation(V, seed=kw.pop("seed", 3), **kw)
    run(sim, 0.5)
    sim.home.is_set = True  # as HomeTracker does once the estimator is ready
    return sim


def run(sim: Simulation, seconds: float, until=None) -> None:
    for _ in range(int(round(seconds * 400))):
        sim.tick()
        if until is not None and until(sim):
            return


def pos(sim: Simulation) -> tuple[float, float, float]:
    k = sim.world.kinematics
    return k.n, k.e, -k.d


def tilt_deg(sim: Simulation) -> float:
    return math.degrees(math.acos(math.cos(sim.imu.roll) * math.cos(sim.imu.pitch)))


def takeoff(sim: Simulation, alt_m: float = 5.0) -> None:
    ap = sim.autopilot
    assert ap.set_mode(Mode.GUIDED, sim.time_ns)[0] and ap.arm(sim.time_ns)[0]
    assert DN.nav_command(sim, M.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, alt_m), None, sim.time_ns)[0] == 0
    run(sim, 8.0)


def item(sim: Simulation, seq: int, cmd: int, n=0.0, e=0.0, up=0.0, p1=0.0, p2=0.0) -> MissionItem:
    h = sim.vehicle.home
    x = y = 0
    if n or e:
        lat, lon = geodetic_from_local(h.lat_deg, h.lon_deg, n, e)
        x, y = int(round(lat * 1e7)), int(round(lon * 1e7))
    return MissionItem(seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, cmd, x=x, y=y, z=up, param1=p1, param2=p2)


def test_sqrt_controller_is_linear_near_zero_and_decelerates_within_the_limit():
    assert sqrt_controller(0.1, 1.0, 2.5) == pytest.approx(0.1)
    far = sqrt_controller(50.0, 1.0, 2.5)
    assert far == pytest.approx(math.sqrt(2 * 2.5 * (50 - 1.25)))  # v^2 / 2a = the distance to go
    assert sqrt_controller(-50.0, 1.0, 2.5) == -far
    assert sqrt_controller(1.25 + 1e-9, 1.0, 2.5) == pytest.approx(1.25, abs=1e-6)  # continuous


def test_armed_in_guided_on_the_ground_it_stays_down_despite_sensor_noise():
    sim = make()
    ap = sim.autopilot
    assert ap.set_mode(Mode.GUIDED, sim.time_ns)[0] and ap.arm(sim.time_ns)[0]
    run(sim, 5.0)
    assert ap.land_complete and pos(sim)[2] < 0.05
    assert ap.disarm(sim.time_ns)[0]  # not "vehicle is flying"


def test_guided_takeoff_holds_then_flies_to_a_position_target_and_holds_without_a_timeout():
    sim = make()
    ap = sim.autopilot
    # take-off only when armed, landed, in GUIDED
    assert DN.nav_command(sim, M.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, 5.0), None, sim.time_ns)[0] == \
        M.MAV_RESULT_FAILED
    takeoff(sim)
    n, e, up = pos(sim)
    assert up == pytest.approx(5.0, abs=0.15) and math.hypot(n, e) < 0.3 and not ap.land_complete
    msg = M.MAVLink_set_position_target_local_ned_message(0, 1, 1, M.MAV_FRAME_LOCAL_NED, 0b110111111000,
                                                          15.0, -10.0, -7.0, 0, 0, 0, 0, 0, 0, 0, 0)
    assert DN.nav_message(sim, msg, sim.time_ns)
    peak = 0.0
    for _ in range(15):
        run(sim, 1.0)
        peak = max(peak, tilt_deg(sim))
    assert pos(sim) == pytest.approx((15.0, -10.0, 7.0), abs=0.3)
    assert ap.mode == Mode.GUIDED and ap.armed and peak <= 30.0 + 1.0  # ATC_ANGLE_MAX
    assert not any("Guided timeout" in t for _, t in ap.events)  # position targets do not time out


def test_a_velocity_target_stops_after_guid_timeout():
    sim = make()
    takeoff(sim)
    msg = M.MAVLink_set_position_target_local_ned_message(0, 1, 1, M.MAV_FRAME_LOCAL_NED, 0b110111000111,
                                                          0, 0, 0, 2.0, 0.0, 0.0, 0, 0, 0, 0, 0)
    assert DN.nav_message(sim, msg, sim.time_ns)
    run(sim, 2.5)
    assert sim.world.kinematics.vn == pytest.approx(2.0, abs=0.3)
    run(sim, 4.0)  # GUID_TIMEOUT 3 s: stopped and holding
    assert math.hypot(sim.world.kinematics.vn, sim.world.kinematics.ve) < 0.2
    n0 = pos(sim)[0]
    run(sim, 2.0)
    assert abs(pos(sim)[0] - n0) < 0.2 and sim.autopilot.mode == Mode.GUIDED


def test_position_targets_are_ignored_outside_guided_and_when_not_finite():
    sim = make()
    msg = M.MAVLink_set_position_target_local_ned_message(0, 1, 1, M.MAV_FRAME_LOCAL_NED, 0b110111111000,
                                                          1, 1, -1, 0, 0, 0, 0, 0, 0, 0, 0)
    assert not DN.nav_message(sim, msg, sim.time_ns)  # STABILIZE
    sim.autopilot.set_mode(Mode.GUIDED, sim.time_ns)
    msg.x = math.nan
    assert not DN.nav_message(sim, msg, sim.time_ns)
    assert sim.autopilot.targets_rejected == 2


def test_brake_stops_a_fast_vehicle_and_loiter_and_alt_hold_hold():
    sim = make()
    ap = sim.autopilot
    takeoff(sim)
    ap.navigator.goto(200.0, 0.0, -5.0, None)
    run(sim, 12.0)
    assert sim.world.kinematics.vn > 7.0  # cruising at WP_SPD
    assert ap.set_mode(Mode.BRAKE, sim.time_ns)[0]
    n0 = pos(sim)[0]
    run(sim, 4.0)
    assert abs(sim.world.kinematics.vn) < 0.3 and pos(sim)[0] - n0 < 20.0  # stopped within ~v^2/(2 * 7.5 m/s^2)
    assert ap.set_mode(Mode.LOITER, sim.time_ns)[0]
    run(sim, 1.0)
    here = pos(sim)
    run(sim, 5.0)
    assert pos(sim) == pytest.approx(here, abs=0.3)
    assert ap.set_mode(Mode.ALT_HOLD, sim.time_ns)[0]
    run(sim, 5.0)
    assert pos(sim)[2] == pytest.approx(here[2], abs=0.3) and tilt_deg(sim) < 2.0


def test_rtl_climbs_returns_loiters_lands_at_home_and_disarms():
    sim = make()
    ap = sim.autopilot
    takeoff(sim)
    ap.navigator.goto(20.0, 10.0, -8.0, None)
    run(sim, 10.0)
    assert ap.set_mode(Mode.RTL, sim.time_ns)[0]
    top = 0.0
    for _ in range(80):
        run(sim, 1.0)
        top = max(top, pos(sim)[2])
        if not ap.armed:
            break
    n, e, up = pos(sim)
    assert not ap.armed and ap.mode == Mode.RTL and math.hypot(n, e) < 0.5 and up < 0.1
    assert top == pytest.approx(15.0, abs=0.5)  # RTL_ALT_M
    assert any("Disarming motors: landed" in t for _, t in ap.events)


def test_rtl_refused_before_home_and_auto_refused_without_a_mission_or_a_takeoff():
    sim = Simulation(V, seed=1)
    ap = sim.autopilot
    assert ap.set_mode(Mode.RTL, 0) == (False, "RTL: home not set")
    assert ap.set_mode(Mode.AUTO, 0) == (False, "Auto: no mission")
    sim.missions.replace(0, [MissionItem(0, 0, 16), item(sim, 1, 16, 10, 0, 5)])
    assert ap.set_mode(Mode.AUTO, 0) == (False, "Auto: Missing takeoff command")
    assert ap.set_mode(7, 0)[0] is False  # CIRCLE: not emulated
    # arming is refused in AUTO (ArduCopter's AUTO_OPTIONS bit 0 is not set)
    sim.missions.replace(0, [MissionItem(0, 0, 16), item(sim, 1, 22, up=5)])
    assert ap.set_mode(Mode.AUTO, 0)[0] and not ap.arm(0)[0]


def test_auto_flies_takeoff_waypoints_and_land_reporting_each_item():
    sim = make()
    ap = sim.autopilot
    sim.missions.replace(0, [MissionItem(0, 0, 16), item(sim, 1, 22, up=5), item(sim, 2, 178, p2=4.0),
                             item(sim, 3, 16, 12, 0, 6), item(sim, 4, 16, 12, 12, 6, p1=1.0),
                             item(sim, 5, 21, 0, 12)])
    assert ap.set_mode(Mode.GUIDED, sim.time_ns)[0] and ap.arm(sim.time_ns)[0]
    assert DN.nav_command(sim, M.MAV_CMD_MISSION_START, (0,) * 7, None, sim.time_ns)[0] == 0
    assert ap.mode == Mode.AUTO
    seen, fastest = set(), 0.0
    for _ in range(90):
        run(sim, 0.5)
        seen.add(sim.missions.current_seq)
        k = sim.world.kinematics
        fastest = max(fastest, math.hypot(k.vn, k.ve))
        if not ap.armed:
            break
    n, e, up = pos(sim)
    assert not ap.armed and up < 0.1 and n == pytest.approx(0.0, abs=0.5) and e == pytest.approx(12.0, abs=0.5)
    assert sim.missions.reached == [1, 3, 4, 5] and {1, 3, 4, 5} <= seen  # DO_CHANGE_SPEED is no nav item
    assert fastest <= 4.0 + 0.3  # DO_CHANGE_SPEED
    texts = [t for _, t in ap.events]
    assert "Mission: 3 WP" in texts and "Reached command #5" in texts


def test_scaled_clock_and_sitl_speedup_option(capsys):
    clock = ScaledClock(4.0)
    t0, w0 = clock.now_ns(), time.monotonic_ns()
    clock.sleep_until_ns(t0 + 200_000_000)  # 0.2 s of its time: 0.05 s of ours
    assert (time.monotonic_ns() - w0) < 150_000_000 and clock.now_ns() >= t0 + 200_000_000
    for bad in (0.0, -1.0, math.nan, 1000.0):
        with pytest.raises(ValueError, match="speedup"):
            ScaledClock(bad)
    assert sitl_main(["--udp", "127.0.0.1:0", "--speedup", "0"]) == 2
    assert sitl_main(["--udp", "127.0.0.1:0", "--speedup", "3", "--lockstep"]) == 2
    err = capsys.readouterr().err
    assert "--speedup: speedup must be in (0, 100]" in err and "not with --lockstep" in err
