import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from quadrotor.frames import (body_rates_to_euler_rates, euler_accel_to_body_accel, euler_rates_to_body_rates,
                              euler_to_quaternion, ned_to_paper_position, ned_to_paper_velocity, paper_to_ned_position,
                              quaternion_to_euler)

angle = st.floats(-1.2, 1.2)
rate = st.floats(-3, 3)


def test_z_up_is_minus_down():
    assert ned_to_paper_position(1.0, 2.0, -3.0) == (1.0, 2.0, 3.0)
    assert ned_to_paper_velocity(0.1, 0.2, 0.5) == (0.1, 0.2, -0.5)
    assert paper_to_ned_position(*ned_to_paper_position(4.0, 5.0, 6.0)) == (4.0, 5.0, 6.0)


@settings(max_examples=200, deadline=None)
@given(angle, angle, angle)
def test_quaternion_round_trip_and_unit_norm(r, p, y):
    q = euler_to_quaternion(r, p, y)
    assert math.fsum(c * c for c in q) == pytest.approx(1.0)
    np.testing.assert_allclose(quaternion_to_euler(q), (r, p, y), atol=1e-9)


def test_quaternion_matches_pymavlink():
    from pymavlink.quaternion import Quaternion
    q = euler_to_quaternion(0.1, -0.2, 0.3)
    np.testing.assert_allclose(q, list(Quaternion([0.1, -0.2, 0.3]).q), atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(angle, angle, rate, rate, rate)
def test_rate_maps_are_inverse(r, p, a, b, c):
    e = body_rates_to_euler_rates(r, p, *euler_rates_to_body_rates(r, p, a, b, c))
    np.testing.assert_allclose(e, (a, b, c), atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(angle, angle, rate, rate, rate, rate, rate, rate)
def test_accel_map_is_the_derivative_of_the_rate_map(r, p, dr, dp, dy, ar, ap, ay):
    h = 1e-6

    def body(t):
        return np.array(euler_rates_to_body_rates(r + dr * t + 0.5 * ar * t * t, p + dp * t + 0.5 * ap * t * t,
                                                  dr + ar * t, dp + ap * t, dy + ay * t))

    numeric = (body(h) - body(-h)) / (2 * h)
    np.testing.assert_allclose(euler_accel_to_body_accel((r, p, 0.0), (dr, dp, dy), (ar, ap, ay)), numeric, atol=1e-5)


def test_small_angles_are_the_identity():
    assert euler_accel_to_body_accel((0, 0, 0), (0, 0, 0), (1.0, 2.0, 3.0)) == pytest.approx((1.0, 2.0, 3.0))
