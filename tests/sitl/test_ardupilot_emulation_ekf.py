"""The emulated EKF height estimate (sitl.copter.ardupilot_emulation.ekf): late and offset as measured."""

from __future__ import annotations

import math

import pytest

from sitl.copter.ardupilot_emulation.ekf import GROUND_OFFSET_M, HEIGHT_LAG_S, EkfHeight
from sitl.copter.sensors import NavReading


def _nav(d: float, vd: float = 0.0) -> NavReading:
    return NavReading(1.0, 2.0, d, 0.1, 0.2, vd, -d, -1.0)


def test_on_the_ground_the_estimate_sits_the_measured_offset_low():
    ekf = EkfHeight(0.0)
    out = ekf.apply(_nav(0.0), 0.0, 0.0025)
    assert out.d == pytest.approx(GROUND_OFFSET_M)
    assert (out.n, out.e, out.vn, out.ve, out.vd, out.baro_alt_m) == (1.0, 2.0, 0.1, 0.2, 0.0, 0.0)


def test_a_steady_climb_is_followed_one_time_constant_late_with_the_velocity_not_late():
    ekf = EkfHeight(0.0)
    dt, v = 0.0025, 0.2
    out = None
    for i in range(1, 2001):  # 5 s of a 0.2 m/s climb: the lag has settled
        out = ekf.apply(_nav(-v * i * dt, -v), -v * i * dt, dt)
    true_alt = v * 2000 * dt
    est_alt = -(out.d - GROUND_OFFSET_M)
    assert true_alt - est_alt == pytest.approx(v * HEIGHT_LAG_S, rel=0.05)
    assert out.vd == -v


def test_a_step_is_reached_as_a_first_order_lag():
    ekf = EkfHeight(0.0, lag_s=0.1, offset_m=0.0)
    out = None
    for _ in range(40):  # 0.1 s
        out = ekf.apply(_nav(-1.0), -1.0, 0.0025)
    assert -out.d == pytest.approx(1.0 - math.exp(-1.0), rel=1e-6)


def test_the_sensor_noise_is_kept_not_filtered():
    ekf = EkfHeight(0.0, lag_s=0.1, offset_m=0.0)
    assert ekf.apply(_nav(0.03), 0.0, 0.0025).d == pytest.approx(0.03)
    assert ekf.apply(_nav(-0.02), 0.0, 0.0025).d == pytest.approx(-0.02)


@pytest.mark.parametrize("lag, offset", [(-0.1, 0.0), (math.nan, 0.0), (0.1, math.inf)])
def test_bad_settings_are_refused(lag, offset):
    with pytest.raises(ValueError, match="lag_s"):
        EkfHeight(0.0, lag_s=lag, offset_m=offset)


def test_the_emulated_simulation_reports_the_offset_estimate_from_boot():
    from sitl.copter.simulation import Simulation
    from sitl.copter.vehicle_file import load_vehicle

    emulated = Simulation(load_vehicle(), emulate="arducopter", ekf_ready_s=0.0)
    n = 4000  # 10 s on the ground: the mean error is the offset, the noise averaged out (sigma / sqrt(n))
    errors = []
    for _ in range(n):
        emulated.tick()
        errors.append(emulated.nav.d - emulated.world.kinematics.d)
    sigma = emulated.sensors.params.position_noise_std_m / math.sqrt(n)
    assert sum(errors) / n == pytest.approx(GROUND_OFFSET_M, abs=4 * sigma)


# ---------------------------------------------------------------- tilt and horizontal estimate

from sitl.copter.ardupilot_emulation.ekf import (GROUND_VELOCITY_GAIN_1_S, POSITION_GAIN_1_S,  # noqa: E402
                                                 POSITION_LAG_S, RATE_OFFSET_RAD_S, TILT_PROFILE, VELOCITY_GAIN_1_S,
                                                 EkfHorizontal, EkfTilt)
from sitl.copter.sensors import ImuReading  # noqa: E402
from quadrotor.frames import euler_to_quaternion  # noqa: E402


def _imu(roll: float, pitch: float, yaw: float) -> ImuReading:
    return ImuReading(roll, pitch, yaw, 0.01, 0.02, 0.03, *euler_to_quaternion(roll, pitch, yaw))


def test_at_the_measured_heading_the_reported_angles_exceed_the_true_ones_by_the_profile():
    tilt = EkfTilt()
    heading = math.radians(-4.8)
    for t, roll_deg, pitch_deg in (TILT_PROFILE[0], TILT_PROFILE[4], TILT_PROFILE[-1]):
        out = EkfTilt.apply(_imu(0.01, -0.02, heading), tilt.error_rad(t))
        assert math.degrees(out.roll - 0.01) == pytest.approx(roll_deg, abs=2e-3)
        assert math.degrees(out.pitch + 0.02) == pytest.approx(pitch_deg, abs=2e-3)
        assert out.yaw == pytest.approx(heading, abs=1e-4)
        assert (out.p, out.q, out.r) == (0.01, 0.02, 0.03)  # no rate offset asked for


def test_the_rate_offset_is_added_to_the_body_rates_only():
    out = EkfTilt.apply(_imu(0.0, 0.0, 0.0), (0.0, 0.0), (0.001, -0.002, 0.003))
    assert (out.p, out.q, out.r) == pytest.approx((0.011, 0.018, 0.033))
    assert (out.roll, out.pitch, out.yaw) == pytest.approx((0.0, 0.0, 0.0))


def test_the_tilt_error_is_fixed_in_the_earth_frame_as_the_vehicle_turns():
    north, east = math.radians(0.1), math.radians(0.2)
    facing_east = EkfTilt.apply(_imu(0.0, 0.0, math.pi / 2), (north, east))
    # heading east, the body's roll axis points east: the east tilt reads as roll, the north one as -pitch
    assert facing_east.roll == pytest.approx(east, rel=1e-3)
    assert facing_east.pitch == pytest.approx(-north, rel=1e-3)


def test_the_profile_is_held_before_arming_interpolated_and_held_after_its_end():
    tilt = EkfTilt(profile=((1.0, 0.1, 0.2), (3.0, 0.3, 0.0)), yaw_deg=0.0)
    assert tilt.error_rad(None) == pytest.approx((math.radians(0.1), math.radians(0.2)))
    assert tilt.error_rad(2.0) == pytest.approx((math.radians(0.2), math.radians(0.1)))
    assert tilt.error_rad(100.0) == pytest.approx((math.radians(0.3), 0.0))


@pytest.mark.parametrize("profile", [(), ((1.0, 0.1),), ((2.0, 0.1, 0.1), (1.0, 0.1, 0.1)), ((0.0, math.nan, 0.0),)])
def test_a_bad_profile_is_refused(profile):
    with pytest.raises(ValueError, match="profile"):
        EkfTilt(profile=profile)


def test_a_steady_tilt_error_gives_the_velocity_and_position_errors_of_the_fit():
    g, north, east = 9.81, math.radians(0.15), math.radians(0.1)
    h = EkfHorizontal(g, position_lag_s=0.0)
    h.advance((north, east), 0.0025, lifted_off=False)
    # waiting on the ground: the velocity reading off (less than in flight), the position not
    kg = GROUND_VELOCITY_GAIN_1_S
    assert h.velocity_error == pytest.approx([-g * east / kg, g * north / kg])
    assert h.position_error == [0.0, 0.0]
    for _ in range(8000):  # 20 s in the air: settled
        h.advance((north, east), 0.0025)
    v = [-g * east / VELOCITY_GAIN_1_S, g * north / VELOCITY_GAIN_1_S]
    assert h.velocity_error == pytest.approx(v, rel=1e-3)
    assert h.position_error == pytest.approx([x / POSITION_GAIN_1_S for x in v], rel=1e-2)
    out = h.apply(NavReading(1.0, 2.0, -1.5, 0.3, -0.4, 0.0, 1.5, -1.0), 0.0025)
    assert (out.n, out.e) == pytest.approx((1.0 + h.position_error[0], 2.0 + h.position_error[1]))
    assert (out.vn, out.ve) == pytest.approx((0.3 + v[0], -0.4 + v[1]), rel=1e-3)
    assert (out.d, out.vd, out.baro_alt_m) == (-1.5, 0.0, 1.5)


def test_the_horizontal_position_lags_the_sensed_one_and_the_velocity_does_not():
    h = EkfHorizontal(9.81)
    assert pytest.approx(0.047) == POSITION_LAG_S
    dt, speed = 0.0025, 2.0
    out = None
    for i in range(2000):  # 5 s at 2 m/s north: the first-order lag settles
        out = h.apply(NavReading(speed * i * dt, 0.0, -1.0, speed, 0.0, 0.0, 1.0, 0.0), dt)
    # a ramp through a first-order lag falls behind by speed * time constant
    assert speed * 1999 * dt - out.n == pytest.approx(speed * POSITION_LAG_S, rel=0.03)
    assert out.vn == speed and out.e == 0.0


def test_the_horizontal_errors_refuse_bad_gains():
    with pytest.raises(ValueError, match="ground gain"):
        EkfHorizontal(9.81, ground_velocity_gain_1_s=0.0)
    with pytest.raises(ValueError):
        EkfHorizontal(9.81, position_lag_s=math.nan)


def test_the_emulated_position_stays_true_on_the_ground_and_drifts_once_in_the_air():
    from sitl.copter.ardupilot_emulation.vehicle import arducopter_sitl_vehicle
    from sitl.copter.simulation import Simulation

    sim = Simulation(arducopter_sitl_vehicle(), emulate="arducopter", ekf_ready_s=0.0)
    for _ in range(1200):  # 3 s on the ground
        sim.tick()
    assert (sim.nav.n, sim.nav.e) == pytest.approx((sim.world.kinematics.n, sim.world.kinematics.e), abs=1e-9)
    assert abs(sim.nav.vn) > 1e-3  # ... while its velocity reading is off
    sim._lifted_off = True  # as after a liftoff: the velocity error now moves the position
    for _ in range(400):
        sim.tick()
    assert abs(sim.nav.n - sim.world.kinematics.n) > 1e-3


def test_the_emulated_vehicle_reports_the_tilted_attitude_and_the_pulled_velocity():
    from sitl.copter.ardupilot_emulation.vehicle import arducopter_sitl_vehicle
    from sitl.copter.simulation import Simulation

    sim = Simulation(arducopter_sitl_vehicle(), emulate="arducopter", ekf_ready_s=0.0)
    plain = Simulation(arducopter_sitl_vehicle(), ekf_ready_s=0.0)
    n = 800
    sums = [0.0] * 9
    for _ in range(n):  # 2 s resting level on the ground, heading 0
        sim.tick()
        plain.tick()
        for i, v in enumerate((sim.imu.roll, sim.imu.pitch, sim.nav.vn, sim.nav.ve, plain.imu.roll, plain.nav.vn,
                               sim.imu.p, sim.imu.q, sim.imu.r)):
            sums[i] += v / n
    k = sim.world.kinematics
    assert abs(k.qx) < 1e-9 and abs(k.qy) < 1e-9
    # the AHRS reads the profile's first row, turned from the firmware's heading (-4.8 deg) to 0
    north, east = EkfTilt().error_rad(None)
    assert sums[0] == pytest.approx(north, abs=2e-4) and sums[1] == pytest.approx(east, abs=2e-4)
    assert math.degrees(north) == pytest.approx(0.100, abs=0.002)
    # the velocity reading off by the ground's steady state of the false acceleration: about -4.6 / +6.4 mm/s
    assert sums[2] == pytest.approx(-9.81 * east / GROUND_VELOCITY_GAIN_1_S, abs=1e-3)
    assert sums[3] == pytest.approx(9.81 * north / GROUND_VELOCITY_GAIN_1_S, abs=1e-3)
    # the rates the firmware's AHRS reads at rest
    assert sums[6:9] == pytest.approx(RATE_OFFSET_RAD_S, abs=2e-5)
    assert math.degrees(RATE_OFFSET_RAD_S[2]) == pytest.approx(0.21)
    assert abs(sums[4]) < 1e-4 and abs(sums[5]) < 1e-3  # the built-in SITL is unchanged
