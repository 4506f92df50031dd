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
