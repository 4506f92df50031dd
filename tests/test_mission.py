import math

import numpy as np
import pytest

from gcs.config import PhaseConfig
from gcs.mission import Mission


def circle_mission(**kw):
    return Mission([PhaseConfig("takeoff", 5.0, z_m=1.5), PhaseConfig("circle", 20.0, radius_m=1.0, period_s=10.0),
                    PhaseConfig("land", 5.0)], **kw)


def test_takeoff_ramp_hold_and_after_end():
    m = Mission([PhaseConfig("takeoff", 15.0, z_m=0.3), PhaseConfig("hold", 45.0)])
    assert m.duration_s == 60.0 and m.setpoint_z_m == 0.3
    assert m.reference(0.0).z == 0.0
    assert m.reference(7.5).z == pytest.approx(0.15) and m.reference(7.5).vz == pytest.approx(0.02)
    assert m.reference(15.0).z == pytest.approx(0.3) and m.reference(15.0).vz == 0.0
    assert m.reference(100.0).z == pytest.approx(0.3)
    assert m.hold_window(1.0) == (59.0, 60.0)
    assert m.flight_window() == (0.0, 60.0)


def test_circle_passes_through_the_start_and_velocities_are_derivatives():
    m = circle_mission()
    r0 = m.reference(5.0)
    assert (r0.x, r0.y, r0.z) == pytest.approx((0.0, 0.0, 1.5))
    for t in np.linspace(5.1, 24.9, 25):
        r = m.reference(t)
        assert math.hypot(r.x + 1.0, r.y) == pytest.approx(1.0)
        h = 1e-6
        a, b = m.reference(t - h), m.reference(t + h)
        assert r.vx == pytest.approx((b.x - a.x) / (2 * h), abs=1e-5)
        assert r.vy == pytest.approx((b.y - a.y) / (2 * h), abs=1e-5)
    assert m.reference(10.0).x == pytest.approx(-2.0)  # half a lap of period 10 s
    assert m.reference(15.0).x == pytest.approx(0.0, abs=1e-9)  # one lap


def test_landing_and_zero_velocity_option():
    m = circle_mission()
    assert m.reference(27.5).z == pytest.approx(0.75) and m.reference(27.5).vz == pytest.approx(-0.3)
    assert m.reference(40.0).z == 0.0
    z = circle_mission(zero_velocity=True)
    r = z.reference(10.0)
    assert (r.vx, r.vy, r.vz) == (0.0, 0.0, 0.0) and r.x == m.reference(10.0).x
    assert m.flight_window() == (0.0, 25.0) and m.hold_window(1.0) == (24.0, 25.0)


def test_explicit_circle_centre_and_empty_mission():
    m = Mission([PhaseConfig("takeoff", 1.0, z_m=1.0),
                 PhaseConfig("circle", 4.0, radius_m=2.0, period_s=4.0, center_m=(0.0, 0.0))])
    r = m.reference(1.0)
    assert math.hypot(r.x, r.y) == pytest.approx(2.0)
    with pytest.raises(ValueError):
        Mission([])


def test_acceleration_is_the_derivative_of_the_reference_velocity():
    m = circle_mission()
    for t in np.linspace(5.1, 24.9, 25):
        h = 1e-6
        a, b = m.reference(t - h), m.reference(t + h)
        ax, ay, az = m.acceleration(t)
        assert ax == pytest.approx((b.vx - a.vx) / (2 * h), abs=1e-4)
        assert ay == pytest.approx((b.vy - a.vy) / (2 * h), abs=1e-4)
        assert az == 0.0
        assert math.hypot(ax, ay) == pytest.approx((2 * math.pi / 10.0) ** 2 * 1.0)  # w^2 r, towards the centre
    for t in (0.0, 2.5, 27.5, 100.0):  # ramps (constant velocity) and after the end
        assert m.acceleration(t) == (0.0, 0.0, 0.0)
    assert circle_mission(zero_velocity=True).acceleration(10.0) == (0.0, 0.0, 0.0)
