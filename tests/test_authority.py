"""AuthorityWatch: sustained saturation of the setpoints says the fault is past the vehicle's authority."""

from __future__ import annotations

import pytest

from gcs.flight.result import EXIT_CODES
from gcs.vehicles.authority import INTEGRAL_PINNED_S, THRUST_SATURATED_S, AuthorityWatch

TS = 0.01


def att(thrust: float) -> dict:
    return {"message": "SET_ATTITUDE_TARGET", "thrust": thrust}


def run(w: AuthorityWatch, seconds: float, fields: dict, airborne: bool = True, delta=None, max_rad=None) -> None:
    for _ in range(int(round(seconds / TS))):
        w.update(fields, airborne, delta, max_rad)


def test_thrust_at_its_top_for_a_second_in_the_air_is_past_authority():
    w = AuthorityWatch(TS)
    run(w, THRUST_SATURATED_S - 0.05, att(1.0))
    assert w.failure() is None
    run(w, 0.06, att(1.0))
    assert "thrust at its top" in w.failure()
    assert EXIT_CODES["out_of_authority"] == 13


def test_short_saturations_and_the_ground_do_not_count():
    w = AuthorityWatch(TS)
    for _ in range(20):  # 0.5 s saturated, one period below: never 1 s in a row
        run(w, 0.5, att(1.0))
        run(w, TS, att(0.99))
    run(w, 5.0, att(1.0), airborne=False)  # spooling up on the ground
    assert w.failure() is None


def test_actuator_output_thrust_is_read_from_its_controls():
    w = AuthorityWatch(TS)
    run(w, 1.1, {"message": "SET_ACTUATOR_CONTROL_TARGET", "controls": [0.0, 0.0, 0.0, 0.0, 1.0, 0, 0, 0]})
    assert "thrust" in w.failure()


@pytest.mark.parametrize(("axis", "name"), [(0, "roll"), (1, "pitch"), (2, "yaw")])
def test_the_rate_correction_pinned_at_its_bound_for_2s_names_the_axis(axis, name):
    w = AuthorityWatch(TS)
    lim = (0.1, 0.1, 0.2)
    delta = [0.0, 0.0, 0.0]
    delta[axis] = -lim[axis]
    run(w, INTEGRAL_PINNED_S - 0.05, att(0.5), delta=delta, max_rad=lim)
    assert w.failure() is None
    run(w, 0.06, att(0.5), delta=delta, max_rad=lim)
    assert f"{name} rate fell short" in w.failure()
    delta[axis] = 0.0
    run(w, 1.0, att(0.5), delta=delta, max_rad=lim)
    assert w.failure() is not None  # once said, it stays: the flight is landing


def test_a_correction_below_its_bound_or_off_is_fine():
    w = AuthorityWatch(TS)
    run(w, 10.0, att(0.6), delta=[0.09, -0.09, 0.19], max_rad=(0.1, 0.1, 0.2))  # 90-95 % of the bound
    run(w, 10.0, att(0.6), delta=[0.0, 0.0, 0.0], max_rad=(0.0, 0.0, 0.0))  # an axis off (bound 0)
    assert w.failure() is None


def test_bad_periods_are_refused():
    with pytest.raises(ValueError):
        AuthorityWatch(0.0)
